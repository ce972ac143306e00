// panel.js — the tuning panel of one stream, generated from its effect's `describe` schema
// (PROTOCOL.md §10) with lil-gui. First, open, a "look" folder with the few controls an artist
// reaches for (LOOK_PARAMS: server parameters under plain names, and the page's own view
// settings given by main.js); then the presets; then "advanced", folded: every parameter in
// one folder per `group` (and the page's other view settings under "display"), each with its
// doc line and unit visible under it and a ↺ button that puts it back to its default. Widgets: a
// number field per float/int (always typed in) with a slider, logarithmic where max/min >= 100;
// a toggle per bool, a drop-down per enum, a colour picker per color, x/y/z fields per vec3,
// a text field per float_list and a folder per object_list item (add/remove buttons).
// A presets folder lists the effect's presets (PROTOCOL.md §3.12): load, save the stream's
// values under a name, delete a user preset; and the stream can go back to its defaults or
// restart its simulation. The list shows the preset the stream's values match (its values over
// the defaults), or "(custom)". Every change is sent as a partial `set` (throttled to one request
// per 100 ms per stream, merged); the server's `params` (reply or another client's broadcast)
// updates the widgets; an error's `param` path puts its message next to the field it names.
const THROTTLE_MS = 100;
const LOG_RATIO = 100; // sliders are logarithmic from this max/min up
const LOG_STEPS = 1000;

function stepOf(p) {
  if (p.type === 'int') return p.even ? 2 : 1;
  const span = p.max - p.min;
  if (!(span > 0)) return 0.001;
  return Math.pow(10, Math.floor(Math.log10(span / 1000)));
}

// The look folder's server parameters per effect, with the names an artist reads.
export const LOOK_PARAMS = {
  flame: [['k_buo', 'height (buoyancy)'], ['wind_velocity', 'wind (m/s)']],
  energy_wave: [['color_energy', 'colour'], ['alpha', 'intensity'], ['size', 'size (world units)']],
  compound_eye: [['base_color', 'colour'], ['dot_color', 'pupil colour'], ['density', 'facets (lenses across)']],
};
const CUSTOM = '(custom)';

// True when `have` holds every value of `want` (objects: want's keys only; numbers to 1e-9).
function matches(want, have) {
  if (Array.isArray(want)) return Array.isArray(have) && want.length === have.length && want.every((w, i) => matches(w, have[i]));
  if (want && typeof want === 'object') return !!have && typeof have === 'object' && Object.keys(want).every((k) => matches(want[k], have[k]));
  if (typeof want === 'number') return typeof have === 'number' && Math.abs(want - have) <= 1e-9 * Math.max(1, Math.abs(want));
  return want === have;
}

const isLog = (p) => (p.type === 'float' || p.type === 'int') && p.min > 0 && p.max / p.min >= LOG_RATIO;
const clone = (v) => JSON.parse(JSON.stringify(v));
const el = (tag, cls, text) => { const e = document.createElement(tag); if (cls) e.className = cls; if (text) e.textContent = text; return e; };

/** Slider position (0..LOG_STEPS) of v on p's logarithmic scale, and back. */
export function logPos(p, v) { return Math.round(LOG_STEPS * Math.log(Math.max(p.min, v) / p.min) / Math.log(p.max / p.min)); }
export function logValue(p, pos) {
  let v = p.min * Math.pow(p.max / p.min, pos / LOG_STEPS);
  if (p.type === 'int') v = Math.round(v / stepOf(p)) * stepOf(p);
  else v = Number(v.toPrecision(3));
  return Math.min(p.max, Math.max(p.min, v));
}

export class StreamPanel {
  /** gui: parent lil-gui; api: {set(partial) -> Promise of the params reply, request(op, fields)
   * -> Promise of the reply, applied(params reply)}: a reply that changed the parameters.
   * view: the page's own settings of this stream's views, {look: [...], display: [...]}, each
   * {obj, key, label, doc} with min/max/step (a number), choices, or color: true. */
  constructor(gui, stream, effect, schema, doc, rev, api, view = { look: [], display: [] }) {
    Object.assign(this, { gui, stream, effect, schema, api, view });
    this.values = clone(doc);
    this.rev = rev;
    this.pendingPartial = null;
    this.lastSent = 0;
    this.timer = null;
    this.errors = new Map(); // top-level name -> element
    this.controllers = new Map(); // path -> controller
    this.presetList = [];
    this.folder = gui.addFolder(this.title());
    this.folder.domElement.dataset.stream = stream;
    this.build();
    this.refreshPresets();
  }

