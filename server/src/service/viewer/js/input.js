// The page's input: orbit, pan, zoom and clicks on the canvas (a face, a
// knot), the keys, the layer and pose toggles, the frame slider and
// playback, the token, binding and source forms, the adjustment buttons.
import { setToken } from './api.js';
import { $, canvas, say } from './dom.js';
import { view } from './state.js';
import { currentPose } from './scene.js';
import { requestDraw } from './render.js';
import { pickAt, setPicked } from './pick.js';
import { knotAt, pickKnot } from './knots.js';
import { showFrame, togglePlay } from './frames.js';
import { open, start } from './loading.js';
import { onFieldInput, resetKnot, exportLayer } from './live.js';
import { camera, cameraFrame, fitCamera } from './camera.js';
import { vadd, vsub, vscale } from './math.js';

let drag = null;

/** Binds the page's controls and the canvas's pointer, wheel and keys (once). */
export function bindInput() {
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
}
