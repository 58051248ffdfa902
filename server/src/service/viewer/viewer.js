// The curvenet viewer: a hand-written WebGL2 renderer over the service's
// read-only viewer endpoints (server/src/service/viewer.rs). No libraries.
//
// Data flow: GET v1/viewer/stages (stages opened with --open-stage) or a
// binding id from ?binding=ID → GET v1/bindings/{id}/viewer-data (mesh,
// cut-mesh, curvenets, neutral frames, counts) → frames solved on the
// server (GET v1/viewer/stages/{i}/frames/{k}, or POST
// v1/bindings/{id}/viewer-frame for a binding without a stage), cached here
// by frame index for playback.
//
// For tests and scripts, <body> carries data-state (loading | ready |
// error) and data-rendered (the frame index of the last drawn frame, "-1"
// before the first); every count in the side panel is an element with
// data-stat="name" and data-value="number".
'use strict';

(() => {
  const $ = (id) => document.getElementById(id);
  const canvas = $('view');
  const body = document.body;

  // ------------------------------------------------------------ API access

  const hashParams = new URLSearchParams(location.hash.slice(1));
  let token = hashParams.get('token') || sessionStorage.getItem('curvenet-token') || '';

  class ApiError extends Error {
    constructor(status, code, message) {
      super(code ? `${code}: ${message}` : message);
      this.status = status;
      this.code = code;
    }
  }

  async function api(path, options = {}) {
    const headers = Object.assign({}, options.headers || {});
    if (token) headers.Authorization = `Bearer ${token}`;
    const response = await fetch(path, Object.assign({}, options, { headers }));
    const text = await response.text();
    let json = null;
    try { json = JSON.parse(text); } catch (_) { /* not JSON */ }
    if (!response.ok) {
      if (response.status === 401) $('token-form').hidden = false;
      throw new ApiError(response.status, json && json.code, (json && json.message) || `HTTP ${response.status} for ${path}`);
    }
    return json;
  }

  function say(text) { $('message').textContent = text || ''; }

  // ------------------------------------------------------------ small math

  const vsub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const vadd = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const vscale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const vcross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const vdot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const vnorm = (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };

  // Column-major 4×4 matrices, as WebGL expects.
  function perspective(fovy, aspect, near, far) {
    const f = 1 / Math.tan(fovy / 2), nf = 1 / (near - far);
    return [f / aspect, 0, 0, 0, 0, f, 0, 0, 0, 0, (far + near) * nf, -1, 0, 0, 2 * far * near * nf, 0];
  }
  function lookAt(eye, target, up) {
    const z = vnorm(vsub(eye, target)), x = vnorm(vcross(up, z)), y = vcross(z, x);
    return [x[0], y[0], z[0], 0, x[1], y[1], z[1], 0, x[2], y[2], z[2], 0,
      -vdot(x, eye), -vdot(y, eye), -vdot(z, eye), 1];
  }
  function multiply(a, b) {
    const out = new Array(16);
    for (let c = 0; c < 4; c++) {
      for (let r = 0; r < 4; r++) {
        let s = 0;
        for (let k = 0; k < 4; k++) s += a[k * 4 + r] * b[c * 4 + k];
        out[c * 4 + r] = s;
      }
    }
    return out;
  }

  // ------------------------------------------------------------ camera

  const camera = { target: [0, 0, 0], distance: 1, yaw: 0.6, pitch: 0.25, fovy: 0.75, radius: 1 };

  function cameraFrame() {
    const cp = Math.cos(camera.pitch);
    const dir = [cp * Math.sin(camera.yaw), Math.sin(camera.pitch), cp * Math.cos(camera.yaw)];
    const eye = vadd(camera.target, vscale(dir, camera.distance));
    const forward = vscale(dir, -1);
    const right = vnorm(vcross(forward, [0, 1, 0]));
    const up = vcross(right, forward);
    return { eye, forward, right, up };
  }

  function fitCamera(points) {
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
  function faceTheCurvenet(data) {
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

  // ------------------------------------------------------------ WebGL

  const gl = canvas.getContext('webgl2', { antialias: true, preserveDrawingBuffer: true });
  if (!gl) {
    body.dataset.state = 'error';
    say('This browser has no WebGL2.');
    throw new Error('no WebGL2');
  }

  function compile(vsSource, fsSource) {
    const program = gl.createProgram();
    for (const [type, source] of [[gl.VERTEX_SHADER, vsSource], [gl.FRAGMENT_SHADER, fsSource]]) {
      const shader = gl.createShader(type);
      gl.shaderSource(shader, '#version 300 es\nprecision highp float;\n' + source);
      gl.compileShader(shader);
      if (!gl.getShaderParameter(shader, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(shader));
      gl.attachShader(program, shader);
    }
    gl.linkProgram(program);
    if (!gl.getProgramParameter(program, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(program));
    const uniforms = {};
    const n = gl.getProgramParameter(program, gl.ACTIVE_UNIFORMS);
    for (let i = 0; i < n; i++) {
      const name = gl.getActiveUniform(program, i).name;
      uniforms[name] = gl.getUniformLocation(program, name);
    }
    return { program, uniforms };
  }

  // Shaded surface: two-sided Lambert under a headlight plus a little rim.
  const shaded = compile(`
    layout(location = 0) in vec3 aPos;
    layout(location = 1) in vec3 aNormal;
    uniform mat4 uMvp;
    out vec3 vNormal;
    void main() { vNormal = aNormal; gl_Position = uMvp * vec4(aPos, 1.0); }`, `
    in vec3 vNormal;
    uniform vec3 uLight;
    uniform vec4 uColor;
    out vec4 outColor;
    void main() {
      vec3 n = normalize(vNormal);
      float d = abs(dot(n, uLight));
      vec3 c = uColor.rgb * (0.28 + 0.72 * d) + vec3(0.05) * pow(1.0 - d, 3.0);
      outColor = vec4(c, uColor.a);
    }`);

  // Flat colour for thin lines, points (round) and filled highlights.
  const flat = compile(`
    layout(location = 0) in vec3 aPos;
    uniform mat4 uMvp;
    uniform float uPointSize;
    void main() { gl_Position = uMvp * vec4(aPos, 1.0); gl_PointSize = uPointSize; }`, `
    uniform vec4 uColor;
    uniform bool uRound;
    out vec4 outColor;
    void main() {
      if (uRound && length(gl_PointCoord - vec2(0.5)) > 0.5) discard;
      outColor = uColor;
    }`);

  // Wide lines: every segment is a screen-aligned quad of uWidth pixels.
  const wide = compile(`
    layout(location = 0) in vec3 aA;
    layout(location = 1) in vec3 aB;
    layout(location = 2) in vec2 aCorner;
    uniform mat4 uMvp;
    uniform vec2 uViewport;
    uniform float uWidth;
    void main() {
      vec4 a = uMvp * vec4(aA, 1.0), b = uMvp * vec4(aB, 1.0);
      vec2 d = (b.xy / b.w - a.xy / a.w) * uViewport;
      d = length(d) > 1e-6 ? normalize(d) : vec2(1.0, 0.0);
      vec4 p = aCorner.x < 0.5 ? a : b;
      p.xy += vec2(-d.y, d.x) * aCorner.y * uWidth / uViewport * p.w;
      gl_Position = p;
    }`, `
    uniform vec4 uColor;
    out vec4 outColor;
    void main() { outColor = uColor; }`);

  // Face ids for picking (id + 1 in RGB; 0 is the background).
  const pickProgram = compile(`
    layout(location = 0) in vec3 aPos;
    layout(location = 1) in vec3 aId;
    uniform mat4 uMvp;
    flat out vec3 vId;
    void main() { vId = aId; gl_Position = uMvp * vec4(aPos, 1.0); }`, `
    flat in vec3 vId;
    out vec4 outColor;
    void main() { outColor = vec4(vId, 1.0); }`);

  function buffer(data, target = gl.ARRAY_BUFFER, usage = gl.STATIC_DRAW) {
    const b = gl.createBuffer();
    gl.bindBuffer(target, b);
    gl.bufferData(target, data, usage);
    return b;
  }

  // A set of wide lines, from flat segment endpoint pairs [ax, ay, az, bx, by, bz, ...].
  function wideLines(segments) {
    const n = segments.length / 6;
    const a = new Float32Array(n * 18), b = new Float32Array(n * 18), corner = new Float32Array(n * 12);
    const corners = [[0, -1], [1, -1], [1, 1], [0, -1], [1, 1], [0, 1]];
    for (let s = 0; s < n; s++) {
      for (let v = 0; v < 6; v++) {
        const o = (s * 6 + v) * 3;
        for (let k = 0; k < 3; k++) {
          a[o + k] = segments[s * 6 + k];
          b[o + k] = segments[s * 6 + 3 + k];
        }
        corner[(s * 6 + v) * 2] = corners[v][0];
        corner[(s * 6 + v) * 2 + 1] = corners[v][1];
      }
    }
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const buffers = [];
    for (const [loc, data, size] of [[0, a, 3], [1, b, 3], [2, corner, 2]]) {
      buffers.push(buffer(data));
      gl.enableVertexAttribArray(loc);
      gl.vertexAttribPointer(loc, size, gl.FLOAT, false, 0, 0);
    }
    gl.bindVertexArray(null);
    return { vao, buffers, count: n * 6 };
  }

  // Points (flat xyz) and optional index lists over them, drawn with `flat`.
  function pointSet(points, indices) {
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    const buffers = [buffer(points instanceof Float32Array ? points : new Float32Array(points))];
    gl.enableVertexAttribArray(0);
    gl.vertexAttribPointer(0, 3, gl.FLOAT, false, 0, 0);
    let count = points.length / 3;
    if (indices) {
      buffers.push(buffer(new Uint32Array(indices), gl.ELEMENT_ARRAY_BUFFER));
      count = indices.length;
    }
    gl.bindVertexArray(null);
    return { vao, buffers, count, indexed: !!indices };
  }

  // Deletes a set's vertex array and buffers.
  function free(set) {
    if (!set || !set.vao) return;
    gl.deleteVertexArray(set.vao);
    for (const b of set.buffers || []) gl.deleteBuffer(b);
  }

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
    layers: { shaded: true, wire: false, cut: true, curvenet: true, frames: true },
    gpu: null,          // static GPU objects of the binding
    dyn: null,          // GPU objects of the current pose
    dynKey: '',
    playing: false,
    generation: 0,      // bumps on every source change (stale fetches are dropped)
  };

  function indexSegments(points, pairs, filter) {
    const out = [];
    for (let e = 0; e < pairs.length / 2; e++) {
      if (filter && !filter(e)) continue;
      const a = pairs[2 * e], b = pairs[2 * e + 1];
      out.push(points[3 * a], points[3 * a + 1], points[3 * a + 2], points[3 * b], points[3 * b + 1], points[3 * b + 2]);
    }
    return out;
  }

  function pick3(points, i) { return [points[3 * i], points[3 * i + 1], points[3 * i + 2]]; }

  // The 12 edges of the scaled-frame boxes of every segment side (paper Fig. 5),
  // as flat segment pairs, split by side.
  function frameBoxes(samples, segments, frames, scale) {
    const sides = [[], []];
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
      return { key: `d${view.frame}`, points: frame.points, cutPoints: frame.cut_points, nets: frame.curvenets };
    }
    if (frame && frame.rest) {
      const r = frame.rest;
      return { key: `r${view.frame}`, points: r.points, cutPoints: r.cut_points, nets: r.curvenets };
    }
    return { key: 'r', points: data.mesh.points, cutPoints: data.cut.points, nets: data.curvenets };
  }

  function buildDynamic() {
    const data = view.data, g = view.gpu;
    const pose = currentPose();
    const key = `${pose.key}|${view.boxScale}|${view.picked}`;
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
    const sets = nets.flatMap((n) => Object.values(n)).concat(Object.values(cut), picked ? picked.sets : []);
    view.dyn = { nets, cut, picked, sets, points };
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
    gl.bindVertexArray(null);
  }

  let drawQueued = false;
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
        body.dataset.rendered = String(frame);
        body.dataset.pose = view.pose;
        $('overlay').textContent = overlayText();
      }
    });
  }

  function overlayText() {
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
    token = $('token').value.trim();
    sessionStorage.setItem('curvenet-token', token);
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

  async function fetchFrame(k) {
    if (view.frames.has(k)) return view.frames.get(k);
    const generation = view.generation;
    const s = view.source;
    const frame = s.kind === 'stage'
      ? await api(`v1/viewer/stages/${s.index}/frames/${k}`)
      : await api(`v1/bindings/${s.id}/viewer-frame`, { method: 'POST', headers: { 'Content-Type': 'application/json' }, body: '{}' });
    if (generation !== view.generation) return null;
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
    const b = data.binding;
    $('binding-label').textContent = `binding ${b.binding_id}`;
    const stats = $('stats').tBodies[0];
    stats.replaceChildren();
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
    const timings = $('timings').tBodies[0];
    timings.replaceChildren();
    for (const [k, v] of Object.entries(b.timings)) {
      const tr = document.createElement('tr');
      const a = document.createElement('td'), c = document.createElement('td');
      a.textContent = k.replace(/_ms$/, '');
      c.textContent = v.toFixed(1);
      c.dataset.timing = k;
      tr.append(a, c);
      timings.append(tr);
    }
    const list = $('warning-list');
    list.replaceChildren();
    for (const w of data.warnings) {
      const li = document.createElement('li');
      const code = document.createElement('code');
      code.textContent = w.code;
      li.append(code, ' ', w.message);
      li.dataset.code = w.code;
      list.append(li);
    }
    if (!data.warnings.length) {
      const li = document.createElement('li');
      li.textContent = 'none';
      list.append(li);
    }
    $('warning-count').textContent = `(${data.warnings.length})`;
    $('warning-count').dataset.value = String(data.warnings.length);
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
        const s = await api(`v1/viewer/stages/${source.index}`);
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
      setPicked(-1);
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

  // For scripts and the browser console.
  window.curvenetViewer = { view, camera, pickAt, showFrame, open, requestDraw };

  body.dataset.rendered = '-1';
  start();
})();
