// The curvenet viewer: a hand-written WebGL2 renderer over the service's
// read-only viewer endpoints (server/src/service/viewer.rs). No libraries.
// ES modules, all built into the binary and served from /viewer/js/:
// main.js (this: state, loading, drawing, input, panel), api.js (fetch and
// token), math.js, camera.js, gl.js (programs and GPU sets), highlight.js
// (what warnings and refusals name, drawn and framed).
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
import { api, token, setToken } from './api.js';
import { AXIS_COLORS, AXIS_LENGTH, PICK_RADIUS, knotKey, knotAxes, knotPosition, project, nearestKnot, buildFields, setFields, readFields } from './adjust.js';
import { vadd, vsub, vscale, vcross, pick3, indexSegments, multiply, perspective, lookAt } from './math.js';
import { camera, cameraFrame, fitCamera, fitBox, faceTheCurvenet } from './camera.js';
import { createRenderer } from './gl.js';
import { HIGHLIGHT, buildHighlights, describe, label as elementLabel, refusalData } from './highlight.js';

const $ = (id) => document.getElementById(id);
const canvas = $('view');
const body = document.body;

function say(text) { $('message').textContent = text || ''; }

const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });
if (!gl) {
  body.dataset.state = 'error';
  say('This browser has no WebGL2.');
  throw new Error('no WebGL2');
}
const renderer = createRenderer(gl);
const { shaded, flat, wide, pickProgram, buffer, wideLines, pointSet, free } = renderer;

// ------------------------------------------------------------ scene state

const view = {
  source: null,       // { kind: 'stage', index } or { kind: 'binding', id }
  data: null,         // ViewerData
  times: [],          // frame time codes (stage) or [null] (binding)
  frames: new Map(),  // frame index -> ViewerFrame
  frame: 0,
  pose: 'deformed',
  picked: -1,
  boxScale: 1,
  layers: { shaded: true, wire: false, cut: true, curvenet: true, frames: true, problems: true, knots: true, cage: true },
  selected: -1,       // the highlight (warning) clicked in the panel, framed
  gpu: null,          // static GPU objects of the binding
  dyn: null,          // GPU objects of the current pose
  dynKey: '',
  playing: false,
  generation: 0,      // bumps on every source change (stale fetches are dropped)
  knot: null,         // the picked knot: { curvenet, knot } (pool index)
  user: new Map(),    // frame index -> Map(knotKey -> AdjustmentSpec): the user's adjustments
  serial: 0,          // bumps with every frame fetched (the pose's GPU key)
  adjusted: 0,        // frames drawn with the user's adjustments (data-adjusted)
};

/** The user's adjustments at frame `k`, as the service takes them. */
function userSpecs(k) {
  const m = view.user.get(k);
  return m ? Array.from(m.values()) : [];
}

// The 12 edges of the scaled-frame boxes of every segment side (paper Fig. 5),
// as flat segment pairs, split by side.
function frameBoxes(samples, segments, frames, scale) {
  const sides = [[], []];
  if (!frames || frames.length < segments.length * 9) return sides; // a refused stage has none
  const nseg = segments.length / 2;
  for (let g = 0; g < nseg; g++) {
    const q0 = pick3(samples, segments[2 * g]), q1 = pick3(samples, segments[2 * g + 1]);
    const mid = vscale(vadd(q0, q1), 0.5);
    for (let side = 0; side < 2; side++) {
      const o = g * 18 + side * 9;
      const t = [frames[o], frames[o + 1], frames[o + 2]];
      const b = [frames[o + 3], frames[o + 4], frames[o + 5]];
      const n = [frames[o + 6], frames[o + 7], frames[o + 8]];
      const sign = side === 0 ? 1 : -1; // the binormal points to the plus side
      const corner = (i, j, k) => vadd(mid, vscale(vadd(vadd(vscale(t, i - 0.5), vscale(b, sign * j)), vscale(n, k - 0.5)), scale));
      const c = [];
      for (let i = 0; i < 2; i++) for (let j = 0; j < 2; j++) for (let k = 0; k < 2; k++) c.push(corner(i, j, k));
      const edges = [[0, 1], [2, 3], [4, 5], [6, 7], [0, 2], [1, 3], [4, 6], [5, 7], [0, 4], [1, 5], [2, 6], [3, 7]];
      for (const [x, y] of edges) sides[side].push(...c[x], ...c[y]);
    }
  }
  return sides;
}

