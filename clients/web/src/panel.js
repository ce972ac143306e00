// panel.js — the tuning panel of one stream, generated from its effect's `describe` schema
// (PROTOCOL.md §10) with lil-gui: a slider with range and unit per float/int, a toggle per
// bool, a drop-down per enum, a colour picker per color, x/y/z sliders per vec3, a text
// field per float_list and a folder per object_list item (add/remove buttons). Every change
// is sent as a partial `set` (throttled to one request per 100 ms per stream, merged); the
// server's `params` (reply or another client's broadcast) updates the widgets; an error's
// `param` path puts its message next to the field it names.
const THROTTLE_MS = 100;

function stepOf(p) {
  if (p.type === 'int') return p.even ? 2 : 1;
  const span = p.max - p.min;
  if (!(span > 0)) return 0.001;
  const raw = span / 1000;
  return Math.pow(10, Math.floor(Math.log10(raw)));
}

const clone = (v) => JSON.parse(JSON.stringify(v));

export class StreamPanel {
  /** gui: parent lil-gui; send(partial) -> Promise of the params reply (rejects with error). */
  constructor(gui, stream, effect, schema, doc, rev, send) {
    Object.assign(this, { gui, stream, effect, schema, send });
    this.values = clone(doc);
    this.rev = rev;
    this.pendingPartial = null;
    this.lastSent = 0;
    this.timer = null;
    this.errors = new Map(); // top-level name -> element
    this.controllers = new Map(); // path -> controller
    this.folder = gui.addFolder(this.title());
    this.folder.domElement.dataset.stream = stream;
    this.build();
  }

  title() { return `${this.stream} · ${this.effect} · rev ${this.rev}`; }

  build() {
    for (const c of [...this.folder.children]) c.destroy();
    this.controllers.clear();
    this.proxies = [];
    for (const p of this.schema.params) this.addParam(this.folder, this.values, p, p.name, () => this.changed(p.name));
  }

  label(p) { return p.unit ? `${p.name} (${p.unit})` : p.name; }

  addParam(folder, obj, p, path, onChange) {
    let c;
    switch (p.type) {
      case 'float':
      case 'int':
        c = folder.add(obj, p.name, p.min, p.max, stepOf(p));
        break;
      case 'bool':
        c = folder.add(obj, p.name);
        break;
      case 'enum':
        c = folder.add(obj, p.name, p.choices);
        break;
      case 'color':
        c = folder.addColor(obj, p.name, 1);
        break;
      case 'vec3': {
        const sub = folder.addFolder(this.label(p));
        const proxy = { x: obj[p.name][0], y: obj[p.name][1], z: obj[p.name][2] };
        this.proxies.push({ proxy, obj, name: p.name });
        for (const k of ['x', 'y', 'z'])
          sub.add(proxy, k, p.min, p.max, stepOf(p)).onChange(() => { obj[p.name] = [proxy.x, proxy.y, proxy.z]; onChange(); });
        sub.close();
        sub.domElement.title = p.doc;
        sub.domElement.dataset.param = path;
        this.controllers.set(path, sub);
        return sub;
      }
      case 'float_list': {
        const proxy = { [p.name]: obj[p.name].join(', ') };
        this.proxies.push({ proxy, obj, name: p.name, list: true });
        c = folder.add(proxy, p.name).onFinishChange(() => {
          obj[p.name] = proxy[p.name].split(/[\s,]+/).filter((s) => s !== '').map(Number);
          onChange();
        });
        c.name(`${this.label(p)} [${p.min}…${p.max}]`);
        break;
      }
      case 'object_list': {
        const sub = folder.addFolder(`${this.label(p)} (${obj[p.name].length})`);
        obj[p.name].forEach((item, i) => {
          const f = sub.addFolder(`${p.name}[${i}]`);
          for (const fp of p.fields) this.addParam(f, item, fp, `${path}[${i}].${fp.name}`, onChange);
          f.close();
        });
        const actions = {
          add: () => {
            if (obj[p.name].length >= p.max_len) return;
            const item = {};
            for (const fp of p.fields) item[fp.name] = clone(fp.default);
            obj[p.name].push(item);
            onChange();
            this.build();
          },
          remove: () => {
            if (obj[p.name].length <= (p.min_len || 0)) return;
            obj[p.name].pop();
            onChange();
            this.build();
          },
        };
        sub.add(actions, 'add').name(`add ${p.name} item`);
        sub.add(actions, 'remove').name('remove last item');
        sub.close();
        sub.domElement.title = p.doc;
        sub.domElement.dataset.param = path;
        this.controllers.set(path, sub);
        return sub;
      }
      default:
        return null;
    }
    if (p.type !== 'float_list') c.name(this.label(p)).onChange(onChange);
    c.domElement.title = p.doc + (p.update === 'restart' ? ' (restarts the stream)' : '');
    c.domElement.dataset.param = path;
    this.controllers.set(path, c);
    return c;
  }