  title() { return `${this.stream} · ${this.effect} · rev ${this.rev}`; }

  build() {
    for (const c of [...this.folder.children]) c.destroy();
    this.controllers.clear();
    this.proxies = [];
    this.logSliders = [];
    this.buildLook();
    this.buildActions();
    const adv = this.folder.addFolder('advanced');
    adv.domElement.dataset.group = 'advanced';
    const groups = new Map();
    for (const p of this.schema.params) {
      const g = p.group || 'other';
      if (!groups.has(g)) {
        const f = adv.addFolder(g);
        f.domElement.dataset.group = g;
        groups.set(g, f);
      }
      const c = this.addParam(groups.get(g), this.values, p, p.name, () => this.changed(p.name));
      if (c) this.addReset(c, p);
    }
    if (this.view.display.length) {
      const f = adv.addFolder('display (this page)');
      f.domElement.dataset.group = 'display';
      for (const v of this.view.display) this.addView(f, v);
      f.close();
    }
    adv.close();
  }

  // The look folder: LOOK_PARAMS of this effect, then the page's look settings.
  buildLook() {
    const f = this.folder.addFolder('look');
    f.domElement.dataset.group = 'look';
    for (const [name, label] of LOOK_PARAMS[this.effect] || []) {
      const p = this.schema.params.find((x) => x.name === name);
      if (!p) continue;
      const c = this.addParam(f, this.values, { ...p, label }, p.name, () => this.changed(p.name));
      if (c) this.addReset(c, p);
    }
    for (const v of this.view.look) this.addView(f, v);
  }

  // A setting of the page's own views (not sent to the server).
  addView(folder, v) {
    const c = v.color ? folder.addColor(v.obj, v.key) : v.choices ? folder.add(v.obj, v.key, v.choices)
      : v.min !== undefined ? folder.add(v.obj, v.key, v.min, v.max, v.step) : folder.add(v.obj, v.key);
    c.name(v.label);
    c.domElement.dataset.view = v.key;
    if (v.onChange) c.onChange(v.onChange);
    if (v.doc) c.domElement.after(el('div', 'fxs-doc', v.doc));
    return c;
  }

  label(p) { return p.label ?? (p.unit ? `${p.name} (${p.unit})` : p.name); }

  /** The doc line under a widget: what it does, and whether a change restarts the stream. */
  addDoc(c, p, isFolder) {
    const d = el('div', 'fxs-doc', p.doc + (p.update === 'restart' ? ' · restarts the stream' : ''));
    if (isFolder) c.$children.prepend(d);
    else c.domElement.after(d);
  }

  addReset(c, p) {
    const b = el('span', 'fxs-reset', '↺'); // a span: a folder's title is itself a <button>
    b.setAttribute('role', 'button');
    b.title = `back to the default, ${JSON.stringify(p.default)}`;
    b.dataset.reset = p.name;
    b.addEventListener('click', (e) => {
      e.stopPropagation();
      this.values[p.name] = clone(p.default);
      this.changed(p.name);
      if (p.type === 'object_list') this.rebuild();
      else this.refresh();
    });
    (c.$title || c.$widget).appendChild(b);
  }

  /** A number: lil-gui's field for typing, and a slider (log-scaled where the range is wide). */
  addNumber(folder, obj, p) {
    if (!isLog(p)) return folder.add(obj, p.name, p.min, p.max, stepOf(p));
    const c = folder.add(obj, p.name).step(stepOf(p));
    const s = el('input', 'fxs-log');
    Object.assign(s, { type: 'range', min: 0, max: LOG_STEPS, step: 1, title: `logarithmic, ${p.min} … ${p.max}` });
    s.value = logPos(p, obj[p.name]);
    s.addEventListener('input', () => { c.setValue(logValue(p, Number(s.value))); });
    c.$widget.prepend(s);
    c.$widget.classList.add('fxs-log-widget');
    this.logSliders.push({ s, c, p });
    c.onChange(() => { s.value = logPos(p, c.getValue()); });
    return c;
  }

