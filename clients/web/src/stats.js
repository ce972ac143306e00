// stats.js — per-stream delivery statistics for the overlay: frames received and drawn per
// second, kB/s, latency from the header's server_time_us (same-host clocks), and frames
// skipped (gaps in seq, per kind: latest frame wins, PROTOCOL.md §8.1, plus frames this
// page replaced before drawing them).
export class StreamStats {
  constructor() {
    this.kindsSeen = new Set();
    this.lastSeq = new Map();
    this.totalFrames = 0;
    this.totalDrawn = 0;
    this.skipped = 0;
    this.acc = { frames: 0, drawn: 0, bytes: 0, lat: 0 };
    this.rate = { fps: 0, drawn: 0, kBps: 0, latency: NaN };
  }

  frame(h, bytes) {
    const prev = this.lastSeq.get(h.kind);
    if (prev !== undefined && h.seq > prev + 1n) this.skipped += Number(h.seq - prev - 1n); // skipped by the server
    this.lastSeq.set(h.kind, h.seq);
    this.kindsSeen.add(h.kind);
    this.totalFrames++;
    this.acc.frames++;
    this.acc.bytes += bytes;
    this.acc.lat += Date.now() - Number(h.serverTimeUs) / 1000;
  }

  drawn() { this.totalDrawn++; this.acc.drawn++; }

  tick(seconds) {
    const a = this.acc;
    this.rate = { fps: a.frames / seconds, drawn: a.drawn / seconds, kBps: a.bytes / 1024 / seconds, latency: a.frames ? a.lat / a.frames : NaN };
    this.acc = { frames: 0, drawn: 0, bytes: 0, lat: 0 };
  }

  text() {
    const r = this.rate;
    return `${r.fps.toFixed(1)} fps in · ${r.drawn.toFixed(1)} drawn · ${r.kBps.toFixed(1)} kB/s · ` +
      `${Number.isNaN(r.latency) ? '–' : r.latency.toFixed(1)} ms · skipped ${this.skipped}`;
  }
}
