// orbit.js — mouse camera control for one view of the shared canvas: three's OrbitControls
// (drag to rotate, wheel to zoom, right-drag or shift-drag to pan), active only while the
// pointer is over that view's rectangle, and a double-click in the view resets the camera.
// Every view shares one canvas, so each view's controls listen on it and this module turns
// them on only for the view under the pointer (before OrbitControls sees the event).
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

export class ViewOrbit {
  // camera: the view's camera; canvas: the shared canvas; css(): the view's rectangle in
  // canvas pixels {left, top, w, h}, or null while it is not laid out.
  constructor(camera, canvas, css) {
    this.css = css;
    const inside = (e) => {
      const r = css(), b = canvas.getBoundingClientRect();
      if (!r) return false;
      const x = e.clientX - b.left, y = e.clientY - b.top;
      return x >= r.left && x < r.left + r.w && y >= r.top && y < r.top + r.h;
    };
    // Registered before OrbitControls' own listeners, so they run first on the same event.
    this.gate = (e) => { if (!e.buttons) this.controls.enabled = inside(e); };
    this.reset = (e) => { if (inside(e)) this.home(); };
    for (const ev of ['pointerdown', 'pointermove', 'wheel']) canvas.addEventListener(ev, this.gate, { capture: true });
    canvas.addEventListener('dblclick', this.reset);
    this.canvas = canvas;
    this.controls = new OrbitControls(camera, canvas);
    this.controls.enabled = false;
    this.controls.enableDamping = false;
    this.moved = false; // the user has moved the camera since the last home()
    this.controls.addEventListener('start', () => { this.moved = true; });
    this.homeState = null;
  }

  // Sets the camera's home (position and target) and goes there.
  setHome(position, target) {
    this.homeState = { position: position.clone(), target: target.clone() };
    this.home();
  }

  home() {
    if (!this.homeState) return;
    this.controls.object.position.copy(this.homeState.position);
    this.controls.target.copy(this.homeState.target);
    this.controls.update();
    this.moved = false;
  }

  update() { this.controls.update(); }

  dispose() {
    for (const ev of ['pointerdown', 'pointermove', 'wheel']) this.canvas.removeEventListener(ev, this.gate, { capture: true });
    this.canvas.removeEventListener('dblclick', this.reset);
    this.controls.dispose();
  }
}
