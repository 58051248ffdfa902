// The WebGL2 side: the shader programs (shaded surface, flat colour, wide
// lines, face-id picking) and GPU sets of lines and points. No libraries.

/** The programs and GPU helpers over the WebGL2 context `gl`. */
export function createRenderer(gl) {

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

  return { compile, shaded, flat, wide, pickProgram, buffer, wideLines, pointSet, free };
}
