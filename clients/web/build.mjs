// build.mjs — bundles the browser client (clients/web/src/main.js, three.js, lil-gui and
// fxs_particles.js) into clients/web/dist/app.js with esbuild from node_modules (installed
// by `npm ci` from the committed lock file), and the same with the browser tests' hooks
// (clients/web/test/hooks.js) into dist/app-test.js, which only the tests load. Run by `make`
// (target web); no network.
import { build } from 'esbuild';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
for (const [entry, out] of [[join(here, 'src', 'main.js'), 'app.js'], [join(here, 'test', 'hooks.js'), 'app-test.js']]) await build({
  entryPoints: [entry],
  outfile: join(here, 'dist', out),
  bundle: true,
  format: 'esm',
  target: ['chrome110', 'firefox110', 'safari16'],
  minify: true,
  sourcemap: false,
  logLevel: 'warning',
  legalComments: 'eof',
});
