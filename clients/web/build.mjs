// build.mjs — bundles the browser client (clients/web/src/main.js, three.js, lil-gui and
// fxs_particles.js) into clients/web/dist/app.js, and the particle decoder's worker
// (src/decode_worker.js) into dist/decode_worker.js, with esbuild from node_modules
// (installed by `npm ci` from the committed lock file); also the page with the browser tests'
// hooks (clients/web/test/hooks.js) into dist/app-test.js, which only the tests load. Run by
// `make` (target web), which also builds dist/fxs_particles.wasm; no network.
import { build } from 'esbuild';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
const common = { bundle: true, target: ['chrome110', 'firefox110', 'safari16'], minify: true, sourcemap: false, logLevel: 'warning', legalComments: 'eof' };
await build({ ...common, entryPoints: [join(here, 'src', 'main.js')], outfile: join(here, 'dist', 'app.js'), format: 'esm' });
await build({ ...common, entryPoints: [join(here, 'test', 'hooks.js')], outfile: join(here, 'dist', 'app-test.js'), format: 'esm' });
// The particle decoder's worker, a classic script (module workers are newer than the targets).
await build({ ...common, entryPoints: [join(here, 'src', 'decode_worker.js')], outfile: join(here, 'dist', 'decode_worker.js'), format: 'iife' });
