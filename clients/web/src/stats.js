// stats.js — per-stream delivery statistics for the overlay: frames received and drawn per
// second, kB/s, latency from the header's server_time_us (same-host clocks; clamped at 0, a
// clock that is a little ahead must not show a negative latency), and frames skipped, kept
// apart: per kind, the gaps in seq (frames the server dropped for this connection: latest
// frame wins, PROTOCOL.md §8.1), and frames this page received but replaced with a newer one
// before drawing them.
const KIND_NAMES = { 1: 'particles', 2: 'texture', 3: 'light rig', 4: 'lens table' };

export const STATS_HELP =
  'fps in: frames received per second (all kinds) · drawn: frames drawn per second · kB/s: bytes received · ' +
  'ms: age of the frames on arrival (server clock to this page, clamped at 0) · skipped by server: frames the ' +
  'server dropped for this page, per kind (it always sends the newest) · replaced: frames that arrived while an ' +
  'older one of the same kind still waited to be drawn';

export class StreamStats {
  constructor() {
    this.kindsSeen = new Set();
    this.lastSeq = new Map();
    this.lastAt = new Map(); // kind -> Date.now() of its latest frame
    this.totalFrames = 0;
    this.totalDrawn = 0;
    this.serverSkipped = new Map(); // kind -> frames the server dropped
    this.replaced = 0;
    this.acc = { frames: 0, drawn: 0, bytes: 0, lat: 0 };
    this.rate = { fps: 0, drawn: 0, kBps: 0, latency: NaN };
  }

  frame(h, bytes) {
    const prev = this.lastSeq.get(h.kind), now = Date.now();
    if (prev !== undefined && h.seq > prev + 1n)
      this.serverSkipped.set(h.kind, (this.serverSkipped.get(h.kind) ?? 0) + Number(h.seq - prev - 1n));
    this.lastSeq.set(h.kind, h.seq);
    this.lastAt.set(h.kind, now);
    this.kindsSeen.add(h.kind);
    this.totalFrames++;
    this.acc.frames++;
    this.acc.bytes += bytes;
    this.acc.lat += Math.max(0, now - Number(h.serverTimeUs) / 1000);
  }

  // A frame that arrived before the previous one of its kind was drawn.
  replace() { this.replaced++; }

  drawn() { this.totalDrawn++; this.acc.drawn++; }

  get skipped() { return [...this.serverSkipped.values()].reduce((a, b) => a + b, 0); }

  tick(seconds) {
    const a = this.acc;
    this.rate = { fps: a.frames / seconds, drawn: a.drawn / seconds, kBps: a.bytes / 1024 / seconds, latency: a.frames ? a.lat / a.frames : NaN };
    this.acc = { frames: 0, drawn: 0, bytes: 0, lat: 0 };
  }

  skippedText() {
    const parts = [...this.serverSkipped].filter(([, n]) => n).map(([k, n]) => `${KIND_NAMES[k] ?? `kind ${k}`} ${n}`);
    return `skipped by server: ${parts.length ? parts.join(', ') : 0} · replaced ${this.replaced}`;
  }

  text() {
    const r = this.rate;
    return `${r.fps.toFixed(1)} fps in · ${r.drawn.toFixed(1)} drawn · ${r.kBps.toFixed(1)} kB/s · ` +
      `${Number.isNaN(r.latency) ? '–' : r.latency.toFixed(1)} ms\n${this.skippedText()}`;
  }

  // For streams that send a frame only on change (a compound eye's lens table, kind 4).
  tableText(rev) {
    const at = this.lastAt.get(4);
    return at === undefined ? 'waiting for the lens table' :
      `lens table rev ${rev} · received ${((Date.now() - at) / 1000).toFixed(0)} s ago (sent on change only)`;
  }
}