function vertexNormals(points, triangles) {
  const normals = new Float32Array(points.length);
  for (let t = 0; t < triangles.length; t += 3) {
    const [a, b, c] = [triangles[t], triangles[t + 1], triangles[t + 2]];
    const pa = pick3(points, a), pb = pick3(points, b), pc = pick3(points, c);
    const n = vcross(vsub(pb, pa), vsub(pc, pa)); // area weighted
    for (const v of [a, b, c]) {
      normals[3 * v] += n[0]; normals[3 * v + 1] += n[1]; normals[3 * v + 2] += n[2];
    }
  }
  for (let v = 0; v < normals.length; v += 3) {
    const l = Math.hypot(normals[v], normals[v + 1], normals[v + 2]) || 1;
    normals[v] /= l; normals[v + 1] /= l; normals[v + 2] /= l;
  }
  return normals;
}

// Static GPU objects of a binding: what does not change with the frame.
function buildStatic(data) {
  const cut = data.cut;
  const meshTriangles = new Uint32Array(data.mesh.triangles);
  // Cut-mesh edges by kind (0 plain, 1 curve, 2 crack, 3 boundary), as cut-vertex pairs.
  const cutEdges = [[], [], [], []];
  for (let e = 0; e < cut.edge_kind.length; e++) cutEdges[cut.edge_kind[e]].push(cut.edges[2 * e], cut.edges[2 * e + 1]);
  // The mesh: one position/normal buffer pair (rewritten per pose) and its triangles and edges.
  const staticBuffers = [];
  const keep = (b) => { staticBuffers.push(b); return b; };
  const meshVao = gl.createVertexArray();
  gl.bindVertexArray(meshVao);
  const positions = keep(buffer(new Float32Array(data.mesh.points), gl.ARRAY_BUFFER, gl.DYNAMIC_DRAW));
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  const normals = keep(buffer(new Float32Array(data.mesh.points.length), gl.ARRAY_BUFFER, gl.DYNAMIC_DRAW));
  gl.enableVertexAttribArray(1);
  gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 0, 0);
  keep(buffer(meshTriangles, gl.ELEMENT_ARRAY_BUFFER));
  gl.bindVertexArray(null);
  const edgeVao = gl.createVertexArray();
  gl.bindVertexArray(edgeVao);
  gl.bindBuffer(gl.ARRAY_BUFFER, positions);
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  keep(buffer(new Uint32Array(data.mesh.edges), gl.ELEMENT_ARRAY_BUFFER));
  gl.bindVertexArray(null);
  // Picking: unshared triangles carrying their input face's id.
  const ntri = meshTriangles.length / 3;
  const ids = new Float32Array(ntri * 9);
  for (let t = 0; t < ntri; t++) {
    const id = data.mesh.triangle_face[t] + 1;
    const rgb = [(id & 255) / 255, ((id >> 8) & 255) / 255, ((id >> 16) & 255) / 255];
    for (let v = 0; v < 3; v++) ids.set(rgb, (t * 3 + v) * 3);
  }
  const pickVao = gl.createVertexArray();
  gl.bindVertexArray(pickVao);
  const pickPositions = keep(buffer(new Float32Array(ntri * 9), gl.ARRAY_BUFFER, gl.DYNAMIC_DRAW));
  gl.enableVertexAttribArray(0);
  gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
  keep(buffer(ids));
  gl.enableVertexAttribArray(1);
  gl.vertexAttribPointer(1, 3, gl.FLOAT, false, 0, 0);
  gl.bindVertexArray(null);
  return {
    buffers: staticBuffers,
    meshVao, positions, normals, triangleCount: meshTriangles.length, meshTriangles,
    edgeVao, edgeCount: data.mesh.edges.length,
    pickVao, pickPositions, pickCount: ntri * 3,
    cutEdges,
  };
}

function freeStatic(g) {
  if (!g) return;
  for (const vao of [g.meshVao, g.edgeVao, g.pickVao]) gl.deleteVertexArray(vao);
  for (const b of g.buffers) gl.deleteBuffer(b);
}

// The current pose: mesh points, cut-vertices, curvenet samples and frames
// (rest view: the frame's rest pose, else the projection pose, with the
// neutral or tracked curvenet; deformed view: the solve and the posed curvenet).
function currentPose() {
  const data = view.data;
  const frame = view.frames.get(view.frame);
  if (view.pose === 'deformed' && frame) {
    // A caged binding's frame carries its cage where it deforms the mesh (the posed cage).
    return { key: `d${view.frame}:${frame.serial}`, points: frame.points, cutPoints: frame.cut_points, nets: frame.curvenets, orientations: frame.knot_orientations, cage: frame.cage };
  }
  if (frame && frame.rest) {
    const r = frame.rest;
    return { key: `r${view.frame}`, points: r.points, cutPoints: r.cut_points, nets: r.curvenets };
  }
  return { key: 'r', points: data.mesh.points, cutPoints: data.cut.points, nets: data.curvenets, cage: data.cage && data.cage.points };
}

