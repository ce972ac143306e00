// orbit.js — mouse camera control for one view of the shared canvas: three's OrbitControls
// (drag to rotate, wheel to zoom, right-drag or shift-drag to pan), active only while the
// pointer is over that view's rectangle, and a double-click in the view goes back home.
// Every view shares one canvas, so each view's controls listen on it and this module turns
// them on only for the view under the pointer (before OrbitControls sees the event).
import { Vector3 } from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

export class ViewOrbit {
  // camera: the view's camera; canvas: the shared canvas; css(): the view's rectangle in
  // canvas pixels {left, top, w, h}, or null while it is not laid out.
  constructor(camera, canvas, css) {
    this.camera = camera;
    this.canvas = canvas;
    const inside = (e) => {
      const r = css(), b = canvas.getBoundingClientRect();
      if (!r) return false;
      const x = e.clientX - b.left, y = e.clientY - b.top;
      return x >= r.left && x < r.left + r.w && y >= r.top && y < r.top + r.h;
    };
    // Registered before OrbitControls' own listeners, so they run first on the same event.
    this.gate = (e) => { if (this.controls && !e.buttons) this.controls.enabled = inside(e); };
    this.reset = (e) => { if (inside(e)) this.home(); };
    for (const ev of ['pointerdown', 'pointermove', 'wheel']) canvas.addEventListener(ev, this.gate, { capture: true });
    canvas.addEventListener('dblclick', this.reset);
    this.controls = null;
    this.up = new Vector3();
    this.homeState = null;
    this.moved = false; // the user has moved the camera since it last went home
  }

  // Sets the camera's home (position, target, up) and goes there (unless go is false).
  // OrbitControls orbits around the camera's up as it was when the controls were made, so a
  // new up makes new controls.
  setHome(position, target, up = this.camera.up, go = true) {
    if (!this.controls || !this.up.equals(up)) {
      this.controls?.dispose();
      this.up.copy(up);
      this.camera.up.copy(up);
      this.controls = new OrbitControls(this.camera, this.canvas);
      this.controls.enabled = false;
      this.controls.addEventListener('start', () => { this.moved = true; });
    }
    this.homeState = { position: position.clone(), target: target.clone() };
    if (go) this.home();
  }

  home() {
    if (!this.homeState) return;
    this.camera.position.copy(this.homeState.position);
    this.controls.target.copy(this.homeState.target);
    this.controls.update();
    this.moved = false;
  }

  update() { this.controls?.update(); }

  get target() { return this.controls?.target; }

  dispose() {
    for (const ev of ['pointerdown', 'pointermove', 'wheel']) this.canvas.removeEventListener(ev, this.gate, { capture: true });
    this.canvas.removeEventListener('dblclick', this.reset);
    this.controls?.dispose();
  }
}