  addParam(folder, obj, p, path, onChange) {
    let c;
    switch (p.type) {
      case 'float':
      case 'int':
        c = this.addNumber(folder, obj, p);
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
        return this.finishFolder(sub, p, path);
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
        return this.finishFolder(sub, p, path);
      }
      default:
        return null;
    }
    if (p.type !== 'float_list') c.name(this.label(p)).onChange(onChange);
    c.domElement.title = p.doc + (p.update === 'restart' ? ' (restarts the stream)' : '');
    c.domElement.dataset.param = path;
    this.addDoc(c, p, false);
    if (!this.controllers.has(path)) this.controllers.set(path, c); // a look control shows the errors
    return c;
  }

  finishFolder(sub, p, path) {
    sub.domElement.title = p.doc;
    sub.domElement.dataset.param = path;
    this.addDoc(sub, p, true);
    if (!this.controllers.has(path)) this.controllers.set(path, sub);
    return sub;
  }

  // ---- presets and stream actions (PROTOCOL.md §3.12, §3.9) ----

  buildActions() {
    const f = this.folder.addFolder('presets & reset');
    f.domElement.dataset.group = 'presets';
    this.presetFolder = f;
    this.presetState = { preset: this.presetState?.preset ?? CUSTOM, name: this.presetState?.name ?? '' };
    this.presetCtl = f.add(this.presetState, 'preset', this.presetNames()).name('preset');
    this.presetCtl.onChange(() => this.showPresetDoc());
    this.presetCtl.domElement.dataset.action = 'preset';
    this.presetDoc = el('div', 'fxs-doc');
    this.presetCtl.domElement.after(this.presetDoc);
    const acts = {
      load: () => this.presetOp('preset_load', { stream: this.stream, name: this.presetState.preset }),
      delete: () => this.presetOp('preset_delete', { effect: this.effect, name: this.presetState.preset }),
      save: () => this.presetOp('preset_save', { stream: this.stream, name: this.presetState.name.trim() }),
      defaults: () => this.setAll(Object.fromEntries(this.schema.params.map((p) => [p.name, clone(p.default)]))),
      restart: () => this.presetOp('reset', { stream: this.stream }),
    };
    const button = (k, label, title) => {
      const c = f.add(acts, k).name(label);
      c.domElement.dataset.action = k;
      c.domElement.title = title;
      return c;
    };
    this.loadCtl = button('load', 'load preset', "the effect's defaults with the preset's values over them");
    this.deleteCtl = button('delete', 'delete preset', 'your own presets only (admin); built-ins are read-only');
    f.add(this.presetState, 'name').name('save as').domElement.dataset.action = 'name';
    button('save', 'save values as preset', "this stream's values under the name above (admin)");
    button('defaults', 'all parameters to defaults', 'every parameter back to its default (one set)');
    button('restart', 'restart simulation', 'the stream starts again from time 0, parameters kept');
    this.presetStatus = el('div', 'fxs-doc fxs-preset-status');
    f.$children.appendChild(this.presetStatus);
    this.showPresetDoc();
  }

  presetNames() {
    const names = this.presetList.map((p) => p.name);
    return this.presetState.preset === CUSTOM || !names.length ? [CUSTOM, ...names] : names;
  }

  // The preset whose values over the defaults (list items completed with their field
  // defaults) are the stream's values, or CUSTOM.
  matchedPreset() {
    const doc = this.serverDoc || this.values;
    for (const pr of this.presetList) {
      const want = {};
      for (const p of this.schema.params) {
        const v = pr.params[p.name] ?? p.default;
        want[p.name] = p.type === 'object_list' && pr.params[p.name]
          ? v.map((item) => ({ ...Object.fromEntries(p.fields.map((f) => [f.name, f.default])), ...item })) : v;
      }
      if (matches(want, doc)) return pr.name;
    }
    return CUSTOM;
  }

  // The list shows the matched preset (the list is rebuilt when "(custom)" comes or goes).
  showMatch() {
    const m = this.matchedPreset(), had = this.presetCtl._values?.includes(CUSTOM);
    this.presetState.preset = m;
    if (had !== (m === CUSTOM)) {
      this.presetCtl = this.presetCtl.options(this.presetNames()).name('preset');
      this.presetCtl.domElement.dataset.action = 'preset';
      this.presetCtl.onChange(() => this.showPresetDoc());
      this.presetCtl.domElement.after(this.presetDoc);
    }
    this.presetCtl.updateDisplay();
    this.showPresetDoc();
  }

  showPresetDoc() {
    const p = this.presetList.find((x) => x.name === this.presetState.preset);
    this.presetDoc.textContent = p ? `${p.builtin ? 'built-in' : 'yours'}: ${p.doc || '(no description)'}` : '';
    this.deleteCtl.enable(!!p && !p.builtin);
    this.loadCtl.enable(!!p);
  }

  /** Re-reads the effect's presets (at start and after any preset_saved/preset_deleted). */
  async refreshPresets() {
    try {
      this.presetList = (await this.api.request('presets', { effect: this.effect })).presets;
    } catch (e) {
      this.presetStatus.textContent = `presets: ${e.code || ''} ${e.message || e}`;
      return;
    }
    this.presetState.preset = this.matchedPreset();
    this.presetCtl = this.presetCtl.options(this.presetNames()).name('preset');
    this.presetCtl.domElement.dataset.action = 'preset';
    this.presetCtl.onChange(() => this.showPresetDoc());
    this.presetCtl.domElement.after(this.presetDoc);
    this.showPresetDoc();
  }

  async presetOp(op, fields) {
    this.presetStatus.textContent = '';
    this.presetStatus.classList.remove('fxs-param-error');
    try {
      const m = await this.api.request(op, fields);
      if (m.op === 'params') { this.api.applied(m); this.update(m.params, m.rev); }
      if (op === 'preset_save' || op === 'preset_delete') await this.refreshPresets();
      if (op === 'preset_save') this.presetCtl.setValue(fields.name);
      this.presetStatus.textContent = { preset_load: `loaded ${fields.name}`, preset_save: `saved ${fields.name}`,
        preset_delete: `deleted ${fields.name}`, reset: 'simulation restarted' }[op];
    } catch (e) {
      this.presetStatus.classList.add('fxs-param-error');
      this.presetStatus.textContent = `${e.code}: ${e.message}`;
    }
  }

  /** Sends a whole document at once (defaults), bypassing the throttle. */
  setAll(partial) {
    clearTimeout(this.timer);
    this.timer = null;
    this.pendingPartial = null;
    this.lastSent = performance.now();
    this.api.set(partial).then((m) => this.update(m.params, m.rev),
      (e) => { this.presetStatus.textContent = `${e.code}: ${e.message}`; });
  }

  // ---- values ----

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
    this.api.set(partial).then(
      (m) => this.update(m.params, m.rev),
      (err) => {
        this.showError(err.param || Object.keys(partial)[0], `${err.code}: ${err.message}`);
        if (this.serverDoc) this.update(this.serverDoc, this.rev, true); // nothing changed on the server
      });
  }

  /** Every widget shows this.values again (after an in-place change). */
  refresh() {
    for (const { proxy, obj, name, list } of this.proxies) {
      if (list) proxy[name] = obj[name].join(', ');
      else [proxy.x, proxy.y, proxy.z] = obj[name];
    }
    for (const c of this.folder.controllersRecursive()) c.updateDisplay();
    for (const { s, c, p } of this.logSliders) s.value = logPos(p, c.getValue());
  }

  rebuild() {
    const closed = this.folder._closed;
    this.build();
    if (closed) this.folder.close();
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
      this.rebuild();
    } else {
      // in place: the controllers hold references into this.values and its list items
      for (const p of this.schema.params) {
        const v = clone(doc[p.name]);
        if (p.type === 'object_list') this.values[p.name].forEach((item, i) => Object.assign(item, v[i]));
        else this.values[p.name] = v;
      }
      this.refresh();
    }
    if (!keepErrors) for (const k of [...this.errors.keys()]) this.clearError(k);
    this.showMatch();
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
    const e = el('div', 'fxs-param-error', `${path}: ${message}`);
    e.dataset.param = path;
    const host = c ? c.domElement : this.folder.domElement;
    host.after ? host.after(e) : host.appendChild(e);
    this.errors.set(top, e);
  }

  clearError(top) {
    const e = this.errors.get(top);
    if (e) { e.remove(); this.errors.delete(top); }
  }

  destroy() { clearTimeout(this.timer); this.folder.destroy(); }
}
