// cutlab trainee station: renders the running session's tissue with WebGL2 from the server's
// frames (one WebSocket), and, on the trainee's page, sends pointer and pen samples back.
// Our own code; no library, nothing loaded from elsewhere. The messages are documented in
// station/src/protocol.rs.
"use strict";
(function () {
  const canvas = document.getElementById("tissue");
  if (!canvas) return;
  const config = JSON.parse(canvas.dataset.config);
  const KIND_TOPOLOGY = 1, KIND_FRAME = 2, KIND_REST = 3, FRAME_HEADER_BYTES = 84;
  const BLADE_LENGTH_M = 0.015, BLADE_WIDTH_M = 0.003;
  const status = (text) => { document.getElementById("status").textContent = text; };

  // ---- small vector and matrix helpers (column-major 4x4, as WebGL wants) ----
  const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
  const add = (a, b) => [a[0] + b[0], a[1] + b[1], a[2] + b[2]];
  const scale = (a, s) => [a[0] * s, a[1] * s, a[2] * s];
  const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
  const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
  const norm = (a) => Math.hypot(a[0], a[1], a[2]);
  const unit = (a) => { const n = norm(a) || 1; return scale(a, 1 / n); };
  // a view's basis: forward `f`, right `s` and up `u` on the screen (unit vectors)
  function basis(eye, target, up) {
    const f = unit(sub(target, eye)), s = unit(cross(f, up));
    return { f, s, u: cross(s, f) };
  }
  function lookAt(eye, target, up) {
    const { f, s, u } = basis(eye, target, up);
    return [s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0,
      -dot(s, eye), -dot(u, eye), dot(f, eye), 1];
  }
  function perspective(fovy, aspect, near, far) {
    const t = 1 / Math.tan(fovy / 2), d = near - far;
    return [t / aspect, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / d, -1, 0, 0, 2 * far * near / d, 0];
  }
  function rotate(q, v) { // q = [w, x, y, z]
    const u = [q[1], q[2], q[3]], w = q[0];
    const t = scale(cross(u, v), 2);
    return add(add(v, scale(t, w)), cross(u, t));
  }

  // ---- WebGL2 ----
  // multisampling costs little on a GPU and four times the pixels on a software renderer
  // (SwiftShader, llvmpipe): there the edges stay aliased and the frames keep up
  const software = (() => {
    const probe = document.createElement("canvas").getContext("webgl2");
    const info = probe && probe.getExtension("WEBGL_debug_renderer_info");
    const name = info ? String(probe.getParameter(info.UNMASKED_RENDERER_WEBGL)) : "";
    if (probe) { const lose = probe.getExtension("WEBGL_lose_context"); if (lose) lose.loseContext(); }
    return /swiftshader|llvmpipe|software/i.test(name);
  })();
  const gl = canvas.getContext("webgl2", { antialias: !software });
  if (!gl) { status("This browser has no WebGL2: the station cannot show the tissue."); return; }
  function program(vs, fs) {
    const p = gl.createProgram();
    for (const [type, src] of [[gl.VERTEX_SHADER, vs], [gl.FRAGMENT_SHADER, fs]]) {
      const s = gl.createShader(type);
      gl.shaderSource(s, src);
      gl.compileShader(s);
      if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
      gl.attachShader(p, s);
    }
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error(gl.getProgramInfoLog(p));
    return p;
  }
  // the tissue: lit from the eye, both sides, each vertex in its region's colour (the
  // scene's: skin, fat, muscle in the wound); the inside of the wound (back faces) darker red
  const tissue = program(`#version 300 es
    in vec3 position; in vec3 normal; in vec3 colour;
    uniform mat4 view, projection;
    out vec3 v_normal; out vec3 v_eye; out vec3 v_colour; out vec3 v_world;
    void main() {
      vec4 p = view * vec4(position, 1.0);
      v_eye = -p.xyz; v_normal = mat3(view) * normal; v_colour = colour; v_world = position;
      gl_Position = projection * p;
    }`, `#version 300 es
    precision highp float;
    in vec3 v_normal; in vec3 v_eye; in vec3 v_colour; in vec3 v_world; out vec4 color;
    uniform vec3 clip_lo, clip_hi; // what is drawn: the tissue all, what lies behind it under it
    void main() {
      if (any(lessThan(v_world, clip_lo)) || any(greaterThan(v_world, clip_hi))) discard;
      vec3 n = normalize(v_normal); if (!gl_FrontFacing) n = -n;
      vec3 l = normalize(v_eye);
      float diffuse = max(dot(n, l), 0.0);
      float spec = pow(max(dot(reflect(-l, n), l), 0.0), 24.0) * 0.25;
      vec3 base = gl_FrontFacing ? v_colour : v_colour * vec3(0.7, 0.26, 0.25);
      color = vec4(base * (0.3 + 0.7 * diffuse) + spec, 1.0);
    }`);
  // each region's colour (linear RGB), the tissue's own where the scene gives none
  const TISSUE = [0.88, 0.62, 0.56];
  const palette = new Map((config.region_colours || []).map(([id, r, g, b]) => [id, [r, g, b]]));
  const lines = program(`#version 300 es
    in vec3 position; uniform mat4 view, projection; uniform float point_size;
    void main() { gl_Position = projection * view * vec4(position, 1.0); gl_PointSize = point_size; }`,
  `#version 300 es
    precision highp float; uniform vec3 tint; out vec4 color;
    void main() { color = vec4(tint, 1.0); }`);
  const mesh = { vao: gl.createVertexArray(), positions: gl.createBuffer(), normals: gl.createBuffer(),
    colours: gl.createBuffer(), indices: gl.createBuffer(), count: 0, vertices: 0, capacity: 0, triangles: null };
  const overlay = { vao: gl.createVertexArray(), buffer: gl.createBuffer() };
  gl.bindVertexArray(mesh.vao);
  for (const [buffer, name] of [[mesh.positions, "position"], [mesh.normals, "normal"], [mesh.colours, "colour"]]) {
    gl.bindBuffer(gl.ARRAY_BUFFER, buffer);
    const at = gl.getAttribLocation(tissue, name);
    gl.enableVertexAttribArray(at);
    gl.vertexAttribPointer(at, 3, gl.FLOAT, false, 0, 0);
  }
  gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, mesh.indices);
  // what lies behind the tissue: each an ellipsoid of 24 x 48 quads, the target (the heart)
  // deep red, a structure to spare (the lung) pink grey, drawn with the tissue's depth, so
  // that it shows only where an opening lets it
  const TARGET = [0.55, 0.02, 0.03], SPARE = [0.62, 0.42, 0.45];
  const targets = (config.targets || []).map((t) => {
    const n = 24, m = 48, xyz = [], normals = [], colours = [], tris = [];
    for (let i = 0; i <= n; i++) {
      const th = Math.PI * i / n;
      for (let j = 0; j <= m; j++) {
        const ph = 2 * Math.PI * j / m;
        const s = [Math.sin(th) * Math.cos(ph), Math.sin(th) * Math.sin(ph), Math.cos(th)];
        xyz.push(...s.map((c, k) => t.centre_m[k] + t.radii_m[k] * c));
        normals.push(...unit(s.map((c, k) => c / t.radii_m[k])));
        colours.push(...(t.spare ? SPARE : TARGET));
        if (i < n && j < m) {
          const a = i * (m + 1) + j, b = a + m + 1;
          tris.push(a, b, a + 1, a + 1, b, b + 1);
        }
      }
    }
    const vao = gl.createVertexArray();
    gl.bindVertexArray(vao);
    for (const [data, name] of [[xyz, "position"], [normals, "normal"], [colours, "colour"]]) {
      gl.bindBuffer(gl.ARRAY_BUFFER, gl.createBuffer());
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(data), gl.STATIC_DRAW);
      const at = gl.getAttribLocation(tissue, name);
      gl.enableVertexAttribArray(at);
      gl.vertexAttribPointer(at, 3, gl.FLOAT, false, 0, 0);
    }
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, gl.createBuffer());
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, new Uint32Array(tris), gl.STATIC_DRAW);
    return { vao, count: tris.length };
  });
  gl.bindVertexArray(overlay.vao);
  gl.bindBuffer(gl.ARRAY_BUFFER, overlay.buffer);
  gl.enableVertexAttribArray(gl.getAttribLocation(lines, "position"));
  gl.vertexAttribPointer(gl.getAttribLocation(lines, "position"), 3, gl.FLOAT, false, 0, 0);
  gl.bindVertexArray(null);

  function setTopology(view) {
    const vertices = view.getUint32(4, true), triangles = view.getUint32(8, true);
    mesh.triangles = new Uint32Array(view.buffer, 12, 3 * triangles).slice();
    mesh.count = 3 * triangles;
    mesh.vertices = vertices;
    gl.bindVertexArray(mesh.vao);
    gl.bindBuffer(gl.ELEMENT_ARRAY_BUFFER, mesh.indices);
    gl.bufferData(gl.ELEMENT_ARRAY_BUFFER, mesh.triangles, gl.DYNAMIC_DRAW);
    if (vertices > mesh.capacity) { // headroom for the vertices the next cuts add
      mesh.capacity = Math.ceil(vertices * 1.5);
      for (const b of [mesh.positions, mesh.normals, mesh.colours]) {
        gl.bindBuffer(gl.ARRAY_BUFFER, b);
        gl.bufferData(gl.ARRAY_BUFFER, 12 * mesh.capacity, gl.DYNAMIC_DRAW);
      }
    }
    // each vertex's region after the triangles (absent in an older server's message)
    const at = 12 + 12 * triangles, colours = new Float32Array(3 * vertices);
    const regions = view.byteLength >= at + 4 * vertices ? new Uint32Array(view.buffer, at, vertices) : null;
    mesh.regions = regions ? regions.slice() : null;
    for (let v = 0; v < vertices; v++) colours.set(palette.get(regions ? regions[v] : -1) || TISSUE, 3 * v);
    gl.bindBuffer(gl.ARRAY_BUFFER, mesh.colours);
    gl.bufferSubData(gl.ARRAY_BUFFER, 0, colours);
    gl.bindVertexArray(null);
  }

  // area-weighted vertex normals (scalar arithmetic: no arrays made per triangle, which the
  // garbage collector made the page's largest cost)
  function vertexNormals(xyz, tris, n) {
    const out = new Float32Array(3 * n);
    for (let t = 0; t < tris.length; t += 3) {
      const a = 3 * tris[t], b = 3 * tris[t + 1], c = 3 * tris[t + 2];
      const ux = xyz[b] - xyz[a], uy = xyz[b + 1] - xyz[a + 1], uz = xyz[b + 2] - xyz[a + 2];
      const vx = xyz[c] - xyz[a], vy = xyz[c + 1] - xyz[a + 1], vz = xyz[c + 2] - xyz[a + 2];
      const fx = uy * vz - uz * vy, fy = uz * vx - ux * vz, fz = ux * vy - uy * vx;
      out[a] += fx; out[a + 1] += fy; out[a + 2] += fz;
      out[b] += fx; out[b + 1] += fy; out[b + 2] += fz;
      out[c] += fx; out[c + 1] += fy; out[c + 2] += fz;
    }
    return out;
  }

  // ---- the camera: the exercise's viewpoint, or above the tissue along its up ----
  const up = config.up || [0, 0, 1];
  let camera = null;
  // the box around the points `xyz` (x, y, z, x, ...): [lo, hi]
  function bounds(xyz) {
    const lo = [Infinity, Infinity, Infinity], hi = [-Infinity, -Infinity, -Infinity];
    for (let i = 0; i < xyz.length; i += 3) for (let k = 0; k < 3; k++) {
      lo[k] = Math.min(lo[k], xyz[i + k]); hi[k] = Math.max(hi[k], xyz[i + k]);
    }
    return [lo, hi];
  }
  // the plan's line from its start to its end, across the view direction `f` (unit); null
  // without a plan or for a line that (nearly) closes on itself (an excision's outline, a
  // pattern's circle), whose start and end say nothing of its direction
  function lineAlong(f) {
    const line = config.plan && config.plan.line_m;
    if (!line || line.length < 2) return null;
    const d = sub(line[line.length - 1], line[0]);
    const reach = Math.max(...line.map((p) => norm(sub(p, line[0]))));
    if (norm(d) < 0.5 * reach) return null;
    const across = sub(d, scale(f, dot(d, f)));
    return norm(across) > 1e-6 ? unit(across) : null;
  }
  function frameCamera(xyz) {
    const [lo, hi] = bounds(xyz);
    const size = norm(sub(hi, lo));
    let target = scale(add(lo, hi), 0.5), eye;
    if (config.plan) { // frame the incision
      const line = config.plan.line_m;
      target = scale(add(line[0], line[line.length - 1]), 0.5);
    }
    if (config.viewpoint) {
      eye = config.viewpoint.eye_m; target = config.viewpoint.look_at_m;
    } else {
      const side = unit(cross(up, Math.abs(up[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0]));
      eye = add(target, add(scale(up, 0.55 * size), scale(side, -0.35 * size)));
    }
    const f = unit(sub(target, eye));
    let viewUp = Math.abs(dot(f, up)) > 0.99 ? cross(up, [1, 0, 0]) : up;
    // the planned line runs left to right on the screen, as in the debrief's top view and
    // the replay (a closed line, a pattern's circle, keeps the view's up)
    const along = lineAlong(f);
    if (along) viewUp = cross(along, f);
    camera = { eye, target, up: viewUp, near: 0.01 * size, far: 10 * size };
  }
  function matrices() {
    const aspect = canvas.clientWidth / Math.max(1, canvas.clientHeight);
    return { view: lookAt(camera.eye, camera.target, camera.up), projection: perspective(0.7, aspect, camera.near, camera.far) };
  }

  // ---- the latest frame, what the page shows ----
  let latest = null, fresh = false;
  const forceLimit = config.force_limit_n > 0 ? config.force_limit_n : 2.5;
  const stats = { frames: 0, draws: 0, rafs: 0, messages: 0, work_ms: 0, since: performance.now(), latencies: [], bytes: 0 };
  function takeFrame(view) {
    const vertices = view.getUint32(4, true);
    const f32 = (at, n) => Array.from(new Float32Array(view.buffer, at, n));
    latest = {
      mode: view.getUint8(1), engaged: view.getUint8(2) === 1, faults: view.getUint8(3),
      tick: Number(view.getBigUint64(8, true)), echo: view.getFloat64(16, true),
      tip: f32(24, 3), rotation: f32(36, 4), force: f32(52, 3),
      // the second hand's grasper: 0 none, 1 open, 2 closed on nothing, 3 holding
      grasper: view.getUint8(64), jaws: f32(68, 3), pull: view.getFloat32(80, true),
      xyz: new Float32Array(view.buffer, FRAME_HEADER_BYTES, 3 * vertices),
    };
    fresh = true;
  }
  // the tissue's rest surface, the session's first, before anything touched it: the server
  // sends it first on every connection, so a page that joins a running attempt (a reload)
  // measures as the one that saw it begin. Depths are measured from it, as the score
  // measures them: the pointer's point and the blade's depth below the surface
  function takeRest(view) {
    const vertices = view.getUint32(4, true), triangles = view.getUint32(8, true);
    const triangles_at = 12, xyz_at = 12 + 12 * triangles;
    if (view.byteLength < xyz_at + 12 * vertices) return;
    rest = {
      triangles: new Uint32Array(view.buffer, triangles_at, 3 * triangles).slice(),
      xyz: new Float32Array(view.buffer, xyz_at, 3 * vertices).slice(),
    };
    underTissue = null;
  }

  // ---- the rest surface: where the pointer points, how deep the blade is ----
  let rest = null;
  // the box what lies behind the tissue is drawn in (from the rest surface, once)
  let underTissue = null;
  // the nearest crossing of the ray `origin + t dir` (t > 0) with the rest surface
  // (Möller–Trumbore, in scalars: it runs for every pointer event and every frame):
  // { point, normal, t } or null
  function castRest(origin, dir) {
    if (!rest) return null;
    const xyz = rest.xyz, tris = rest.triangles;
    const [ox, oy, oz] = origin, [dx, dy, dz] = dir;
    let best = Infinity, hit = -1;
    for (let i = 0; i < tris.length; i += 3) {
      const a = 3 * tris[i], b = 3 * tris[i + 1], c = 3 * tris[i + 2];
      const ax = xyz[a], ay = xyz[a + 1], az = xyz[a + 2];
      const e1x = xyz[b] - ax, e1y = xyz[b + 1] - ay, e1z = xyz[b + 2] - az;
      const e2x = xyz[c] - ax, e2y = xyz[c + 1] - ay, e2z = xyz[c + 2] - az;
      const px = dy * e2z - dz * e2y, py = dz * e2x - dx * e2z, pz = dx * e2y - dy * e2x;
      const det = e1x * px + e1y * py + e1z * pz;
      if (Math.abs(det) < 1e-14) continue;
      const tx = ox - ax, ty = oy - ay, tz = oz - az;
      const uu = (tx * px + ty * py + tz * pz) / det;
      if (uu < 0 || uu > 1) continue;
      const qx = ty * e1z - tz * e1y, qy = tz * e1x - tx * e1z, qz = tx * e1y - ty * e1x;
      const vv = (dx * qx + dy * qy + dz * qz) / det;
      if (vv < 0 || uu + vv > 1) continue;
      const d = (e2x * qx + e2y * qy + e2z * qz) / det;
      if (d > 0 && d < best) { best = d; hit = i; }
    }
    if (hit < 0) return null;
    const a = 3 * tris[hit], b = 3 * tris[hit + 1], c = 3 * tris[hit + 2];
    const e1 = [xyz[b] - xyz[a], xyz[b + 1] - xyz[a + 1], xyz[b + 2] - xyz[a + 2]];
    const e2 = [xyz[c] - xyz[a], xyz[c + 1] - xyz[a + 1], xyz[c + 2] - xyz[a + 2]];
    return { point: add(origin, scale(dir, best)), normal: unit(cross(e1, e2)), t: best };
  }
  // the rest surface above `point` along `up`: { point, depth } (depth below it in m, negative
  // above it), or null off the tissue
  function surfaceAbove(point) {
    const reach = 0.2, hit = castRest(add(point, scale(up, reach)), scale(up, -1));
    return hit ? { point: hit.point, depth: reach - hit.t } : null;
  }
  // the rest surface above the latest frame's blade tip (cast once a frame, read by the HUD
  // and the drawing)
  // the layer the blade is in: the region of the surface's vertex nearest its tip (the
  // wound's faces lie against the blade), named as the scene names it; null off the tissue,
  // at the surface, or where the scene names no layers
  const regionNames = new Map((config.region_names || []).map(([id, name]) => [id, name]));
  let layerShown = null;
  function bladeLayer(f, above) {
    if (!above || above.depth <= 0.0005 || !mesh.regions || regionNames.size === 0) return null;
    const xyz = f.xyz, t = f.tip;
    let best = 1e-4, region = null; // within 10 mm
    for (let v = 0; v < mesh.vertices; v++) {
      const dx = xyz[3 * v] - t[0], dy = xyz[3 * v + 1] - t[1], dz = xyz[3 * v + 2] - t[2];
      const d = dx * dx + dy * dy + dz * dz;
      if (d < best) { best = d; region = mesh.regions[v]; }
    }
    return region === null ? null : regionNames.get(region) ?? null;
  }
  function bladeAbove() {
    if (!("above" in latest)) latest.above = surfaceAbove(latest.tip);
    return latest.above;
  }

  // a program's uniform locations, looked up once
  const uniforms = new Map();
  function uniform(program, name) {
    if (!uniforms.has(program)) uniforms.set(program, new Map());
    const m = uniforms.get(program);
    if (!m.has(name)) m.set(name, gl.getUniformLocation(program, name));
    return m.get(name);
  }

  function draw() {
    requestAnimationFrame(draw);
    stats.rafs += 1;
    if (!latest || !mesh.triangles || latest.xyz.length !== 3 * mesh.vertices) return;
    if (!camera) frameCamera(rest ? rest.xyz : latest.xyz);
    // the drawing buffer: the screen's pixels on a GPU, half the CSS pixels each way on a
    // software renderer (a quarter of the work; the browser scales the picture up)
    const density = software ? 0.5 : Math.min(2, window.devicePixelRatio || 1);
    const w = Math.round(canvas.clientWidth * density), h = Math.round(canvas.clientHeight * density);
    const resized = canvas.width !== w || canvas.height !== h;
    // nothing new to show: the last picture stays (no work for the CPU or the GPU)
    if (!fresh && !resized) return;
    const started = performance.now();
    if (resized) { canvas.width = w; canvas.height = h; }
    gl.viewport(0, 0, canvas.width, canvas.height);
    gl.clearColor(0.12, 0.15, 0.17, 1);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    const { view, projection } = matrices();
    if (fresh) {
      gl.bindBuffer(gl.ARRAY_BUFFER, mesh.positions);
      gl.bufferSubData(gl.ARRAY_BUFFER, 0, latest.xyz);
      gl.bindBuffer(gl.ARRAY_BUFFER, mesh.normals);
      gl.bufferSubData(gl.ARRAY_BUFFER, 0, vertexNormals(latest.xyz, mesh.triangles, mesh.vertices));
      fresh = false;
      stats.frames += 1;
      if (Number.isFinite(latest.echo)) stats.latencies.push(performance.now() - latest.echo);
      hud(latest);
    }
    gl.useProgram(tissue);
    gl.uniformMatrix4fv(uniform(tissue, "view"), false, view);
    gl.uniformMatrix4fv(uniform(tissue, "projection"), false, projection);
    gl.bindVertexArray(mesh.vao);
    gl.uniform3fv(uniform(tissue, "clip_lo"), [-1e9, -1e9, -1e9]);
    gl.uniform3fv(uniform(tissue, "clip_hi"), [1e9, 1e9, 1e9]);
    gl.drawElements(gl.TRIANGLES, mesh.count, gl.UNSIGNED_INT, 0);
    // what lies behind the tissue, only under it, 3 mm in from its rest bounds (the lung
    // reaches beyond the window: seen beside it, it would look like part of the patient)
    if (!underTissue) {
      const [lo, hi] = bounds(rest ? rest.xyz : latest.xyz);
      const under = (box, inset, far) => box.map((c, k) => (Math.abs(up[k]) > 0.5 ? far : c + inset));
      underTissue = [under(lo, 0.003, -1e9), under(hi, -0.003, 1e9)];
    }
    gl.uniform3fv(uniform(tissue, "clip_lo"), underTissue[0]);
    gl.uniform3fv(uniform(tissue, "clip_hi"), underTissue[1]);
    for (const t of targets) {
      gl.bindVertexArray(t.vao);
      gl.drawElements(gl.TRIANGLES, t.count, gl.UNSIGNED_INT, 0);
    }
    // overlays: the plan (guided), the blade
    gl.useProgram(lines);
    gl.uniformMatrix4fv(uniform(lines, "view"), false, view);
    gl.uniformMatrix4fv(uniform(lines, "projection"), false, projection);
    gl.bindVertexArray(overlay.vao);
    const strip = (points, mode, tint, size) => {
      gl.bindBuffer(gl.ARRAY_BUFFER, overlay.buffer);
      gl.bufferData(gl.ARRAY_BUFFER, new Float32Array(points.flat()), gl.STREAM_DRAW);
      gl.uniform3fv(uniform(lines, "tint"), tint);
      gl.uniform1f(uniform(lines, "point_size"), size || 1);
      gl.drawArrays(mode, 0, points.length);
    };
    if (config.plan) {
      const lift = (p, i) => add(p, scale(config.plan.normals[i] || up, 0.0005));
      const line = config.plan.line_m.map(lift);
      strip(line, gl.LINE_STRIP, [0.16, 0.78, 0.35]);
      strip([line[0]], gl.POINTS, [0.16, 0.78, 0.35], 10);
      strip([line[line.length - 1]], gl.POINTS, [0.95, 0.75, 0.2], 10);
    }
    // the marks on the tissue (a pattern's circle, in ink), whatever the mode
    for (const mark of config.marks || []) strip(mark, gl.LINE_STRIP, [0.12, 0.16, 0.55]);
    if (!config.plan && rest) strip(ruler(), gl.LINES, [0.95, 0.95, 0.95]);
    drawBlade(strip);
    drawGrasper(strip);
    stats.draws += 1;
    stats.work_ms += performance.now() - started;
  }
  requestAnimationFrame(draw);

  // the blade in 3D: a steel blade (its cutting edge along the tool's x, its back behind),
  // the part below the intact surface red, its shadow on the surface straight above the tip,
  // and the handle above; drawn over the tissue so it is seen inside the cut too
  function drawBlade(strip) {
    const tip = latest.tip, axis = rotate(latest.rotation, [0, 0, 1]);
    const back = scale(rotate(latest.rotation, [1, 0, 0]), -BLADE_WIDTH_M);
    const at = (along, behind) => add(add(tip, scale(axis, along * BLADE_LENGTH_M)), scale(back, behind));
    const above = bladeAbove();
    gl.enable(gl.DEPTH_TEST);
    if (above) { // the shadow: a dark spot on the surface, where the blade enters
      const lift = add(above.point, scale(up, 0.0003));
      strip([lift, add(lift, back)], gl.LINES, [0.08, 0.06, 0.06]);
      strip([lift], gl.POINTS, [0.08, 0.06, 0.06], 9);
    }
    gl.disable(gl.DEPTH_TEST);
    const steel = latest.engaged ? [0.86, 0.88, 0.92] : [0.55, 0.58, 0.62];
    strip([at(0, 0), at(1, 0), at(1, 1), at(0, 0), at(1, 1), at(0.3, 1)], gl.TRIANGLES, steel);
    strip([at(1, 0.5), at(4, 0.5)], gl.LINES, [0.3, 0.32, 0.36]);
    if (above && above.depth > 0) { // the buried part of the edge
      strip([tip, add(tip, scale(axis, Math.min(above.depth / Math.max(1e-6, dot(axis, up)), 4 * BLADE_LENGTH_M)))], gl.LINES, [1, 0.25, 0.2]);
    }
    strip([tip], gl.POINTS, latest.mode === 2 ? [1, 0.3, 0.2] : [0.9, 0.9, 0.95], 6);
  }

  // the second hand's grasper: its two jaws either side of their centre across the view, a
  // shaft up from it; grey open, blue closed, bright blue holding tissue
  function drawGrasper(strip) {
    if (!latest.grasper) return;
    const c = latest.jaws, { s } = basis(camera.eye, camera.target, camera.up);
    const gap = latest.grasper === 1 ? 0.004 : 0.001, jaw = (k) => add(c, scale(s, k * gap));
    const tint = [[0.6, 0.62, 0.66], [0.6, 0.62, 0.66], [0.25, 0.45, 0.8], [0.2, 0.55, 1]][latest.grasper];
    gl.disable(gl.DEPTH_TEST);
    strip([add(jaw(1), scale(up, 0.006)), jaw(1), add(jaw(-1), scale(up, 0.006)), jaw(-1)], gl.LINES, tint);
    strip([add(c, scale(up, 0.006)), add(c, scale(up, 0.04))], gl.LINES, [0.3, 0.32, 0.36]);
    strip([c], gl.POINTS, tint, 8);
  }

  // exam mode's landmarks: a ruler on the tissue, ticks every 10 mm along its two near
  // edges (long ones every 50 mm and at the middle), so a length and a place can be judged
  // without the plan
  let rulerPoints = null;
  function ruler() {
    if (rulerPoints) return rulerPoints;
    const [lo, hi] = bounds(rest.xyz);
    const axes = [0, 1, 2].filter((k) => Math.abs(up[k]) < 0.5), mid = scale(add(lo, hi), 0.5);
    rulerPoints = [];
    for (const [along, across] of [[axes[0], axes[1]], [axes[1], axes[0]]]) {
      for (let k = -40; k <= 40; k++) {
        const p = mid.slice(); p[along] = mid[along] + k * 0.01; p[across] = lo[across] + 0.003;
        if (p[along] < lo[along] || p[along] > hi[along]) continue;
        const s = surfaceAbove(p);
        if (!s) continue;
        const foot = add(s.point, scale(up, 0.0003)), inward = [0, 0, 0];
        inward[across] = k === 0 || k % 5 === 0 ? 0.008 : 0.004;
        rulerPoints.push(foot, add(foot, inward));
      }
    }
    return rulerPoints;
  }

  // the axes marker: the world's x (red), y (green) and z (blue) as this view shows them (the
  // frame the recording and the replay are in; the debrief's top view is in the plan's)
  let axesDrawn = null;
  function axesMarker() {
    const marker = document.getElementById("axes");
    if (!marker || !camera) return;
    const c = marker.getContext("2d"), mid = marker.width / 2, reach = 0.36 * marker.width;
    const { s: side, u: upOnScreen } = basis(camera.eye, camera.target, camera.up);
    c.clearRect(0, 0, marker.width, marker.height);
    c.lineWidth = 2; c.font = "11px sans-serif"; c.textAlign = "center"; c.textBaseline = "middle";
    axesDrawn = {};
    [["x", [1, 0, 0], "#dc3c3c"], ["y", [0, 1, 0], "#2e9a2e"], ["z", [0, 0, 1], "#3c5adc"]].forEach(([name, e, colour]) => {
      const x = mid + reach * dot(e, side), y = mid - reach * dot(e, upOnScreen);
      axesDrawn[name] = [x - mid, y - mid];
      c.strokeStyle = colour; c.fillStyle = colour;
      c.beginPath(); c.moveTo(mid, mid); c.lineTo(x, y); c.stroke();
      c.fillText(name, mid + (x - mid) * 1.3, mid + (y - mid) * 1.3);
    });
  }

  // the scale bar: 10 mm at the middle of the view, in CSS pixels
  function scaleBar() {
    const bar = document.getElementById("scale-bar");
    if (!bar || !camera) return;
    const { s: side } = basis(camera.eye, camera.target, camera.up);
    const a = window.cutlabStation.project(camera.target), b = window.cutlabStation.project(add(camera.target, scale(side, 0.01)));
    bar.style.width = Math.max(4, Math.round(Math.hypot(b[0] - a[0], b[1] - a[1]))) + "px";
  }

  // the depth gauge: the cut seen from the side (the view looks down the blade): the
  // surface, the planned depth (green, dashed), the depth the wheel set (grey), the blade
  // (steel above the surface, red below it, to its tip)
  const gaugeCanvas = document.getElementById("depth-gauge");
  // the gauge's range, mm: the deepest the blade is set to go (20 mm, or the scene's blade)
  const GAUGE_MM = Math.max(20, Math.ceil((config.max_depth_m ?? 0.02) * 1e3 / 10) * 10);
  // what the gauge drew last (the depths of its grey line and of the blade): for the tests
  let gaugeDrawn = null;
  // `bladeDepth`: the blade's, now; the grey line is the depth the trainee set (`depth`, below:
  // a parameter of the same name once hid it, and the set-depth line followed the blade)
  // the gauge's still part (the tissue, the millimetre ticks and their numbers, the planned
  // depth), drawn once: text on a software-rendered canvas is dear
  let gaugeBackground = null, gaugeKey = null;
  function gauge(bladeDepth) {
    if (!gaugeCanvas) return;
    const g = gaugeCanvas.getContext("2d"), w = gaugeCanvas.width, h = gaugeCanvas.height;
    const top = 14, mm = (h - top - 6) / GAUGE_MM, y = (m) => top + m * 1e3 * mm;
    const line = (g, m, colour, dash) => { g.setLineDash(dash); g.strokeStyle = colour; g.lineWidth = 2; g.beginPath(); g.moveTo(28, y(m)); g.lineTo(w, y(m)); g.stroke(); g.setLineDash([]); };
    const setShown = config.pointer && config.driver ? depth : null;
    gaugeDrawn = { set_m: setShown, blade_m: bladeDepth };
    // nothing a person could see changed (a hundredth of a millimetre): the picture stays
    const key = `${setShown}|${bladeDepth === null ? "-" : Math.round(bladeDepth * 1e5)}`;
    if (key === gaugeKey) return;
    gaugeKey = key;
    if (!gaugeBackground) {
      gaugeBackground = document.createElement("canvas");
      gaugeBackground.width = w; gaugeBackground.height = h;
      const b = gaugeBackground.getContext("2d");
      b.fillStyle = "#e9b8ac"; b.fillRect(0, top, w, h - top);
      b.fillStyle = "#1f262b"; b.font = "10px sans-serif";
      const every = GAUGE_MM > 30 ? 10 : 5;
      for (let k = 0; k <= GAUGE_MM; k += every) { b.fillRect(0, y(k * 1e-3), k % (2 * every) ? 4 : 8, 1); if (k) b.fillText(k + "", 10, y(k * 1e-3) + 4); }
      b.fillText("mm", 10, 10);
      if (config.plan) line(b, config.plan.depth_m, "#17803d", [5, 3]);
    }
    g.clearRect(0, 0, w, h);
    g.drawImage(gaugeBackground, 0, 0);
    if (setShown !== null) line(g, setShown, "#6b7378", [2, 3]);
    if (bladeDepth === null) return;
    const x = 0.65 * w, tip = y(Math.max(-top / mm * 1e-3, Math.min(GAUGE_MM * 1e-3, bladeDepth)));
    g.fillStyle = "#c9ced6"; g.fillRect(x - 3, 0, 6, Math.min(tip, top));
    if (bladeDepth > 0) { g.fillStyle = "#d4351c"; g.fillRect(x - 3, top, 6, tip - top); }
  }
  // the depth the wheel, the keys or the pen set (the pointer's), up to the scene's blade; a
  // wheel's notch or a key sets 1/40 of that (0.5 mm of the 20 mm blade, 1.5 mm of the
  // thorax's 60 mm), full pressure of a pen 0.6 of it
  let depth = config.start_depth_m ?? 0.004;
  const DEPTH_MAX_M = config.max_depth_m ?? 0.02, DEPTH_STEP_M = Math.max(0.0005, DEPTH_MAX_M / 40);
  const deeper = (by) => { depth = Math.max(0, Math.min(DEPTH_MAX_M, depth + by)); };

  const MODES = ["free", "touching", "cutting"];
  let cutSeen = false, releasedAt = null;
  // the force as a person can read it: smoothed over about 150 ms (the servo's force jumps
  // between ticks), the warning held for a second after the limit the score uses was passed
  let forceShown = 0, overUntil = 0, scaled = false;
  window.addEventListener("resize", () => { scaled = false; });
  // the HUD's elements, written only when what they show changes (a write of the same text
  // still makes the browser restyle the page)
  const shown = new Map();
  function show(id, what, value) {
    const key = id + "." + what;
    if (shown.get(key) === value) return;
    shown.set(key, value);
    const e = document.getElementById(id);
    if (!e) return;
    if (what === "width") e.style.width = value; else e[what] = value;
  }
  function hud(f) {
    const force = norm(f.force), now = performance.now();
    forceShown += (force - forceShown) * 0.25;
    if (force > forceLimit) overUntil = now + 1000;
    show("force-value", "textContent", forceShown.toFixed(2) + " N");
    show("force-bar", "width", Math.min(100, 100 * forceShown / forceLimit).toFixed(0) + "%");
    show("force-bar", "className", now < overUntil ? "over" : forceShown > 0.7 * forceLimit ? "near" : "");
    show("force-warning", "hidden", now >= overUntil);
    show("elapsed", "textContent", (f.tick * 1e-3).toFixed(1) + " s");
    show("blade", "textContent", (f.engaged ? "engaged, " : "") + MODES[f.mode]);
    // the blade's depth below the intact surface, where the tip is now
    const above = bladeAbove();
    show("blade-depth", "textContent", !above ? "off the tissue"
      : above.depth > 0.00005 ? (above.depth * 1e3).toFixed(1) + " mm below the surface" : "at or above the surface");
    gauge(above ? above.depth : null);
    layerShown = bladeLayer(f, above);
    show("blade-layer", "textContent", layerShown ?? "–");
    if (f.grasper) show("grasper", "textContent", ["", "open", "closed on nothing", "holding " + f.pull.toFixed(2) + " N"][f.grasper]);
    if (!scaled) { scaled = true; scaleBar(); axesMarker(); }
    cutSeen = cutSeen || f.mode === 2;
  }

  // ---- the socket ----
  // a lost connection (a reload, the network, an oversized message) is made again: the
  // session waits for its page (the blade pauses) for `config.absence_s`
  let socket = null, ended = false, lostAt = null;
  function connect() {
    socket = new WebSocket((location.protocol === "https:" ? "wss://" : "ws://") + location.host + config.ws);
    socket.binaryType = "arraybuffer";
    socket.onopen = () => { if (lostAt !== null) { lostAt = null; status("Connected again: carry on."); } };
    socket.onmessage = (event) => {
      if (typeof event.data === "string") return onText(JSON.parse(event.data));
      stats.bytes += event.data.byteLength;
      stats.messages += 1;
      const view = new DataView(event.data);
      const kind = view.getUint8(0);
      if (kind === KIND_REST) takeRest(view);
      else if (kind === KIND_TOPOLOGY) setTopology(view);
      else if (kind === KIND_FRAME) takeFrame(view);
    };
    socket.onclose = () => {
      if (ended) return;
      if (lostAt === null) lostAt = performance.now();
      const away_s = (performance.now() - lostAt) / 1000;
      if (away_s > (config.absence_s || 30)) { status("The connection to the session was lost."); return; }
      status("The connection was lost: connecting again…");
      setTimeout(connect, Math.min(2000, 250 + away_s * 200));
    };
  }
  connect();
  function onText(m) {
    if (m.type !== "ended") return;
    ended = true;
    const stopButton = document.getElementById("stop");
    if (stopButton) stopButton.hidden = true;
    const debrief = document.getElementById("debrief");
    const link = `/attempts/${m.attempt}`;
    status(m.scored ? `Ended: score ${m.score.toFixed(2)}, ${m.passed ? "PASS" : "FAIL"}.` : `Ended, not scored: ${m.why}`);
    debrief.innerHTML = "";
    const p = document.createElement("p");
    p.id = "debrief-summary";
    p.textContent = m.scored ? `Score ${m.score.toFixed(2)} (${m.passed ? "pass" : "fail"}). ` : `Not scored: ${m.why}. `;
    const a = document.createElement("a"); a.href = link; a.textContent = "The attempt, its metrics and its replay";
    p.appendChild(a);
    debrief.appendChild(p);
    // the attempt's page (metrics and their verdicts, the cut against the plan, the replay link)
    fetch(link, { credentials: "same-origin" }).then((r) => r.ok ? r.text() : "").then((html) => {
      const main = new DOMParser().parseFromString(html, "text/html").querySelector("main");
      if (main) { const section = document.createElement("section"); section.id = "debrief-attempt"; section.append(...main.childNodes); debrief.appendChild(section); }
    });
  }

  window.cutlabStation = {
    // the depths the gauge drew last, m: `set_m` (the grey line), `blade_m`
    gauge() { return gaugeDrawn; },
    // the layer the HUD names the blade in (null: none)
    layer() { return layerShown; },
    // the axes marker's arrows as drawn, canvas pixels from its middle (y down): { x, y, z }
    axes() { return axesDrawn; },
    // the figures `cutlab bench station` reads
    stats() {
      const s = (performance.now() - stats.since) / 1000;
      // fps: frames drawn; updates_per_s: of them, those with new positions from the session
      return { fps: stats.draws / s, updates_per_s: stats.frames / s, latencies_ms: stats.latencies.slice(), bytes_per_s: stats.bytes / s, frames: stats.frames, draws: stats.draws, page_ms_per_frame: stats.work_ms / Math.max(1, stats.draws), animation_frames_per_s: stats.rafs / s, messages_per_s: stats.messages / s, seconds: s, ended };
    },
    // starts the figures afresh (a benchmark's measured window)
    reset() { Object.assign(stats, { frames: 0, draws: 0, rafs: 0, messages: 0, work_ms: 0, since: performance.now(), latencies: [], bytes: 0 }); },
    config,
    // the surface's vertex count now, and the rest surface's (the session's first)
    vertices() { return mesh.vertices || 0; },
    restVertices() { return rest ? rest.xyz.length / 3 : 0; },
    // where a world point (m) is on the page, in CSS pixels of the viewport (for tests)
    project(point) {
      if (!camera) return null;
      const { view, projection } = matrices();
      const v = [point[0], point[1], point[2], 1];
      const mul = (m, x) => [0, 1, 2, 3].map((r) => m[r] * x[0] + m[4 + r] * x[1] + m[8 + r] * x[2] + m[12 + r] * x[3]);
      const c = mul(projection, mul(view, v));
      const r = canvas.getBoundingClientRect();
      return [r.left + (c[0] / c[3] + 1) / 2 * r.width, r.top + (1 - c[1] / c[3]) / 2 * r.height];
    },
  };
  if (!config.driver) return;
  function stop() { if (socket.readyState === WebSocket.OPEN) socket.send(JSON.stringify({ type: "stop" })); }
  document.getElementById("stop").addEventListener("click", stop);
  if (!config.pointer) { document.getElementById("depth").textContent = "by the device"; return; }

  // ---- the trainee's input: the point under the pointer on the tissue, depth, button ----
  let hit = null, engaged = false, lastSent = 0, retracting = false;
  document.getElementById("depth").textContent = (depth * 1e3).toFixed(1) + " mm";
  function ray(event) {
    const r = canvas.getBoundingClientRect();
    const x = 2 * (event.clientX - r.left) / r.width - 1, y = 1 - 2 * (event.clientY - r.top) / r.height;
    const { f, s, u } = basis(camera.eye, camera.target, camera.up);
    const t = Math.tan(0.35), aspect = r.width / r.height;
    return { origin: camera.eye, dir: unit(add(f, add(scale(s, x * t * aspect), scale(u, y * t)))) };
  }
  // the point under the pointer on the tissue's rest surface (not the pressed or cut one:
  // the depth is below the intact surface, as the score measures it)
  function pick(event) {
    if (!camera) return null;
    const { origin, dir } = ray(event);
    return castRest(origin, dir);
  }
  function send(t_ms) {
    if (!hit || socket.readyState !== WebSocket.OPEN || !(t_ms > lastSent)) return;
    lastSent = t_ms;
    socket.send(JSON.stringify({ type: "pointer", t_ms, surface_in_world_m: hit.point, depth_m: engaged ? depth : 0, blade_engaged: engaged, retractor: retracting }));
  }
  // the wound retractor (a field exercise): set into the incision while on, spreading it
  // 20 mm; the attempt then waits for Stop rather than ending after the blade's lift
  const retractButton = document.getElementById("retract");
  function toggleRetractor() {
    if (!config.retractor) return;
    retracting = !retracting;
    retractButton.setAttribute("aria-pressed", String(retracting));
    retractButton.textContent = retracting ? "Take the retractor out (R)" : "Set the retractor (R)";
    status(retracting ? "Retractor set in the incision: the wound opens 20 mm. Stop when you have seen the field." : "Retractor out: the wound closes.");
    if (retracting) releasedAt = null;
    send(performance.now());
  }
  if (retractButton) retractButton.addEventListener("click", toggleRetractor);
  // the second hand: a touch closes the grasper's jaws where it lands, drags the tissue
  // along, lifts the jaws over 0.3 s once closed, and opens them when it lifts
  const GRASP_LIFT_M = 0.004, LIFT_S = 0.3;
  const grasp = { id: null, hit: null, closedAt: null, lastSent: 0 };
  const isGrasper = (e) => config.grasper && e.pointerType === "touch";
  // the lift follows the samples' own clock (an event's time stamp, or now for the
  // heartbeat), so a page that handles its events late still lifts over 0.3 s of its samples
  function sendGrasper(t_ms, liftM) {
    if (!grasp.hit || socket.readyState !== WebSocket.OPEN || !(t_ms > grasp.lastSent)) return;
    grasp.lastSent = t_ms;
    const closed = grasp.closedAt !== null;
    const lift = liftM ?? (closed ? GRASP_LIFT_M * Math.min(1, Math.max(0, t_ms - grasp.closedAt) / (LIFT_S * 1e3)) : GRASP_LIFT_M);
    socket.send(JSON.stringify({ type: "grasper", t_ms, surface_in_world_m: grasp.hit.point, depth_m: -lift, blade_engaged: closed }));
  }
  canvas.addEventListener("pointerdown", (event) => {
    if (!isGrasper(event) || grasp.id !== null) return;
    const h = pick(event); if (!h) return;
    canvas.setPointerCapture(event.pointerId);
    // the jaws come down open onto the point, then close there: open at the surface before
    // closed at it, so no tick between the two samples closes them above it
    const t = event.timeStamp;
    grasp.id = event.pointerId; grasp.hit = h; grasp.closedAt = null;
    sendGrasper(t);
    sendGrasper(t + 0.5, 0);
    grasp.closedAt = t + 1;
    sendGrasper(t + 1);
  });
  canvas.addEventListener("pointermove", (event) => {
    if (event.pointerId !== grasp.id) return;
    const h = pick(event); if (h) { grasp.hit = h; sendGrasper(event.timeStamp); }
  });
  const letGo = (event) => {
    if (event.pointerId !== grasp.id) return;
    grasp.id = null; grasp.closedAt = null;
    sendGrasper(event.timeStamp);
  };
  canvas.addEventListener("pointerup", letGo);
  canvas.addEventListener("pointercancel", letGo);
  canvas.addEventListener("pointermove", (event) => {
    if (isGrasper(event)) return;
    const events = event.getCoalescedEvents ? event.getCoalescedEvents() : [event];
    for (const e of events.length ? events : [event]) {
      if (e.pointerType === "pen" && e.pressure > 0) depth = Math.min(DEPTH_MAX_M, e.pressure * 0.6 * DEPTH_MAX_M);
      const h = pick(e);
      if (h) { hit = h; send(e.timeStamp); }
    }
  });
  canvas.addEventListener("pointerdown", (event) => {
    if (event.button !== 0 || isGrasper(event)) return;
    canvas.setPointerCapture(event.pointerId);
    engaged = true; releasedAt = null;
    const h = pick(event); if (h) hit = h;
    send(event.timeStamp);
  });
  canvas.addEventListener("pointerup", (event) => {
    if (isGrasper(event)) return;
    engaged = false; releasedAt = performance.now(); send(event.timeStamp);
  });
  canvas.addEventListener("wheel", (event) => {
    event.preventDefault();
    deeper(-Math.sign(event.deltaY) * DEPTH_STEP_M);
    document.getElementById("depth").textContent = (depth * 1e3).toFixed(1) + " mm";
  }, { passive: false });
  window.addEventListener("keydown", (event) => {
    if (event.key === "ArrowUp") deeper(-DEPTH_STEP_M);
    else if (event.key === "ArrowDown") deeper(DEPTH_STEP_M);
    else if (event.key === "r" || event.key === "R") { toggleRetractor(); return; }
    else return;
    document.getElementById("depth").textContent = (depth * 1e3).toFixed(1) + " mm";
  });
  // the pose must keep arriving while the hand holds still: a sample 100 ms after the last
  // one (not every frame: a repeat of the last point between two moves stopped the blade for
  // a few ms, and its resistance with it, at every frame); and the blade lifted out for 1.5 s
  // after a cut ends the session
  (function heartbeat() {
    requestAnimationFrame(heartbeat);
    const now = performance.now();
    if (now - lastSent > 100) send(now);
    // the grasper's too, every 50 ms: its lift goes on while the touch holds still
    if (grasp.hit && now - grasp.lastSent > 50) sendGrasper(now);
    // (a page with a retractor waits longer: time to set it after the lift)
    const autoStopMs = config.retractor ? 5000 : 1500;
    if (cutSeen && !engaged && !retracting && releasedAt !== null && performance.now() - releasedAt > autoStopMs && !ended) { stop(); releasedAt = null; }
  })();
})();
