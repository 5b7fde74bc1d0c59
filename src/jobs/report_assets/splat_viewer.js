// The report's splat viewer (src/jobs/splat_viewer.hpp): WebGL2, one instanced quad per Gaussian,
// sorted back to front on the CPU. Reads #splat-config (the starting camera and background) and
// #splat-data (base64 float32, 13 per Gaussian: mean, covariance xx xy xz yy yz zz, rgba).
(function () {
  const canvas = document.getElementById('splat-canvas');
  const status = document.getElementById('splat-status');
  const cfg = JSON.parse(document.getElementById('splat-config').textContent);
  const raw = atob(document.getElementById('splat-data').textContent.trim());
  const bytes = new Uint8Array(raw.length);
  for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
  const data = new Float32Array(bytes.buffer);
  const F = 13, N = data.length / F;
  const gl = canvas.getContext('webgl2', { preserveDrawingBuffer: true, premultipliedAlpha: false });
  if (!gl) { status.textContent = 'WebGL2 is not available in this browser: no 3D view.'; document.body.setAttribute('data-viewer', 'no-webgl'); return; }

  const vs = `#version 300 es
  precision highp float;
  layout(location=0) in vec2 corner;
  layout(location=1) in vec3 mean;
  layout(location=2) in vec3 covA;   // xx xy xz
  layout(location=3) in vec3 covB;   // yy yz zz
  layout(location=4) in vec4 rgba;
  uniform mat3 R; uniform vec3 T; uniform vec4 K; uniform vec2 size;
  out vec2 uv; out vec4 col;
  void main() {
    vec3 p = R * mean + T;
    if (p.z < 0.01) { gl_Position = vec4(0.0, 0.0, 2.0, 1.0); return; }
    mat3 V = mat3(covA.x, covA.y, covA.z, covA.y, covB.x, covB.y, covA.z, covB.y, covB.z);
    mat3 C = R * V * transpose(R);                      // camera-frame covariance
    float iz = 1.0 / p.z;
    vec3 j0 = vec3(K.x * iz, 0.0, -K.x * p.x * iz * iz);  // rows of the projection's Jacobian
    vec3 j1 = vec3(0.0, K.y * iz, -K.y * p.y * iz * iz);
    float a = dot(j0, C * j0) + 0.3, b = dot(j0, C * j1), c = dot(j1, C * j1) + 0.3;
    float mid = 0.5 * (a + c), rad = sqrt(max(0.25 * (a - c) * (a - c) + b * b, 0.0));
    float l1 = mid + rad, l2 = max(mid - rad, 0.0);
    vec2 v1 = abs(b) > 1e-12 ? normalize(vec2(b, l1 - a)) : (a >= c ? vec2(1.0, 0.0) : vec2(0.0, 1.0));
    vec2 v2 = vec2(-v1.y, v1.x);
    vec2 center = vec2(K.x * p.x * iz + K.z, K.y * p.y * iz + K.w);
    vec2 pix = center + corner.x * min(3.0 * sqrt(l1), 2048.0) * v1 + corner.y * min(3.0 * sqrt(l2), 2048.0) * v2;
    gl_Position = vec4(pix.x / size.x * 2.0 - 1.0, 1.0 - pix.y / size.y * 2.0, 0.0, 1.0);
    uv = 3.0 * corner; col = rgba;
  }`;
  const fs = `#version 300 es
  precision highp float;
  in vec2 uv; in vec4 col; out vec4 frag;
  void main() {
    float alpha = min(0.99, col.a * exp(-0.5 * dot(uv, uv)));
    if (alpha < 1.0 / 255.0) discard;
    frag = vec4(col.rgb * alpha, alpha);                // premultiplied, blended back to front
  }`;
  function shader(type, src) {
    const s = gl.createShader(type); gl.shaderSource(s, src); gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  }
  const prog = gl.createProgram();
  gl.attachShader(prog, shader(gl.VERTEX_SHADER, vs)); gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, fs));
  gl.linkProgram(prog);
  if (!gl.getProgramParameter(prog, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(prog));
  gl.useProgram(prog);

  const vao = gl.createVertexArray(); gl.bindVertexArray(vao);
  const quad = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, quad);
  gl.bufferData(gl.ARRAY_BUFFER, new Float32Array([-1, -1, 1, -1, -1, 1, 1, 1]), gl.STATIC_DRAW);
  gl.enableVertexAttribArray(0); gl.vertexAttribPointer(0, 2, gl.FLOAT, false, 0, 0);
  const inst = gl.createBuffer(); gl.bindBuffer(gl.ARRAY_BUFFER, inst);
  const layout = [[1, 3, 0], [2, 3, 3], [3, 3, 6], [4, 4, 9]];
  for (const [loc, n, off] of layout) {
    gl.enableVertexAttribArray(loc); gl.vertexAttribPointer(loc, n, gl.FLOAT, false, F * 4, off * 4);
    gl.vertexAttribDivisor(loc, 1);
  }
  const sorted = new Float32Array(data.length);
  const depth = new Float32Array(N), order = new Uint32Array(N), counts = new Uint32Array(65536);

  // Camera: rows of R are the camera's x (right), y (down), z (forward) in the world.
  let R = cfg.R.slice(), C = [0, 0, 0];
  for (let a = 0; a < 3; a++) C[a] = -(R[a] * cfg.t[0] + R[3 + a] * cfg.t[1] + R[6 + a] * cfg.t[2]);
  const down = [R[3], R[4], R[5]];                       // the starting camera's down: the orbit's axis
  let dist = 1;                                          // to the orbit target: the median depth ahead
  { const ds = [];
    for (let i = 0; i < N; i += Math.max(1, Math.floor(N / 5000))) {
      const z = R[6] * (data[i * F] - C[0]) + R[7] * (data[i * F + 1] - C[1]) + R[8] * (data[i * F + 2] - C[2]);
      if (z > 0) ds.push(z);
    }
    ds.sort((x, y) => x - y); if (ds.length) dist = ds[Math.floor(ds.length / 2)]; }
  let target = [C[0] + R[6] * dist, C[1] + R[7] * dist, C[2] + R[8] * dist];
  const cross = (u, v) => [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
  const norm = (u) => { const l = Math.hypot(u[0], u[1], u[2]) || 1; return [u[0] / l, u[1] / l, u[2] / l]; };
  function lookAt() {                                    // R from C looking at target, keeping `down`
    const z = norm([target[0] - C[0], target[1] - C[1], target[2] - C[2]]);
    const x = norm(cross(down, z)), y = cross(z, x);
    R = [x[0], x[1], x[2], y[0], y[1], y[2], z[0], z[1], z[2]];
  }
  function rotate(p, axis, angle) {                     // p about `axis` through `target` (Rodrigues)
    const k = norm(axis), v = [p[0] - target[0], p[1] - target[1], p[2] - target[2]];
    const c = Math.cos(angle), s = Math.sin(angle), d = k[0] * v[0] + k[1] * v[1] + k[2] * v[2], kv = cross(k, v);
    return [0, 1, 2].map((a) => target[a] + v[a] * c + kv[a] * s + k[a] * d * (1 - c));
  }

  function draw() {
    const T = [0, 1, 2].map((a) => -(R[3 * a] * C[0] + R[3 * a + 1] * C[1] + R[3 * a + 2] * C[2]));
    // Back to front: a 16-bit counting sort on depth. The range is taken from the stored
    // (float32) depths, and every key is clamped to 0…65535: a key computed from a depth
    // rounded below the double-precision minimum fell outside the buckets, which dropped the
    // farthest Gaussian and drew a stale one in front of all others.
    let lo = Infinity, hi = -Infinity;
    for (let i = 0; i < N; i++) {
      const o = i * F;
      depth[i] = R[6] * data[o] + R[7] * data[o + 1] + R[8] * data[o + 2] + T[2];
      const z = depth[i]; if (z < lo) lo = z; if (z > hi) hi = z;
    }
    const scale = hi > lo ? 65535 / (hi - lo) : 0;
    const key = (i) => 65535 - Math.min(65535, Math.max(0, Math.floor((depth[i] - lo) * scale)));
    counts.fill(0);
    for (let i = 0; i < N; i++) counts[key(i)]++;
    for (let k = 1; k < 65536; k++) counts[k] += counts[k - 1];
    for (let i = N - 1; i >= 0; i--) order[--counts[key(i)]] = i;
    for (let j = 0; j < N; j++) sorted.set(data.subarray(order[j] * F, order[j] * F + F), j * F);
    gl.bindBuffer(gl.ARRAY_BUFFER, inst); gl.bufferData(gl.ARRAY_BUFFER, sorted, gl.DYNAMIC_DRAW);
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(cfg.background[0], cfg.background[1], cfg.background[2], 1); gl.clear(gl.COLOR_BUFFER_BIT);
    gl.enable(gl.BLEND); gl.blendFunc(gl.ONE, gl.ONE_MINUS_SRC_ALPHA);
    // R is row-major here; transpose = true makes the shader's R the same matrix.
    gl.uniformMatrix3fv(gl.getUniformLocation(prog, 'R'), true, R);
    gl.uniform3fv(gl.getUniformLocation(prog, 'T'), T);
    const s = canvas.width / cfg.width;
    gl.uniform4f(gl.getUniformLocation(prog, 'K'), cfg.fx * s, cfg.fy * s, cfg.cx * s, cfg.cy * s);
    gl.uniform2f(gl.getUniformLocation(prog, 'size'), canvas.width, canvas.height);
    gl.drawArraysInstanced(gl.TRIANGLE_STRIP, 0, 4, N);
  }
  let pending = false;
  const redraw = () => { if (!pending) { pending = true; requestAnimationFrame(() => { pending = false; draw(); }); } };
  let drag = null;
  canvas.addEventListener('pointerdown', (e) => { drag = [e.clientX, e.clientY]; canvas.setPointerCapture(e.pointerId); });
  canvas.addEventListener('pointerup', () => { drag = null; });
  canvas.addEventListener('pointermove', (e) => {
    if (!drag) return;
    const dx = e.clientX - drag[0], dy = e.clientY - drag[1]; drag = [e.clientX, e.clientY];
    C = rotate(C, down, -dx * 0.005);
    lookAt();
    C = rotate(C, [R[0], R[1], R[2]], dy * 0.005);
    lookAt(); redraw();
  });
  canvas.addEventListener('wheel', (e) => {
    e.preventDefault();
    const f = Math.exp(e.deltaY * 0.001);
    C = [0, 1, 2].map((a) => target[a] + (C[a] - target[a]) * f); redraw();
  }, { passive: false });
  draw();
  // For the headless-browser test: how many pixels differ from the background.
  const px = new Uint8Array(canvas.width * canvas.height * 4);
  gl.readPixels(0, 0, canvas.width, canvas.height, gl.RGBA, gl.UNSIGNED_BYTE, px);
  let drawn = 0;
  for (let i = 0; i < px.length; i += 4)
    drawn += Math.abs(px[i] - 255 * cfg.background[0]) + Math.abs(px[i + 1] - 255 * cfg.background[1]) +
             Math.abs(px[i + 2] - 255 * cfg.background[2]) > 6;
  document.body.setAttribute('data-viewer', 'ok');
  document.body.setAttribute('data-viewer-splats', N);
  document.body.setAttribute('data-viewer-covered', (drawn / (px.length / 4)).toFixed(4));
  // The first frame itself, on request (report.html#viewer-frame), to compare with the CPU render.
  if (location.hash === '#viewer-frame') document.body.setAttribute('data-viewer-frame', canvas.toDataURL('image/png'));
  status.textContent = N + ' Gaussians. Drag to orbit, scroll to zoom.';
})();
