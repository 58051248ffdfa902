// Frames: solved on the server (a stage's frame, or a binding's
// viewer-frame, with the user's adjustments at that frame), kept by frame
// index for playback; the frame slider and playback.
import { api } from './api.js';
import { $, say } from './dom.js';
import { view, userSpecs } from './state.js';
import { requestDraw } from './render.js';
import { fillKnotPanel } from './knots.js';

// Frame k solved on the server, with the user's adjustments at k (if any).
export async function requestFrame(k) {
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
  return received(k, frame);
}

/** Keeps a frame answered for frame index `k` (its arrays as f32) and returns it. */
export function received(k, frame) {
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
export async function showFrame(k) {
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
export function togglePlay() { if (view.playing) stopPlay(); else startPlay(); }
export function stopPlay() {
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
