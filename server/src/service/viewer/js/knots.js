// The picked knot (Curvenet Adjustments): picking near a knot in the
// deformed view, its place on screen, and the panel's fields showing its
// adjustment at the frame shown (the user's, else the stage's).
import { $, canvas, body } from './dom.js';
import { view, userSpecs } from './state.js';
import { resize, matrices, requestDraw } from './render.js';
import { PICK_RADIUS, knotKey, knotPosition, project, nearestKnot, setFields } from './adjust.js';

export function knotAt(clientX, clientY) {
  const frame = view.frames.get(view.frame);
  if (!view.data || view.data.refused || view.pose !== 'deformed' || !view.layers.knots || !frame || !frame.knot_orientations) return null;
  return nearestKnot(view.data, frame.curvenets, matrices().mvp, canvas.getBoundingClientRect(), clientX, clientY, PICK_RADIUS);
}

/** Client coordinates of knot `knot` (pool index) of curvenet `k` in the frame shown, or null. */
export function knotScreenPosition(k, knot) {
  const frame = view.frames.get(view.frame);
  if (!frame) return null;
  resize();
  const p = knotPosition(view.data, frame.curvenets, k, knot);
  const s = p && project(matrices().mvp, canvas.getBoundingClientRect(), p);
  return s && { x: s.x, y: s.y };
}

/** Picks knot `knot` (pool index) of curvenet `k`; false when it is not a knot. */
export function pickKnot(k, knot) {
  const c = view.data && view.data.curvenets[k];
  if (!c || !c.knots || !c.knots.includes(knot)) return false;
  view.knot = { curvenet: k, knot };
  fillKnotPanel();
  requestDraw();
  return true;
}

// The adjustment of the picked knot at the frame shown: the user's, else
// what the frame applied (the stage's), else none.
export function shownAdjustment() {
  if (!view.knot) return null;
  const key = knotKey(view.knot.curvenet, view.knot.knot);
  const mine = view.user.get(view.frame);
  if (mine && mine.has(key)) return { spec: mine.get(key), source: 'yours' };
  const frame = view.frames.get(view.frame);
  const applied = frame && (frame.adjustments || []).find((a) => a.curvenet === view.knot.curvenet && a.knot === view.knot.knot);
  return applied ? { spec: applied, source: applied.prim ? `the stage's ${applied.prim}` : "the stage's" } : null;
}

export function fillKnotCount() {
  const count = userSpecs(view.frame).length;
  $('adjust-count').textContent = count ? `${count} adjusted at frame ${view.times[view.frame]}` : '';
  $('adjust-count').dataset.value = String(count);
  $('adjust-export').disabled = !(view.source && view.source.kind === 'stage' && count);
}

export function fillKnotPanel() {
  const label = $('knot-label'), fields = $('adjust-fields');
  fillKnotCount();
  if (!view.knot) {
    label.textContent = 'click near a knot (a spline end) in the deformed view to adjust it';
    delete body.dataset.knot;
    fields.hidden = true;
    return;
  }
  const { curvenet, knot } = view.knot;
  body.dataset.knot = knotKey(curvenet, knot);
  const shown = shownAdjustment();
  const name = view.stageInfo && view.stageInfo.curvenets ? view.stageInfo.curvenets[curvenet] : `curvenet ${curvenet}`;
  label.textContent = `${name}, knot ${knot}: ${shown ? `adjusted (${shown.source})` : 'not adjusted'}`;
  label.dataset.curvenet = String(curvenet);
  label.dataset.knot = String(knot);
  fields.hidden = false;
  setFields($('adjust-table'), shown && shown.spec);
  $('adjust-attach').checked = !shown || shown.spec.attach_tangents !== false;
}
