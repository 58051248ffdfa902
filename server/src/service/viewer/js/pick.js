// Picking a face: face ids drawn into an offscreen target and one pixel
// read back; the picked face and its cut-faces named in the panel.
import { $, canvas } from './dom.js';
import { gl, pickProgram } from './context.js';
import { view } from './state.js';
import { buildDynamic } from './scene.js';
import { resize, matrices, requestDraw } from './render.js';

// Picking: draw face ids into an offscreen target and read one pixel.
let pickTarget = null;
export function pickAt(clientX, clientY) {
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

export function setPicked(face) {
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
