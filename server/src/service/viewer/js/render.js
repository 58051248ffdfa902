// Drawing the scene: the canvas size, the camera's matrices, the layers in
// their order and colours, and the one queued draw per animation frame
// (which sets data-rendered and the overlay).
import { $, canvas, body, fail } from './dom.js';
import { gl, shaded, flat, wide } from './context.js';
import { view } from './state.js';
import { buildDynamic } from './scene.js';
import { camera, cameraFrame } from './camera.js';
import { multiply, perspective, lookAt } from './math.js';
import { AXIS_COLORS } from './adjust.js';
import { HIGHLIGHT, label as elementLabel } from './highlight.js';

const palette = [[0.98, 0.45, 0.35], [0.35, 0.8, 0.55], [0.45, 0.6, 1.0], [0.95, 0.8, 0.3], [0.8, 0.45, 0.95], [0.3, 0.85, 0.9]];

export function resize() {
  const dpr = window.devicePixelRatio || 1;
  const w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
  if (canvas.width !== w || canvas.height !== h) {
    canvas.width = w;
    canvas.height = h;
  }
}

export function matrices() {
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
export const afterDraw = []; // called once the next draw is on the canvas
export function requestDraw() {
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
