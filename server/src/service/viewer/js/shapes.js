// Geometry derived for drawing: the scaled-frame boxes of the segments and
// the mesh's vertex normals (pure functions over flat f32 arrays).
import { vadd, vsub, vscale, vcross, pick3 } from './math.js';

// The 12 edges of the scaled-frame boxes of every segment side (paper Fig. 5),
// as flat segment pairs, split by side.
export function frameBoxes(samples, segments, frames, scale) {
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

export function vertexNormals(points, triangles) {
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
