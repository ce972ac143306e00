// view.js — the contract between the page (main.js) and its views, written once, as
// server/effect.h is for the daemon's effects. A view draws one stream's frames into its
// rectangle of the page's one WebGL2 canvas: FlameView (flame.js), WaveView (wave.js),
// SceneView (scene.js, the wave's light rig), EyeView (eye.js). main.js makes a stream's
// views from its effect (makeViews), hands them the stream's parameters and frames, lays all
// views out in a grid and asks each to draw its rectangle once per display frame. A new view
// keeps this contract, gets a place in main.js (makeViews, the grid's order, the label's
// title) and a line in tests/integration/web_views_check.mjs, which checks every view
// against viewFaults below.

/**
 * The kinds of view, in the grid's order. main.js orders the grid, titles the labels and
 * filters `?views=` by a view's `kind`.
 */
export const VIEW_KINDS = ['flame', 'wave', 'scene', 'eye'];

/**
 * A view's rectangle for drawing: CSS pixels of the canvas, y from its bottom edge (as
 * gl.viewport counts); the renderer's pixel ratio applies.
 * @typedef {{x: number, y: number, w: number, h: number}} ViewRect
 */

/**
 * A view's rectangle on the page: CSS pixels from the canvas's top-left corner.
 * @typedef {{left: number, top: number, w: number, h: number}} ViewCss
 */

/**
 * What every view has and does. Everything runs on the page's one thread, in this order:
 * the constructor (the stream's name; SceneView also the WaveView's texture), attachControls
 * once, setParams before the first frame and after every change, then per display frame
 * onFrame for the stream's newest pending frames and render; dispose when the stream goes.
 *
 * @typedef {object} View
 * @property {'flame'|'wave'|'scene'|'eye'} kind  Which view this is (VIEW_KINDS).
 * @property {string} stream  The name of the stream it shows.
 * @property {(params: object) => void} setParams  The stream's whole parameter document (a
 *   `get` reply, a `set` reply, a `params` event: PROTOCOL.md §3), kept for the next render.
 * @property {(h: object, buf: ArrayBuffer) => boolean} onFrame  One frame of the stream: h its
 *   header as parseHeader (fxs_particles.js) reads it (kind, codec, seq, paramRev, count,
 *   headerBytes, payloadBytes...), buf the whole message. Every view of a stream gets every
 *   kind the stream sends and ignores those it does not draw; only the newest frame of each
 *   kind arrives, kinds in ascending order (a texture before the light rig of its step).
 *   Returns whether it decoded the frame; main.js does not use the value. A throw is shown
 *   on the view's label and the page goes on.
 * @property {(renderer: import('three').WebGLRenderer, rect: ViewRect, time: number) => boolean} render
 *   Draws the view into rect of the canvas, time in seconds. On entry the canvas is the
 *   render target, the viewport and the scissor are rect and the scissor test is on; main.js
 *   clears the canvas once per display frame, not between views (autoClear is off). A view
 *   that draws into targets of its own binds the canvas and sets the viewport and scissor to
 *   rect again before it draws there, and leaves the canvas bound. Returns true when it
 *   showed a frame it had not shown before (the stream's "drawn" count), false otherwise;
 *   until it has something to show it draws nothing, touches no renderer state and returns
 *   false. A throw is shown on the label.
 * @property {() => void} dispose  Frees its GPU objects and listeners; the view is not used again.
 * @property {(canvas: HTMLCanvasElement, css: () => (ViewCss|null)) => void} [attachControls]
 *   Optional: input on its part of the canvas (orbit.js's cameras); css() is its rectangle
 *   now, null while it is not laid out.
 * @property {() => object} [info]  Optional: a plain object of what it shows, for the label
 *   (EyeView's lutRev) and the browser tests' hooks.
 *
 * Members of one kind that main.js also uses: `settings` (FlameView, WaveView), the display
 * settings of the panel, one object shared by the views of that kind; and the toon scene's
 * black level and gain, which it writes into WaveView.material and SceneView.billboardMat.
 */

const REQUIRED = ['setParams', 'onFrame', 'render', 'dispose'];
const OPTIONAL = ['attachControls', 'info'];

/**
 * What v lacks of the View contract, one line each; [] when it keeps it.
 * @param {object} v
 * @returns {string[]}
 */
export function viewFaults(v) {
  const faults = [];
  if (v === null || typeof v !== 'object') return ['not an object'];
  if (!VIEW_KINDS.includes(v.kind)) faults.push(`kind ${JSON.stringify(v.kind)} is not one of ${VIEW_KINDS.join(', ')}`);
  if (typeof v.stream !== 'string' || !v.stream) faults.push('stream is not a stream name');
  for (const m of REQUIRED) if (typeof v[m] !== 'function') faults.push(`${m}() is missing`);
  for (const m of OPTIONAL) if (m in v && typeof v[m] !== 'function') faults.push(`${m} is not a function`);
  return faults;
}
