// The orbit camera: target, distance, yaw and pitch; fitting it to points,
// to a box, and turning it towards what matters.
import { vadd, vsub, vscale, vcross, vnorm, pick3 } from './math.js';

export const camera = { target: [0, 0, 0], distance: 1, yaw: 0.6, pitch: 0.25, fovy: 0.75, radius: 1 };

export function cameraFrame() {
  const cp = Math.cos(camera.pitch);
  const dir = [cp * Math.sin(camera.yaw), Math.sin(camera.pitch), cp * Math.cos(camera.yaw)];
  const eye = vadd(camera.target, vscale(dir, camera.distance));
  const forward = vscale(dir, -1);
  const right = vnorm(vcross(forward, [0, 1, 0]));
  const up = vcross(right, forward);
  return { eye, forward, right, up };
}

export function fitCamera(points) {
  const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
  for (let i = 0; i < points.length; i += 3) {
    for (let k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], points[i + k]);
      hi[k] = Math.max(hi[k], points[i + k]);
    }
  }
  camera.target = vscale(vadd(lo, hi), 0.5);
  camera.radius = Math.max(1e-9, 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]));
  camera.distance = camera.radius / Math.sin(camera.fovy / 2) * 1.02;
}

// Turns the camera (about the vertical) to the side of the mesh where the
// curvenet's intersections are (all its samples when it has none).
export function faceTheCurvenet(data) {
  let sum = [0, 0, 0], n = 0;
  for (const c of data.curvenets) {
    const picks = c.intersections.length ? c.intersections : c.samples.map((_, i) => i).filter((i) => i % 3 === 0).map((i) => i / 3);
    for (const i of picks) {
      sum = vadd(sum, pick3(c.samples, i));
      n++;
    }
  }
  if (!n) return;
  const d = vsub(vscale(sum, 1 / n), camera.target);
  if (Math.hypot(d[0], d[2]) > 1e-6 * camera.radius) camera.yaw = Math.atan2(d[0], d[2]);
}

/**
 * Frames the box `b` ([min xyz, max xyz]): centred on it, at least
 * `minRadius` wide, looking at it from the side `from` (a point, usually the
 * mesh's centre: the camera turns so that the box is between it and the eye).
 */
export function fitBox(b, minRadius, from) {
  const lo = [b[0], b[1], b[2]], hi = [b[3], b[4], b[5]];
  const centre = vscale(vadd(lo, hi), 0.5);
  const d = vsub(centre, from);
  if (Math.hypot(d[0], d[2]) > 1e-9 * (minRadius || 1)) camera.yaw = Math.atan2(d[0], d[2]);
  camera.target = centre;
  camera.radius = Math.max(minRadius, 0.5 * Math.hypot(hi[0] - lo[0], hi[1] - lo[1], hi[2] - lo[2]), 1e-9);
  camera.distance = camera.radius / Math.sin(camera.fovy / 2) * 1.02;
}
