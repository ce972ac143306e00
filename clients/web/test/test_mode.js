// test_mode.js — imported first by hooks.js, so the page's modules see FXS_TEST when they run.
globalThis.FXS_TEST = true;
