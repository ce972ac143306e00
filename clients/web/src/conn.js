// conn.js — one fxstream.v1 WebSocket connection (PROTOCOL.md §1-§4): requests with ids
// answered by promises, events and binary frames to callbacks, reconnection with
// exponential backoff (0.5 s doubling to 10 s) after the daemon restarts or the link drops.
// When the daemon requires a token (hello.auth.required, PROTOCOL.md §3.11) and one is given,
// it is sent with the `auth` op before the connection counts as open; `role` is the
// connection's role (hello.auth.role, then the auth reply's).
export class Conn {
  constructor(url, { onOpen, onEvent, onFrame, onState, token }) {
    Object.assign(this, { url, onOpen, onEvent, onFrame, onState, token });
    this.nextId = 1;
    this.pending = new Map(); // id -> {resolve, reject, timer}
    this.delay = 500;
    this.state = 'connecting';
    this.hello = null;
    this.role = 'none';
    this.connect();
  }

  setState(s, detail = '') {
    this.state = s;
    this.onState?.(s, detail);
  }

  connect() {
    this.setState('connecting');
    let ws;
    try {
      ws = new WebSocket(this.url, 'fxstream.v1');
    } catch (e) {
      this.retry(String(e));
      return;
    }
    ws.binaryType = 'arraybuffer';
    this.ws = ws;
    ws.onmessage = (e) => {
      if (typeof e.data !== 'string') { this.onFrame?.(e.data); return; }
      let m;
      try { m = JSON.parse(e.data); } catch { return; }
      if (m.op === 'hello') {
        this.hello = m;
        this.delay = 500;
        this.authenticate(m);
        return;
      }
      if (m.id !== undefined && this.pending.has(m.id)) {
        const p = this.pending.get(m.id);
        this.pending.delete(m.id);
        clearTimeout(p.timer);
        if (m.op === 'error') p.reject(m); else p.resolve(m);
        return;
      }
      this.onEvent?.(m);
    };
    ws.onclose = () => {
      if (this.ws !== ws) return;
      for (const p of this.pending.values()) { clearTimeout(p.timer); p.reject({ code: 'closed', message: 'connection closed' }); }
      this.pending.clear();
      this.retry('closed');
    };
    ws.onerror = () => {}; // onclose follows
  }

  async authenticate(hello) {
    this.role = hello.auth?.role ?? 'none';
    if (hello.auth?.required && this.token) {
      try {
        this.role = (await this.request('auth', { token: this.token })).role;
      } catch (e) {
        this.setState('unauthorized', e.message || 'invalid token');
        return;
      }
    } else if (hello.auth?.required) {
      this.setState('unauthorized', 'the daemon needs a token: open the page with ?token=…');
      return;
    }
    this.setState('connected');
    this.onOpen?.(hello);
  }

  retry(why) {
    const d = this.delay;
    this.delay = Math.min(this.delay * 2, 10000);
    this.setState('reconnecting', `${why}; retrying in ${(d / 1000).toFixed(1)} s`);
    clearTimeout(this.retryTimer);
    this.retryTimer = setTimeout(() => this.connect(), d);
  }

  /** Whether the connection's role may `set` and `reset` (tune and admin, PROTOCOL.md §3.11). */
  canTune() { return this.role === 'tune' || this.role === 'admin'; }

  /** Sends op with fields; resolves with the reply, rejects with an error message. */
  request(op, fields = {}, timeoutMs = 20000) {
    return new Promise((resolve, reject) => {
      if (!this.ws || this.ws.readyState !== WebSocket.OPEN) { reject({ code: 'closed', message: 'not connected' }); return; }
      const id = this.nextId++;
      const timer = setTimeout(() => { this.pending.delete(id); reject({ code: 'timeout', message: `${op}: no reply` }); }, timeoutMs);
      this.pending.set(id, { resolve, reject, timer });
      this.ws.send(JSON.stringify({ op, id, ...fields }));
    });
  }
}
