// Opening a source: the stages list, a stage (bound, or drawn refused) or
// a binding id; its data fetched, the scene and the panel rebuilt, the
// first frame shown.
import { api } from './api.js';
import { $, body, say, fail } from './dom.js';
import { free } from './context.js';
import { view } from './state.js';
import { buildStatic, freeStatic } from './scene.js';
import { requestDraw } from './render.js';
import { setPicked } from './pick.js';
import { showFrame, stopPlay } from './frames.js';
import { fillPanel, frameHighlight } from './panel.js';
import { fillKnotPanel } from './knots.js';
import { onFieldInput } from './live.js';
import { fitCamera, faceTheCurvenet } from './camera.js';
import { buildFields } from './adjust.js';
import { refusalData } from './highlight.js';

export async function open(source) {
  stopPlay();
  view.generation++;
  const generation = view.generation;
  body.dataset.state = 'loading';
  body.dataset.rendered = '-1';
  say('loading…');
  try {
    let id;
    if (source.kind === 'stage') {
      let s;
      try {
        s = await api(`v1/viewer/stages/${source.index}`);
      } catch (e) {
        // A binding refused for its input (422): draw what was refused.
        if (e.status !== 422) throw e;
        const refusal = await api(`v1/viewer/stages/${source.index}/refusal`);
        if (generation !== view.generation) return;
        showRefusal(source, refusal);
        return;
      }
      view.stageInfo = s;
      view.times = s.times;
      id = s.binding.binding_id;
    } else {
      id = source.id;
      view.stageInfo = null;
      view.times = [null];
    }
    const data = await api(`v1/bindings/${id}/viewer-data`);
    if (generation !== view.generation) return;
    freeStatic(view.gpu);
    if (view.dyn) for (const s of view.dyn.sets) free(s);
    view.dyn = null;
    view.dynKey = '';
    view.source = source.kind === 'stage' ? source : { kind: 'binding', id };
    view.data = data;
    view.frames = new Map();
    view.frame = 0;
    view.gpu = buildStatic(data);
    // The cage layer is offered (and on) when the binding has a cage.
    $('cage-layer').hidden = !data.cage;
    view.selected = -1;
    view.user = new Map();
    view.knot = null;
    buildFields($('adjust-table'), data.diagonal || 1, onFieldInput);
    setPicked(-1);
    fillKnotPanel();
    fillPanel(data);
    const url = new URL(location.href);
    url.search = source.kind === 'stage' ? `?stage=${source.index}` : `?binding=${id}`;
    history.replaceState(null, '', url);
    $('frame').max = String(Math.max(0, view.times.length - 1));
    $('frame').disabled = view.times.length < 2;
    $('play').disabled = view.times.length < 2;
    fitCamera(data.mesh.points);
    faceTheCurvenet(data);
    say('');
    await showFrame(0);
    if (generation !== view.generation) return;
    body.dataset.state = 'ready';
    requestDraw();
  } catch (e) {
    if (generation === view.generation) fail(e);
  }
}

// A stage whose binding is refused: the mesh and the curvenets in the
// projection pose, the element the error names highlighted and framed, the
// error in the panel. No frames.
function showRefusal(source, refusal) {
  const data = refusalData(refusal);
  freeStatic(view.gpu);
  if (view.dyn) for (const s of view.dyn.sets) free(s);
  view.dyn = null;
  view.dynKey = '';
  view.source = source;
  view.stageInfo = refusal.stage;
  view.times = [];
  view.data = data;
  view.frames = new Map();
  view.frame = 0;
  view.gpu = buildStatic(data);
  $('cage-layer').hidden = true;
  view.selected = 0;
  view.user = new Map();
  view.knot = null;
  fillKnotPanel();
  setPicked(-1);
  fillPanel(data);
  const url = new URL(location.href);
  url.search = `?stage=${source.index}`;
  history.replaceState(null, '', url);
  $('frame').max = '0';
  $('frame').disabled = true;
  $('play').disabled = true;
  $('frame-label').textContent = 'binding refused';
  $('solve-label').textContent = '';
  frameHighlight(refusal.highlight);
  say(`${refusal.code}: ${refusal.message}`);
  body.dataset.state = 'refused';
  requestDraw();
}

export async function start() {
  const params = new URLSearchParams(location.search);
  let stages = [];
  try {
    stages = (await api('v1/viewer/stages')).stages;
  } catch (e) {
    fail(e);
    return;
  }
  const select = $('source-select');
  select.replaceChildren();
  for (const s of stages) {
    const o = document.createElement('option');
    o.value = `stage:${s.index}`;
    o.textContent = `${s.mesh} — ${s.stage.split('/').pop()} (${s.times.length} frame${s.times.length === 1 ? '' : 's'})`;
    select.append(o);
  }
  if (params.get('binding')) {
    const o = document.createElement('option');
    o.value = 'binding';
    o.textContent = `binding ${params.get('binding').slice(0, 16)}…`;
    select.append(o);
    select.value = 'binding';
    $('binding-id').value = params.get('binding');
    open({ kind: 'binding', id: params.get('binding') });
  } else if (stages.length) {
    const index = Math.min(stages.length - 1, Number(params.get('stage') || 0));
    select.value = `stage:${index}`;
    open({ kind: 'stage', index });
  } else {
    body.dataset.state = 'ready';
    say('No stage is open: start the server with --open-stage STAGE (or curvenet inspect STAGE --serve), or enter a binding id.');
    requestDraw();
  }
}
