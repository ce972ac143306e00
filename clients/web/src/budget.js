// budget.js — how many particles the page asks a particle stream for (`subscribe`'s
// max_particles, PROTOCOL.md §3.5): no more than it can draw, and no more than its link carries
// at the stream's rate. The daemon serves the largest step of its 1-2-5 ladder at or below the
// value asked, a subset drawn in proportion and stable from frame to frame, and says in each
// frame's header how many particles it stands for (`total`), so the view keeps the flame's
// brightness (flame.js).
//
// Every 2 s (main.js's pacing) nextBudget looks at the stream's latest frames:
// * frames arriving late while the page draws at 20 frames/s or more (the link is the
//   bottleneck): the budget drops to what the bytes received per second carry at the stream's
//   rate, at most half of what it was — before the page lowers the stream's rate, so the flame
//   keeps moving and loses detail first;
// * the page drawing under 20 frames/s with more than DRAW_SLOW_FLOOR particles: half as many
//   (the draw is the bottleneck; below that the particles are not what makes it slow, and the
//   page's rate caps take over);
// * frames on time at the stream's full rate with particles left out: one ladder step up, to at
//   most what the page draws (DRAW_MAX, or ?particles=N).
export const BUDGET_LADDER = [1000, 2000, 5000, 10000, 20000, 50000, 100000, 200000, 500000, 1000000, 2000000];
// What the page draws at the browser's frame rate on a desktop GPU in every mode (pbvr: 8 render
// particles per hot particle).
export const DRAW_MAX = 200000;
export const DRAW_SLOW_FLOOR = 20000;

// The largest ladder step at or below n (the smallest step below it).
export function ladderFloor(n) {
  let step = BUDGET_LADDER[0];
  for (const s of BUDGET_LADDER) if (s <= n) step = s;
  return step;
}

// The page's own limit: ?particles=N, else DRAW_MAX.
export function drawLimit(query) {
  const n = Number(query);
  return ladderFloor(Number.isFinite(n) && n > 0 ? n : DRAW_MAX);
}

// The next budget of a stream, or the same value. m: { budget, limit (drawLimit), full (the
// stream's particles a frame: the header's total, or count when the frame is whole), late,
// onTime (frames within 250 / 50 ms of the stream's best latency), atTopRate (the page takes
// the stream's full fps), bytesPerSec (received), bytesPerParticle (of recent frames), fps (the
// rate asked), drawFps (frames the page drew a second) }.
export function nextBudget(m) {
  const served = Math.min(m.budget, m.full || m.budget);
  if (m.drawFps < 20) return served > DRAW_SLOW_FLOOR ? ladderFloor(Math.max(DRAW_SLOW_FLOOR, served / 2)) : m.budget;
  if (m.late && served > BUDGET_LADDER[0]) {
    const carried = m.bytesPerParticle > 0 && m.fps > 0 ? (0.8 * m.bytesPerSec) / (m.fps * m.bytesPerParticle) : Infinity;
    return ladderFloor(Math.min(served / 2, carried));
  }
  if (m.onTime && m.atTopRate && m.full > m.budget && m.budget < m.limit)
    return BUDGET_LADDER.find((s) => s > m.budget && s <= m.limit) ?? m.budget;
  return m.budget;
}