function buildDynamic() {
  const data = view.data, g = view.gpu;
  const pose = currentPose();
  const key = `${pose.key}|${view.boxScale}|${view.picked}|${view.selected}|${view.knot ? knotKey(view.knot.curvenet, view.knot.knot) : ''}`;
  if (view.dyn && view.dynKey === key) return;
  if (view.dyn) {
    for (const s of view.dyn.sets) free(s);
  }
  const points = pose.points instanceof Float32Array ? pose.points : new Float32Array(pose.points);
  gl.bindBuffer(gl.ARRAY_BUFFER, g.positions);
  gl.bufferSubData(gl.ARRAY_BUFFER, 0, points);
  gl.bindBuffer(gl.ARRAY_BUFFER, g.normals);
  gl.bufferSubData(gl.ARRAY_BUFFER, 0, vertexNormals(points, g.meshTriangles));
  const tri = g.meshTriangles, pick = new Float32Array(tri.length * 3);
  for (let i = 0; i < tri.length; i++) pick.set(points.subarray(3 * tri[i], 3 * tri[i] + 3), 3 * i);
  gl.bindBuffer(gl.ARRAY_BUFFER, g.pickPositions);
  gl.bufferSubData(gl.ARRAY_BUFFER, 0, pick);
  const nets = data.curvenets.map((c, k) => {
    const samples = pose.nets[k].samples;
    const [plus, minus] = frameBoxes(samples, c.segments, pose.nets[k].frames, view.boxScale);
    return {
      segments: wideLines(indexSegments(samples, c.segments)),
      samples: pointSet(samples),
      intersections: pointSet(samples, c.intersections),
      anchors: pointSet(samples, c.anchors),
      removed: pointSet(samples, c.removed_samples),
      far: pointSet(samples, c.far_samples),
      plus: wideLines(plus),
      minus: wideLines(minus),
    };
  });
  const cp = pose.cutPoints;
  const cut = {
    plain: pointSet(cp, g.cutEdges[0]),
    curve: wideLines(indexSegments(cp, g.cutEdges[1])),
    crack: wideLines(indexSegments(cp, g.cutEdges[2])),
    boundary: wideLines(indexSegments(cp, g.cutEdges[3])),
  };
  const picked = buildPicked(cp);
  const highlights = buildHighlights(renderer, data.highlights || [], { points, nets: pose.nets });
  // The knots' orientation axes and the picked knot (deformed view only: the frames carry the orientations).
  const axes = knotAxes(data, pose.nets, pose.orientations, AXIS_LENGTH * (data.diagonal || 1)).map((a) => wideLines(a));
  const at = view.knot && pose.orientations && knotPosition(data, pose.nets, view.knot.curvenet, view.knot.knot);
  const knot = at ? pointSet(new Float32Array(at)) : null;
  // The cage's wireframe (a caged binding), in the pose's cage.
  const cage = data.cage && pose.cage ? wideLines(indexSegments(pose.cage, data.cage.edges)) : null;
  const sets = nets.flatMap((n) => Object.values(n)).concat(Object.values(cut), picked ? picked.sets : [],
    highlights.flatMap((h) => [h.lines, h.points, h.faces]), axes, knot ? [knot] : [], cage ? [cage] : []);
  view.dyn = { nets, cut, picked, highlights, sets, points, axes, knot, cage };
  view.dynKey = key;
}

// Cut-faces of the picked input face: filled fans and their outlines.
function buildPicked(cutPoints) {
  if (view.picked < 0) return null;
  const cut = view.data.cut;
  const faces = [];
  for (let f = 0; f < cut.face_parent.length; f++) if (cut.face_parent[f] === view.picked) faces.push(f);
  const fills = [], outlines = [];
  for (const f of faces) {
    const vs = cut.face_vertices.slice(cut.face_start[f], cut.face_start[f + 1]);
    const fill = [];
    for (let k = 1; k + 1 < vs.length; k++) fill.push(vs[0], vs[k], vs[k + 1]);
    const outline = [];
    for (let k = 0; k < vs.length; k++) outline.push(vs[k], vs[(k + 1) % vs.length]);
    fills.push(pointSet(cutPoints, fill));
    outlines.push(wideLines(indexSegments(cutPoints, outline)));
  }
  return { faces, fills, outlines, sets: fills.concat(outlines) };
}

// ------------------------------------------------------------ drawing

const palette = [[0.98, 0.45, 0.35], [0.35, 0.8, 0.55], [0.45, 0.6, 1.0], [0.95, 0.8, 0.3], [0.8, 0.45, 0.95], [0.3, 0.85, 0.9]];

function resize() {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
}

