// The user's adjustments, live: each change posts the frame again with
// them (debounced, one request in flight, the latest change sent when it
// returns), and the export of them as a USD layer over the stage.
import { token } from './api.js';
import { $, body, say } from './dom.js';
import { view } from './state.js';
import { afterDraw, requestDraw } from './render.js';
import { requestFrame, received } from './frames.js';
import { shownAdjustment, fillKnotCount, fillKnotPanel } from './knots.js';
import { knotKey, readFields } from './adjust.js';
import { userSpecs } from './state.js';

export function onFieldInput() {
  if (!view.knot) return;
  const shown = shownAdjustment();
  const v = readFields($('adjust-table'));
  setAdjustment({
    curvenet: view.knot.curvenet, knot: view.knot.knot, translate: v.translate, rotate: v.rotate, scale: v.scale,
    attach_tangents: $('adjust-attach').checked,
    tangent_translates: (shown && shown.spec.tangent_translates) || [],
  }, false).catch(() => {});
}

// Live updates: debounced, one request in flight; a change made meanwhile
// is sent when it returns. The promises of setAdjustment resolve once the
// frame with the latest adjustments is drawn.
const live = { timer: null, inFlight: false, again: false, refill: false, waiters: [] };

/**
 * Sets the user's adjustment of a knot at the frame shown (an
 * AdjustmentSpec: curvenet, knot, translate, rotate, scale, attach_tangents,
 * tangent_translates). Resolves with the frame drawn.
 */
export function setAdjustment(spec, refill = true) {
  const k = view.frame;
  if (!view.user.has(k)) view.user.set(k, new Map());
  view.user.get(k).set(knotKey(spec.curvenet, spec.knot), spec);
  return refresh(refill);
}

/** Clears the user's adjustment of the picked knot at the frame shown. */
export function resetKnot() {
  if (!view.knot) return Promise.resolve(null);
  const m = view.user.get(view.frame);
  if (m) m.delete(knotKey(view.knot.curvenet, view.knot.knot));
  return refresh(true);
}

function refresh(refill) {
  live.refill = live.refill || refill;
  fillKnotCount();
  const done = new Promise((resolve, reject) => live.waiters.push({ resolve, reject }));
  if (live.timer) clearTimeout(live.timer);
  live.timer = setTimeout(runRefresh, 40);
  return done;
}

async function runRefresh() {
  live.timer = null;
  if (live.inFlight) { live.again = true; return; }
  live.inFlight = true;
  const k = view.frame, generation = view.generation;
  let result = null, error = null;
  try {
    const frame = await requestFrame(k);
    if (generation === view.generation) {
      received(k, frame);
      $('solve-label').textContent = `solve ${frame.solve_ms.toFixed(1)} ms`;
      say('');
      result = frame;
    }
  } catch (e) {
    error = e;
    say(`adjustment: ${e.message}`);
  }
  live.inFlight = false;
  if (live.again || live.timer) {
    live.again = false;
    if (!live.timer) runRefresh();
    return; // the waiters wait for the latest
  }
  if (live.refill) fillKnotPanel();
  else fillKnotCount();
  live.refill = false;
  const waiters = live.waiters.splice(0);
  if (error) {
    for (const w of waiters) w.reject(error);
    return;
  }
  afterDraw.push(() => {
    if (result) body.dataset.adjusted = String(++view.adjusted);
    for (const w of waiters) w.resolve(result);
  });
  requestDraw();
}

/** The user's adjustments at the frame shown as a USD layer (text), from the server. */
export async function exportLayer() {
  const s = view.source;
  if (!s || s.kind !== 'stage') throw new Error('export needs a stage opened with --open-stage');
  const headers = { 'Content-Type': 'application/json' };
  if (token) headers.Authorization = `Bearer ${token}`;
  const response = await fetch(`v1/viewer/stages/${s.index}/export`, {
    method: 'POST', headers, body: JSON.stringify({ frame: view.frame, adjustments: userSpecs(view.frame) }),
  });
  const text = await response.text();
  if (!response.ok) {
    let message = text;
    try { const j = JSON.parse(text); message = `${j.code}: ${j.message}`; } catch (_) { /* not JSON */ }
    throw new Error(message);
  }
  return text;
}
