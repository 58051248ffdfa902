// The curvenet viewer: a hand-written WebGL2 renderer over the service's
// read-only viewer endpoints (server/src/service/viewer/mod.rs). No libraries.
// ES modules, all built into the binary and served from /viewer/js/
// (assets.rs lists them), one concern each:
//
//   main.js      this: the scripting API, then input bound and the page started
//   dom.js       the page's elements and message line (the leaf)
//   state.js     what is shown: source, data, frames, pose, layers, picks
//   context.js   the WebGL2 context and the renderer's programs (gl.js)
//   api.js       fetch and the token
//   math.js, camera.js, shapes.js   vectors and matrices, the orbit camera,
//                frame boxes and vertex normals
//   scene.js     the GPU objects of the binding and of the pose shown
//   render.js    drawing the layers, one queued draw per animation frame
//   pick.js      picking a face
//   frames.js    frames from the server, the slider and playback
//   panel.js     counts, timings, warnings, a refusal; framing a warning
//   loading.js   opening a stage or a binding (or drawing its refusal)
//   knots.js     the picked knot and its panel (adjust.js: axes, fields)
//   live.js      the user's adjustments posted live, and their export
//   input.js     pointer, wheel, keys and the panel's controls
//   highlight.js what warnings and refusals name, drawn and framed
//
// Data flow: GET v1/viewer/stages (stages opened with --open-stage) or a
// binding id from ?binding=ID → GET v1/bindings/{id}/viewer-data (mesh in
// core's own triangulation, cut-mesh, curvenets, neutral frames, counts,
// warnings with their highlights) → frames solved on the server (GET
// v1/viewer/stages/{i}/frames/{k}, or POST v1/bindings/{id}/viewer-frame for
// a binding without a stage), cached here by frame index for playback. A
// stage whose binding is refused is drawn from GET
// v1/viewer/stages/{i}/refusal: the mesh, the curvenets and the element the
// error names, highlighted and framed.
//
// Curvenet Adjustments (adjust.js): every knot's orientation frame is drawn
// in the deformed view (frames carry knot_orientations); a click near a
// knot picks it, and the panel's fields adjust it. Each change posts the
// frame again with the user's adjustments (POST v1/viewer/stages/{i}/frames/{k},
// or the binding's viewer-frame), debounced, one request in flight, the
// latest change sent when it returns. The user's adjustments belong to the
// frame they were made at (another frame shows the stage's own); "export"
// downloads them as a USD layer over the stage (POST v1/viewer/stages/{i}/export).
//
// For tests and scripts, <body> carries data-state (loading | ready |
// refused | error) and data-rendered (the frame index of the last drawn
// frame, "-1" before the first, "refusal" for a refused stage); every count
// in the side panel is an element with data-stat="name" and
// data-value="number"; #problem-label names a refusal's element
// (data-code, data-element, data-curvenet, data-spline, data-segment,
// data-sample, data-faces, data-vertices) and so does every warning's <li>.
// data-knot is the picked knot ("curvenet:knot"), data-adjusted counts the
// frames drawn with the user's adjustments. window.curvenetViewer is the
// scripting API (pickKnot, setAdjustment, lastFramePoints, exportLayer, ...).
import { body } from './dom.js';
import { view, userSpecs } from './state.js';
import { camera } from './camera.js';
import { requestDraw } from './render.js';
import { pickAt } from './pick.js';
import { showFrame } from './frames.js';
import { select } from './panel.js';
import { open, start } from './loading.js';
import { knotScreenPosition, pickKnot } from './knots.js';
import { setAdjustment, resetKnot, exportLayer } from './live.js';
import { bindInput } from './input.js';

/** The points of the frame shown, as drawn (f32 values, flat xyz). */
function lastFramePoints() {
  const frame = view.frames.get(view.frame);
  return frame ? Array.from(frame.points) : null;
}

// For scripts, tests and the browser console.
window.curvenetViewer = {
  view, camera, pickAt, showFrame, open, select, requestDraw,
  pickKnot, setAdjustment, resetKnot, lastFramePoints, exportLayer, knotScreenPosition,
  adjustments: () => userSpecs(view.frame),
};

bindInput();
body.dataset.rendered = '-1';
start();