function matrices() {
  const { eye, up } = cameraFrame();
  const aspect = canvas.width / canvas.height;
  const near = Math.max(camera.distance - camera.radius * 3, camera.distance * 0.01);
  const far = camera.distance + camera.radius * 3;
  return { mvp: multiply(perspective(camera.fovy, aspect, near, far), lookAt(eye, camera.target, up)), eye };
}

function drawWide(set, mvp, color, width) {
  if (!set || !set.count) return;
  gl.useProgram(wide.program);
  gl.uniformMatrix4fv(wide.uniforms.uMvp, false, mvp);
  gl.uniform2f(wide.uniforms.uViewport, canvas.width / 2, canvas.height / 2);
  gl.uniform1f(wide.uniforms.uWidth, width * (window.devicePixelRatio || 1) / 2);
  gl.uniform4fv(wide.uniforms.uColor, color);
  gl.bindVertexArray(set.vao);
  gl.drawArrays(gl.TRIANGLES, 0, set.count);
}

function drawFlat(set, mvp, color, mode, pointSize = 1) {
  if (!set || !set.count) return;
  gl.useProgram(flat.program);
  gl.uniformMatrix4fv(flat.uniforms.uMvp, false, mvp);
  gl.uniform4fv(flat.uniforms.uColor, color);
  gl.uniform1f(flat.uniforms.uPointSize, pointSize * (window.devicePixelRatio || 1));
  gl.uniform1i(flat.uniforms.uRound, mode === gl.POINTS ? 1 : 0);
  gl.bindVertexArray(set.vao);
  if (set.indexed) gl.drawElements(mode, set.count, gl.UNSIGNED_INT, 0);
  else gl.drawArrays(mode, 0, set.count);
}

function draw() {
  resize();
  gl.viewport(0, 0, canvas.width, canvas.height);
  gl.clearColor(0.106, 0.118, 0.137, 1);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  if (!view.data || !view.gpu) return;
  buildDynamic();
  const g = view.gpu, L = view.layers;
  const { mvp } = matrices();
  const { forward } = cameraFrame();
  gl.enable(gl.DEPTH_TEST);
  gl.depthFunc(gl.LEQUAL);

  // The surface, pushed back so that lines on it stay visible.
  gl.enable(gl.POLYGON_OFFSET_FILL);
  gl.polygonOffset(1.5, 2);
  if (L.shaded) {
    gl.useProgram(shaded.program);
    gl.uniformMatrix4fv(shaded.uniforms.uMvp, false, mvp);
    gl.uniform3fv(shaded.uniforms.uLight, forward);
    gl.uniform4fv(shaded.uniforms.uColor, [0.78, 0.74, 0.69, 1]);
    gl.bindVertexArray(g.meshVao);
    gl.drawElements(gl.TRIANGLES, g.triangleCount, gl.UNSIGNED_INT, 0);
  } else {
    // Depth only, so hidden lines stay hidden.
    gl.colorMask(false, false, false, false);
    gl.useProgram(flat.program);
    gl.uniformMatrix4fv(flat.uniforms.uMvp, false, mvp);
    gl.bindVertexArray(g.meshVao);
    gl.drawElements(gl.TRIANGLES, g.triangleCount, gl.UNSIGNED_INT, 0);
    gl.colorMask(true, true, true, true);
  }
  gl.disable(gl.POLYGON_OFFSET_FILL);

  if (L.wire) drawFlat({ vao: g.edgeVao, count: g.edgeCount, indexed: true }, mvp, [0.2, 0.22, 0.26, 1], gl.LINES);
  const dyn = view.dyn;
  if (L.cut) {
    drawFlat(dyn.cut.plain, mvp, [0.36, 0.56, 0.85, 1], gl.LINES);
    drawWide(dyn.cut.boundary, mvp, [0.25, 0.75, 0.35, 1], 2);
    drawWide(dyn.cut.curve, mvp, [0.88, 0.76, 0.0, 1], 2);
    drawWide(dyn.cut.crack, mvp, [1.0, 0.13, 0.13, 1], 4);
  }
  if (dyn.picked) {
    gl.enable(gl.BLEND);
    gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
    gl.enable(gl.POLYGON_OFFSET_FILL);
    gl.polygonOffset(-1, -2);
    dyn.picked.fills.forEach((s, i) => drawFlat(s, mvp, [...palette[i % palette.length], 0.55], gl.TRIANGLES));
    gl.disable(gl.POLYGON_OFFSET_FILL);
    gl.disable(gl.BLEND);
    dyn.picked.outlines.forEach((s, i) => drawWide(s, mvp, [...palette[i % palette.length], 1], 2.5));
  }
  dyn.nets.forEach((n) => {
    if (L.frames) {
      drawWide(n.plus, mvp, [1.0, 0.55, 0.1, 1], 1.5);
      drawWide(n.minus, mvp, [0.1, 0.78, 0.9, 1], 1.5);
    }
    if (L.curvenet) {
      drawWide(n.segments, mvp, [0.95, 0.85, 0.3, 1], 2.5);
      drawFlat(n.samples, mvp, [1.0, 0.85, 0.29, 1], gl.POINTS, 5);
      drawFlat(n.intersections, mvp, [1.0, 0.23, 0.23, 1], gl.POINTS, 11);
      drawFlat(n.anchors, mvp, [0.22, 0.83, 0.33, 1], gl.POINTS, 10);
      drawFlat(n.far, mvp, [1.0, 0.55, 0.1, 1], gl.POINTS, 9);
      drawFlat(n.removed, mvp, [1.0, 0.31, 0.85, 1], gl.POINTS, 9);
    }
  });
  if (L.cage && dyn.cage) drawWide(dyn.cage, mvp, [0.55, 0.95, 0.75, 1], 1.5);
  if (L.knots) dyn.axes.forEach((a, j) => drawWide(a, mvp, AXIS_COLORS[j], 2.5));
  if (dyn.knot) {
    gl.disable(gl.DEPTH_TEST);
    drawFlat(dyn.knot, mvp, [1, 1, 1, 1], gl.POINTS, 15);
    gl.enable(gl.DEPTH_TEST);
  }
  // What the warnings or the refusal name, in violet: faces filled over the
  // surface, lines and markers on top of everything (never hidden).
  if (L.problems && dyn.highlights.length) {
    gl.enable(gl.BLEND);
    gl.blendFunc(gl.SRC_ALPHA, gl.ONE_MINUS_SRC_ALPHA);
    gl.enable(gl.POLYGON_OFFSET_FILL);
    gl.polygonOffset(-1, -2);
    for (const h of dyn.highlights) if (h.faces) drawFlat(h.faces, mvp, [HIGHLIGHT[0], HIGHLIGHT[1], HIGHLIGHT[2], 0.7], gl.TRIANGLES);
    gl.disable(gl.POLYGON_OFFSET_FILL);
    gl.disable(gl.BLEND);
    gl.disable(gl.DEPTH_TEST);
    dyn.highlights.forEach((h, i) => {
      const strong = i === view.selected || view.data.refused;
      drawWide(h.lines, mvp, HIGHLIGHT, strong ? 6 : 4);
      drawFlat(h.points, mvp, HIGHLIGHT, gl.POINTS, strong ? 16 : 12);
    });
    gl.enable(gl.DEPTH_TEST);
  }
  gl.bindVertexArray(null);
}

