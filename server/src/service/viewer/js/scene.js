// The scene's GPU objects: the static ones of a binding (the mesh, its
// edges, the picking triangles, the cut-mesh edges by kind) and those of
// the pose shown (mesh points and normals, cut-vertices, curvenets and
// their frames, highlights, knot axes, the cage), rebuilt when the pose changes.
import { gl, renderer, buffer, wideLines, pointSet, free } from './context.js';
import { view } from './state.js';
import { frameBoxes, vertexNormals } from './shapes.js';
import { indexSegments } from './math.js';
import { AXIS_LENGTH, knotKey, knotAxes, knotPosition } from './adjust.js';
import { buildHighlights } from './highlight.js';

// Static GPU objects of a binding: what does not change with the frame.
export function buildStatic(data) {
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

export function freeStatic(g) {
  if (!g) return;
  for (const vao of [g.meshVao, g.edgeVao, g.pickVao]) gl.deleteVertexArray(vao);
  for (const b of g.buffers) gl.deleteBuffer(b);
}

// The current pose: mesh points, cut-vertices, curvenet samples and frames
// (rest view: the frame's rest pose, else the projection pose, with the
// neutral or tracked curvenet; deformed view: the solve and the posed curvenet).
export function currentPose() {
  const data = view.data;
  const frame = view.frames.get(view.frame);
  if (view.pose === 'deformed' && frame) {
    // A caged binding's frame carries its cage where it deforms the mesh (the posed cage).
    return { key: `d${view.frame}:${frame.serial}`, points: frame.points, cutPoints: frame.cut_points, nets: frame.curvenets, orientations: frame.knot_orientations, cage: frame.cage };
  }
  if (frame && frame.rest) {
    // The rest pose the solve saw (a caged binding's with its rest cage).
    const r = frame.rest;
    return { key: `r${view.frame}`, points: r.points, cutPoints: r.cut_points, nets: r.curvenets, cage: r.cage };
  }
  return { key: 'r', points: data.mesh.points, cutPoints: data.cut.points, nets: data.curvenets, cage: data.cage && data.cage.points };
}

export function buildDynamic() {
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