  /** A widget changed top-level parameter `name`: queue it (whole value) for `set`. */
  changed(name) {
    this.pendingPartial = { ...(this.pendingPartial || {}), [name]: clone(this.values[name]) };
    const wait = Math.max(0, this.lastSent + THROTTLE_MS - performance.now());
    if (!this.timer) this.timer = setTimeout(() => this.flush(), wait);
  }

  flush() {
    this.timer = null;
    const partial = this.pendingPartial;
    this.pendingPartial = null;
    if (!partial) return;
    this.lastSent = performance.now();
    for (const k of Object.keys(partial)) this.clearError(k);
    this.send(partial).then(
      (m) => this.update(m.params, m.rev),
      (err) => {
        this.showError(err.param || Object.keys(partial)[0], `${err.code}: ${err.message}`);
        if (this.serverDoc) this.update(this.serverDoc, this.rev, true); // nothing changed on the server
      });
  }

  /** The server's complete document (reply or broadcast). */
  update(doc, rev, keepErrors = false) {
    this.serverDoc = clone(doc);
    this.rev = rev;
    this.folder.title(this.title());
    if (this.pendingPartial) return; // the user is still editing; the next reply brings it
    const relist = this.schema.params.some((p) => p.type === 'object_list' && (doc[p.name] || []).length !== (this.values[p.name] || []).length);
    if (relist) {
      this.values = clone(doc);
      const closed = this.folder._closed;
      this.build();
      if (closed) this.folder.close();
    } else {
      // in place: the controllers hold references into this.values and its list items
      for (const p of this.schema.params) {
        const v = clone(doc[p.name]);
        if (p.type === 'object_list') this.values[p.name].forEach((item, i) => Object.assign(item, v[i]));
        else this.values[p.name] = v;
      }
      for (const { proxy, obj, name, list } of this.proxies) {
        if (list) proxy[name] = obj[name].join(', ');
        else [proxy.x, proxy.y, proxy.z] = obj[name];
      }
      for (const c of this.folder.controllersRecursive()) c.updateDisplay();
    }
    if (!keepErrors) for (const k of [...this.errors.keys()]) this.clearError(k);
  }

  controllerFor(path) {
    let p = path;
    while (p) {
      if (this.controllers.has(p)) return this.controllers.get(p);
      const cut = Math.max(p.lastIndexOf('.'), p.lastIndexOf('['));
      if (cut <= 0) break;
      p = p.slice(0, cut);
    }
    return this.controllers.get(path.split(/[.[]/)[0]);
  }

  showError(path, message) {
    const top = path.split(/[.[]/)[0];
    this.clearError(top);
    const c = this.controllerFor(path);
    const el = document.createElement('div');
    el.className = 'fxs-param-error';
    el.textContent = `${path}: ${message}`;
    el.dataset.param = path;
    const host = c ? c.domElement : this.folder.domElement;
    host.after ? host.after(el) : host.appendChild(el);
    this.errors.set(top, el);
  }

  clearError(top) {
    const el = this.errors.get(top);
    if (el) { el.remove(); this.errors.delete(top); }
  }

  destroy() { clearTimeout(this.timer); this.folder.destroy(); }
}