let drawQueued = false;
const afterDraw = []; // called once the next draw is on the canvas
function requestDraw() {
  if (drawQueued) return;
  drawQueued = true;
  requestAnimationFrame(() => {
    drawQueued = false;
    try {
      draw();
    } catch (e) {
      fail(e);
      return;
    }
    if (view.data) {
      const frame = view.frames.has(view.frame) ? view.frame : -1;
      body.dataset.rendered = view.data.refused ? 'refusal' : String(frame);
      body.dataset.pose = view.pose;
      $('overlay').textContent = overlayText();
    }
    for (const f of afterDraw.splice(0)) f();
  });
}

function overlayText() {
  if (view.data.refused) return `${view.stageInfo.mesh}\nbinding refused: ${elementLabel(view.data.refused.highlight)}`;
  const t = view.times[view.frame];
  const label = view.source && view.source.kind === 'stage' ? `${view.stageInfo.mesh}` : `binding ${view.data.binding.binding_id.slice(0, 12)}`;
  return `${label}\n${view.pose === 'rest' ? 'rest pose' : 'deformed'}${t != null ? `, frame ${t}` : ''}`;
}

// Picking: draw face ids into an offscreen target and read one pixel.
let pickTarget = null;
function pickAt(clientX, clientY) {
  if (!view.gpu) return -1;
  resize();
  const w = canvas.width, h = canvas.height;
  if (!pickTarget || pickTarget.w !== w || pickTarget.h !== h) {
    if (pickTarget) {
      gl.deleteFramebuffer(pickTarget.fb);
      gl.deleteRenderbuffer(pickTarget.color);
      gl.deleteRenderbuffer(pickTarget.depth);
    }
    const fb = gl.createFramebuffer(), color = gl.createRenderbuffer(), depth = gl.createRenderbuffer();
    gl.bindRenderbuffer(gl.RENDERBUFFER, color);
    gl.renderbufferStorage(gl.RENDERBUFFER, gl.RGBA8, w, h);
    gl.bindRenderbuffer(gl.RENDERBUFFER, depth);
    gl.renderbufferStorage(gl.RENDERBUFFER, gl.DEPTH_COMPONENT24, w, h);
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.RENDERBUFFER, color);
    gl.framebufferRenderbuffer(gl.FRAMEBUFFER, gl.DEPTH_ATTACHMENT, gl.RENDERBUFFER, depth);
    pickTarget = { fb, color, depth, w, h };
  }
  buildDynamic();
  gl.bindFramebuffer(gl.FRAMEBUFFER, pickTarget.fb);
  gl.viewport(0, 0, w, h);
  gl.clearColor(0, 0, 0, 0);
  gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
  gl.enable(gl.DEPTH_TEST);
  gl.useProgram(pickProgram.program);
  gl.uniformMatrix4fv(pickProgram.uniforms.uMvp, false, matrices().mvp);
  gl.bindVertexArray(view.gpu.pickVao);
  gl.drawArrays(gl.TRIANGLES, 0, view.gpu.pickCount);
  const rect = canvas.getBoundingClientRect();
  const x = Math.floor((clientX - rect.left) / rect.width * w), y = Math.floor((1 - (clientY - rect.top) / rect.height) * h);
  const px = new Uint8Array(4);
  gl.readPixels(Math.min(w - 1, Math.max(0, x)), Math.min(h - 1, Math.max(0, y)), 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, px);
  gl.bindFramebuffer(gl.FRAMEBUFFER, null);
  gl.bindVertexArray(null);
  return (px[0] | (px[1] << 8) | (px[2] << 16)) - 1;
}

