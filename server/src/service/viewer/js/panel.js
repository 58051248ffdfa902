// The side panel: the binding's counts and timings (data-stat), the
// warnings with what they name, a refusal's error; framing a warning's
// element (or the whole mesh).
import { $, body } from './dom.js';
import { view } from './state.js';
import { camera, fitCamera, fitBox, faceTheCurvenet } from './camera.js';
import { describe, label as elementLabel } from './highlight.js';
import { requestDraw } from './render.js';

const STAT_LABELS = {
  mesh_vertices: 'mesh vertices', mesh_faces: 'mesh faces', samples: 'samples', segments: 'segments',
  cut_vertices: 'cut-vertices', cut_faces: 'cut-faces', cut_halfedges: 'cut halfedges', cracks: 'cracks',
  islands_removed: 'islands removed', chord_paths: 'segments inside one face', straightest_paths: 'straightest paths',
  fallback_paths: 'fallback paths', segments_left_out: 'segments left out', detours: 'detours', unknowns: 'unknowns',
  constraints: 'constraint rows', factor_nonzeros: 'factor nonzeros',
};

export function fillPanel(data) {
  fillProblem(data.refused);
  const b = data.binding;
  const stats = $('stats').tBodies[0];
  stats.replaceChildren();
  const timings = $('timings').tBodies[0];
  timings.replaceChildren();
  if (!b) {
    $('binding-label').textContent = 'refused: no binding';
    fillWarnings([], []);
    return;
  }
  $('binding-label').textContent = `binding ${b.binding_id}`;
  const row = (table, label, value, stat, text) => {
    const tr = document.createElement('tr');
    const a = document.createElement('td'), v = document.createElement('td');
    a.textContent = label;
    v.textContent = text != null ? text : Number(value).toLocaleString('en-US');
    if (stat) {
      v.dataset.stat = stat;
      v.dataset.value = String(value);
    }
    tr.append(a, v);
    table.append(tr);
  };
  for (const [k, label] of Object.entries(STAT_LABELS)) if (k in b.stats) row(stats, label, b.stats[k], k);
  row(stats, 'curvenets', data.curvenets.length, 'curvenets');
  const count = (key) => data.curvenets.reduce((s, c) => s + c[key].length, 0);
  row(stats, 'intersections', count('intersections'), 'intersections');
  row(stats, 'anchors', count('anchors'), 'anchors');
  row(stats, 'blend shapes', b.blend_shapes, 'blend_shapes');
  row(stats, 'cache size', b.size_bytes, 'size_bytes', `${(b.size_bytes / 1048576).toFixed(2)} MiB`);
  for (const [k, v] of Object.entries(b.timings)) {
    const tr = document.createElement('tr');
    const a = document.createElement('td'), c = document.createElement('td');
    a.textContent = k.replace(/_ms$/, '');
    c.textContent = v.toFixed(1);
    c.dataset.timing = k;
    tr.append(a, c);
    timings.append(tr);
  }
  fillWarnings(data.warnings, data.highlights || []);
}

// The warnings, each with what it names; a click on one that names
// something frames it (a second click frames the whole mesh again).
function fillWarnings(warnings, highlights) {
  const list = $('warning-list');
  list.replaceChildren();
  warnings.forEach((w, i) => {
    const li = document.createElement('li');
    const code = document.createElement('code');
    code.textContent = w.code;
    li.append(code, ' ', w.message);
    li.dataset.code = w.code;
    const h = highlights[i];
    if (h && h.element !== 'none') {
      describe(li, h);
      li.dataset.index = String(i);
      li.classList.add('locatable');
      li.title = `click to frame ${elementLabel(h)}`;
      li.addEventListener('click', () => select(view.selected === i ? -1 : i));
    }
    list.append(li);
  });
  if (!warnings.length) {
    const li = document.createElement('li');
    li.textContent = 'none';
    list.append(li);
  }
  $('warning-count').textContent = `(${warnings.length})`;
  $('warning-count').dataset.value = String(warnings.length);
}

// The refusal's error and the element it names (hidden for a binding).
function fillProblem(refusal) {
  const section = $('problem'), text = $('problem-label');
  section.hidden = !refusal;
  for (const k of Object.keys(text.dataset)) delete text.dataset[k];
  if (!refusal) {
    text.textContent = '';
    return;
  }
  describe(text, refusal.highlight);
  text.replaceChildren();
  const code = document.createElement('code');
  code.textContent = refusal.code;
  const what = document.createElement('strong');
  what.textContent = elementLabel(refusal.highlight);
  text.append(code, ' ', refusal.message, document.createElement('br'), 'highlighted: ', what);
}

// Frames highlight `i` of the data (or, with -1, the whole mesh).
export function select(i) {
  view.selected = i;
  for (const li of document.querySelectorAll('#warning-list li')) li.classList.toggle('selected', li.dataset.index === String(i));
  frameHighlight(i >= 0 ? view.data.highlights[i] : null);
  requestDraw();
}

// Points the camera at a highlight's box (at least a quarter of the mesh
// wide, seen from outside the mesh), or at the whole mesh.
export function frameHighlight(h) {
  fitCamera(view.data.mesh.points);
  const whole = { target: camera.target, radius: camera.radius };
  if (!h || !h.bounds) {
    faceTheCurvenet(view.data);
    body.dataset.framed = 'mesh';
    return;
  }
  fitBox(h.bounds, 0.25 * whole.radius, whole.target);
  body.dataset.framed = h.element;
}
