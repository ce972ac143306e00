// eye.js — placeholder for the compound eye view (kind 4 lens tables / kind 2 bake
// textures); replaced by the real renderer below.
export class EyeView {
  constructor(stream) { this.stream = stream; this.kind = 'eye'; }
  setParams() {}
  onFrame() { return false; }
  render() { return false; }
}