function setPicked(face) {
  view.picked = face;
  const label = $('pick-label');
  if (face < 0) {
    label.textContent = 'click the mesh to pick a face and see its cut-faces';
    delete label.dataset.face;
    delete label.dataset.cutFaces;
  } else {
    const parent = view.data.cut.face_parent;
    const faces = [];
    for (let f = 0; f < parent.length; f++) if (parent[f] === face) faces.push(f);
    label.textContent = `face ${face}: ${faces.length} cut-face${faces.length === 1 ? '' : 's'} (${faces.join(', ')})`;
    label.dataset.face = String(face);
    label.dataset.cutFaces = String(faces.length);
  }
  requestDraw();
}

// ------------------------------------------------------------ input

let drag = null;
canvas.addEventListener('contextmenu', (e) => e.preventDefault());
canvas.addEventListener('pointerdown', (e) => {
  canvas.setPointerCapture(e.pointerId);
  drag = { x: e.clientX, y: e.clientY, x0: e.clientX, y0: e.clientY, pan: e.button === 2 || e.button === 1 || e.shiftKey };
});
canvas.addEventListener('pointermove', (e) => {
  if (!drag) return;
  const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
  drag.x = e.clientX;
  drag.y = e.clientY;
  if (drag.pan) {
    const { right, up } = cameraFrame();
    const perPixel = 2 * camera.distance * Math.tan(camera.fovy / 2) / canvas.clientHeight;
    camera.target = vadd(camera.target, vadd(vscale(right, -dx * perPixel), vscale(up, dy * perPixel)));
  } else {
    camera.yaw -= dx * 0.008;
    camera.pitch = Math.max(-1.55, Math.min(1.55, camera.pitch + dy * 0.008));
  }
  requestDraw();
});
canvas.addEventListener('pointerup', (e) => {
  if (drag && Math.hypot(e.clientX - drag.x0, e.clientY - drag.y0) < 4 && e.button === 0) {
    // The face under the click, and the knot near it (deformed view, knot frames shown), if any.
    const knot = knotAt(e.clientX, e.clientY);
    if (knot) pickKnot(knot.curvenet, knot.knot);
    setPicked(pickAt(e.clientX, e.clientY));
  }
  drag = null;
});
// Zoom towards the point under the cursor (on the plane through the
// orbit target facing the camera), which stays where it is on screen.
canvas.addEventListener('wheel', (e) => {
  e.preventDefault();
  const d = camera.distance;
  const next = Math.max(camera.radius * 0.02, Math.min(camera.radius * 50, d * Math.exp(e.deltaY * 0.0012)));
  const rect = canvas.getBoundingClientRect();
  const nx = 2 * (e.clientX - rect.left) / rect.width - 1, ny = 1 - 2 * (e.clientY - rect.top) / rect.height;
  const { right, up } = cameraFrame();
  const halfH = d * Math.tan(camera.fovy / 2), halfW = halfH * rect.width / rect.height;
  const under = vadd(camera.target, vadd(vscale(right, nx * halfW), vscale(up, ny * halfH)));
  camera.target = vadd(under, vscale(vsub(camera.target, under), next / d));
  camera.distance = next;
  requestDraw();
}, { passive: false });
window.addEventListener('resize', requestDraw);
window.addEventListener('keydown', (e) => {
  if (e.target instanceof HTMLInputElement && e.target.type !== 'range' && e.target.type !== 'checkbox') return;
  if (e.key === 'f' && view.data) { fitCamera(currentPose().points); requestDraw(); }
  if (e.key === ' ') { e.preventDefault(); togglePlay(); }
});

