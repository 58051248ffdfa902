// Curvenet Adjustments in the viewer: every knot's orientation frame drawn
// as three short axes, picking a knot on screen, and the panel's fields
// (translate in model units, rotate in degrees about X then Y then Z,
// scale, all in the knot's frame, as the service takes them).
import { pick3, vadd, vscale } from './math.js';

/** Axis colours: x red, y green, z blue. */
export const AXIS_COLORS = [[0.95, 0.25, 0.25, 1], [0.3, 0.85, 0.35, 1], [0.35, 0.55, 1.0, 1]];
/** Axis length, as a fraction of the bounding-box diagonal. */
export const AXIS_LENGTH = 0.025;
/** A click picks the nearest knot within this many CSS pixels. */
export const PICK_RADIUS = 12;

/** The key of a knot in maps. */
export const knotKey = (curvenet, knot) => `${curvenet}:${knot}`;

/**
 * Flat segment pairs of the x, y and z axes at every knot: knot `i` of
 * curvenet `k` (pool index `data.curvenets[k].knots[i]`) sits at sample `i`
 * of the pose `nets[k].samples`; its orientation is row-major with the
 * axes as columns (`orientations[k][pool index]`).
 */
export function knotAxes(data, nets, orientations, length) {
  const axes = [[], [], []];
  if (!orientations) return axes;
  data.curvenets.forEach((c, k) => {
    const o = orientations[k] || {};
    const samples = nets[k].samples;
    (c.knots || []).forEach((p, i) => {
      const m = o[String(p)];
      if (!m) return;
      const q = pick3(samples, i);
      for (let j = 0; j < 3; j++) axes[j].push(...q, ...vadd(q, vscale([m[j], m[3 + j], m[6 + j]], length)));
    });
  });
  return axes;
}

/** The position of knot `knot` (pool index) of curvenet `k` in the pose `nets`, or null. */
export function knotPosition(data, nets, k, knot) {
  const c = data.curvenets[k];
  const i = c && c.knots ? c.knots.indexOf(knot) : -1;
  return i < 0 ? null : pick3(nets[k].samples, i);
}

/** Client coordinates of a model point through the column-major `mvp`, or null behind the eye. */
export function project(mvp, rect, p) {
  const clip = [0, 1, 2, 3].map((r) => mvp[r] * p[0] + mvp[4 + r] * p[1] + mvp[8 + r] * p[2] + mvp[12 + r]);
  if (clip[3] <= 0) return null;
  return {
    x: rect.left + (clip[0] / clip[3] + 1) / 2 * rect.width,
    y: rect.top + (1 - clip[1] / clip[3]) / 2 * rect.height,
    depth: clip[2] / clip[3],
  };
}

/** The knot nearest the client point (x, y) within `radius` pixels: {curvenet, knot} or null. */
export function nearestKnot(data, nets, mvp, rect, x, y, radius) {
  let best = null;
  data.curvenets.forEach((c, k) => {
    (c.knots || []).forEach((p, i) => {
      const s = project(mvp, rect, pick3(nets[k].samples, i));
      if (!s) return;
      const d = Math.hypot(s.x - x, s.y - y);
      if (d <= radius && (!best || d < best.d - 0.5 || (Math.abs(d - best.d) <= 0.5 && s.depth < best.depth))) {
        best = { curvenet: k, knot: p, d, depth: s.depth };
      }
    });
  });
  return best && { curvenet: best.curvenet, knot: best.knot };
}

const GROUPS = [
  { name: 'translate', label: 'translate', identity: 0 },
  { name: 'rotate', label: 'rotate °', identity: 0 },
  { name: 'scale', label: 'scale', identity: 1 },
];

/**
 * Builds the nine fields (a slider and a number per axis of translate,
 * rotate, scale) into `table`; `diagonal` sets the translate range (±10%
 * of it). `onInput()` is called on every change.
 */
export function buildFields(table, diagonal, onInput) {
  const body = table.tBodies[0];
  body.replaceChildren();
  const ranges = {
    translate: { min: -0.1 * diagonal, max: 0.1 * diagonal, step: diagonal / 4000 },
    rotate: { min: -180, max: 180, step: 0.5 },
    scale: { min: 0.1, max: 3, step: 0.01 },
  };
  for (const g of GROUPS) {
    ['x', 'y', 'z'].forEach((axis, j) => {
      const tr = document.createElement('tr');
      const name = document.createElement('td');
      name.textContent = `${g.label} ${axis}`;
      const cell = document.createElement('td');
      const slider = document.createElement('input');
      const number = document.createElement('input');
      slider.type = 'range';
      number.type = 'number';
      for (const input of [slider, number]) {
        Object.assign(input, ranges[g.name]);
        input.value = String(g.identity);
        input.dataset.group = g.name;
        input.dataset.axis = String(j);
      }
      number.min = ''; // typed values may leave the slider's range
      number.max = '';
      number.id = `adjust-${g.name}-${axis}`;
      slider.setAttribute('aria-label', `${g.label} ${axis}`);
      slider.addEventListener('input', () => { number.value = slider.value; onInput(); });
      number.addEventListener('input', () => { slider.value = number.value; onInput(); });
      cell.append(slider, number);
      tr.append(name, cell);
      body.append(tr);
    });
  }
}

/** Writes an adjustment's values into the fields (absent: no change). */
export function setFields(table, spec) {
  for (const g of GROUPS) {
    const v = (spec && spec[g.name]) || [g.identity, g.identity, g.identity];
    for (const input of table.querySelectorAll(`input[data-group=${g.name}]`)) {
      input.value = String(+Number(v[Number(input.dataset.axis)]).toPrecision(7));
    }
  }
}

/** The fields' values: {translate, rotate, scale}. */
export function readFields(table) {
  const out = {};
  for (const g of GROUPS) {
    out[g.name] = [0, 1, 2].map((j) => {
      const v = Number(table.querySelector(`input[type=number][data-group=${g.name}][data-axis="${j}"]`).value);
      return Number.isFinite(v) ? v : g.identity;
    });
  }
  return out;
}
