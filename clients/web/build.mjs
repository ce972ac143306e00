// build.mjs — bundles the browser client (clients/web/src/main.js, three.js, lil-gui and
// fxs_particles.js) into clients/web/dist/app.js with esbuild from node_modules (installed
// by `npm ci` from the committed lock file). Run by `make` (target web); no network.
import { build } from 'esbuild';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
await build({
  entryPoints: [join(here, 'src', 'main.js')],
  outfile: join(here, 'dist', 'app.js'),
  bundle: true,
  format: 'esm',
  target: ['chrome110', 'firefox110', 'safari16'],
  minify: true,
  sourcemap: false,
  logLevel: 'warning',
  legalComments: 'eof',
});