for (const box of document.querySelectorAll('[data-layer]')) {
  box.addEventListener('change', () => { view.layers[box.dataset.layer] = box.checked; requestDraw(); });
}
$('box-scale').addEventListener('input', (e) => { view.boxScale = Number(e.target.value); requestDraw(); });
for (const radio of document.querySelectorAll('input[name=pose]')) {
  radio.addEventListener('change', () => { view.pose = radio.value; requestDraw(); });
}
$('frame').addEventListener('input', (e) => showFrame(Number(e.target.value)));
$('play').addEventListener('click', togglePlay);
$('token-form').addEventListener('submit', (e) => {
  e.preventDefault();
  setToken($('token').value.trim());
  $('token-form').hidden = true;
  start();
});
$('binding-form').addEventListener('submit', (e) => {
  e.preventDefault();
  const id = $('binding-id').value.trim();
  if (id) open({ kind: 'binding', id });
});
$('source-select').addEventListener('change', (e) => {
  const v = e.target.value;
  if (v.startsWith('stage:')) open({ kind: 'stage', index: Number(v.slice(6)) });
});

// ------------------------------------------------------------ frames

// Frame k solved on the server, with the user's adjustments at k (if any).
async function requestFrame(k) {
  const s = view.source;
  const adjustments = userSpecs(k);
  const post = (path, body) => api(path, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: JSON.stringify(body) });
  if (s.kind === 'stage') {
    return adjustments.length ? post(`v1/viewer/stages/${s.index}/frames/${k}`, { adjustments }) : api(`v1/viewer/stages/${s.index}/frames/${k}`);
  }
  return post(`v1/bindings/${s.id}/viewer-frame`, { orientations: true, adjustments });
}

async function fetchFrame(k) {
  if (view.frames.has(k)) return view.frames.get(k);
  const generation = view.generation;
  const frame = await requestFrame(k);
  if (generation !== view.generation) return null;
  frame.serial = ++view.serial;
  frame.points = new Float32Array(frame.points);
  frame.cut_points = new Float32Array(frame.cut_points);
  if (frame.rest) {
    frame.rest.points = new Float32Array(frame.rest.points);
    frame.rest.cut_points = new Float32Array(frame.rest.cut_points);
  }
  view.frames.set(k, frame);
  return frame;
}

let wanted = 0;
async function showFrame(k) {
  wanted = k;
  $('frame').value = String(k);
  const t = view.times[k];
  $('frame-label').textContent = view.times.length > 1 || t != null ? `frame ${t} (${k + 1}/${view.times.length})` : 'neutral pose';
  try {
    const frame = await fetchFrame(k);
    if (!frame || wanted !== k) return;
    view.frame = k;
    $('solve-label').textContent = `solve ${frame.solve_ms.toFixed(1)} ms`;
    say('');
    fillKnotPanel();
    requestDraw();
  } catch (e) {
    say(`frame ${t}: ${e.message}`);
    stopPlay();
  }
}

let playTimer = null;
function togglePlay() { if (view.playing) stopPlay(); else startPlay(); }
function stopPlay() {
  view.playing = false;
  $('play').textContent = 'play';
  if (playTimer) clearTimeout(playTimer);
  playTimer = null;
}
function startPlay() {
  if (view.times.length < 2) return;
  view.playing = true;
  $('play').textContent = 'pause';
  const fps = view.fps || 24;
  const step = async () => {
    if (!view.playing) return;
    const started = performance.now();
    await showFrame((view.frame + 1) % view.times.length);
    if (!view.playing) return;
    playTimer = setTimeout(step, Math.max(0, 1000 / fps - (performance.now() - started)));
  };
  step();
}

// ------------------------------------------------------------ panel

const STAT_LABELS = {
  mesh_vertices: 'mesh vertices', mesh_faces: 'mesh faces', samples: 'samples', segments: 'segments',
  cut_vertices: 'cut-vertices', cut_faces: 'cut-faces', cut_halfedges: 'cut halfedges', cracks: 'cracks',
  islands_removed: 'islands removed', chord_paths: 'segments inside one face', straightest_paths: 'straightest paths',
  fallback_paths: 'fallback paths', segments_left_out: 'segments left out', detours: 'detours', unknowns: 'unknowns',
  constraints: 'constraint rows', factor_nonzeros: 'factor nonzeros',
};

function fillPanel(data) {
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
function select(i) {
  view.selected = i;
  for (const li of document.querySelectorAll('#warning-list li')) li.classList.toggle('selected', li.dataset.index === String(i));
  frameHighlight(i >= 0 ? view.data.highlights[i] : null);
  requestDraw();
}

// Points the camera at a highlight's box (at least a quarter of the mesh
// wide, seen from outside the mesh), or at the whole mesh.
function frameHighlight(h) {
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

// ------------------------------------------------------------ loading

function fail(e) {
  body.dataset.state = 'error';
  say(e.message || String(e));
  console.error(e);
}

async function open(source) {
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

async function start() {
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

// ------------------------------------------------------------ adjustments

function knotAt(clientX, clientY) {
  const frame = view.frames.get(view.frame);
  if (!view.data || view.data.refused || view.pose !== 'deformed' || !view.layers.knots || !frame || !frame.knot_orientations) return null;
  return nearestKnot(view.data, frame.curvenets, matrices().mvp, canvas.getBoundingClientRect(), clientX, clientY, PICK_RADIUS);
}

/** Client coordinates of knot `knot` (pool index) of curvenet `k` in the frame shown, or null. */
function knotScreenPosition(k, knot) {
  const frame = view.frames.get(view.frame);
  if (!frame) return null;
  resize();
  const p = knotPosition(view.data, frame.curvenets, k, knot);
  const s = p && project(matrices().mvp, canvas.getBoundingClientRect(), p);
  return s && { x: s.x, y: s.y };
}

/** Picks knot `knot` (pool index) of curvenet `k`; false when it is not a knot. */
function pickKnot(k, knot) {
  const c = view.data && view.data.curvenets[k];
  if (!c || !c.knots || !c.knots.includes(knot)) return false;
  view.knot = { curvenet: k, knot };
  fillKnotPanel();
  requestDraw();
  return true;
}

// The adjustment of the picked knot at the frame shown: the user's, else
// what the frame applied (the stage's), else none.
function shownAdjustment() {
  if (!view.knot) return null;
  const key = knotKey(view.knot.curvenet, view.knot.knot);
  const mine = view.user.get(view.frame);
  if (mine && mine.has(key)) return { spec: mine.get(key), source: 'yours' };
  const frame = view.frames.get(view.frame);
  const applied = frame && (frame.adjustments || []).find((a) => a.curvenet === view.knot.curvenet && a.knot === view.knot.knot);
  return applied ? { spec: applied, source: applied.prim ? `the stage's ${applied.prim}` : "the stage's" } : null;
}

function fillKnotCount() {
  const count = userSpecs(view.frame).length;
  $('adjust-count').textContent = count ? `${count} adjusted at frame ${view.times[view.frame]}` : '';
  $('adjust-count').dataset.value = String(count);
  $('adjust-export').disabled = !(view.source && view.source.kind === 'stage' && count);
}

function fillKnotPanel() {
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

function onFieldInput() {
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
function setAdjustment(spec, refill = true) {
  const k = view.frame;
  if (!view.user.has(k)) view.user.set(k, new Map());
  view.user.get(k).set(knotKey(spec.curvenet, spec.knot), spec);
  return refresh(refill);
}

/** Clears the user's adjustment of the picked knot at the frame shown. */
function resetKnot() {
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
      frame.serial = ++view.serial;
      frame.points = new Float32Array(frame.points);
      frame.cut_points = new Float32Array(frame.cut_points);
      if (frame.rest) {
        frame.rest.points = new Float32Array(frame.rest.points);
        frame.rest.cut_points = new Float32Array(frame.rest.cut_points);
      }
      view.frames.set(k, frame);
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
async function exportLayer() {
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

$('adjust-attach').addEventListener('change', onFieldInput);
$('adjust-reset').addEventListener('click', () => resetKnot().catch(() => {}));
$('adjust-export').addEventListener('click', async () => {
  try {
    const text = await exportLayer();
    const stem = (view.stageInfo.stage.split('/').pop() || 'stage').replace(/\.[^.]*$/, '');
    const a = document.createElement('a');
    a.href = URL.createObjectURL(new Blob([text], { type: 'text/plain' }));
    a.download = `${stem}_adjusted.usda`;
    document.body.append(a);
    a.click();
    a.remove();
    setTimeout(() => URL.revokeObjectURL(a.href), 1000);
    say(`exported ${a.download}: curvenet bake ${a.download} -o OUT bakes it`);
  } catch (e) {
    say(`export: ${e.message}`);
  }
});

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


body.dataset.rendered = '-1';
start();
