// polyjax view: WebGL2 programs over the BRDF functions the page carries (GLSL from polyjax's expression builder,
// MERL-grid tables as 3D textures), drawn into 2D canvases; window.polyjaxView exposes the state and the plotted
// numbers. Conventions: polyjax.render (pixel centres, unit sphere at the origin, point light I cos / r^2,
// 2^exposure, clip, sRGB) - see docs/viewer.md.
"use strict";
(function () {
  const DATA = JSON.parse(document.getElementById("polyjax-data").textContent);
  const BRDFS = document.getElementById("polyjax-brdfs").textContent;
  const S = DATA.settings, ITEMS = DATA.items;
  const DEG = Math.PI / 180;
  const view = window.polyjaxView = { ready: false, error: null, frame: 0, state: {}, polar: null, albedo: null,
                                      points: null, photos: null, items: ITEMS.map((it) => it.name) };
  const $ = (id) => document.getElementById(id);

  function fail(msg) {
    const m = $("message");
    m.textContent = msg;
    m.hidden = false;
    view.error = msg;
  }

  // ------------------------------------------------------------------ WebGL2 set-up
  const glCanvas = document.createElement("canvas");
  const gl = glCanvas.getContext("webgl2", { preserveDrawingBuffer: true, antialias: false, alpha: false,
                                             premultipliedAlpha: false, depth: false });
  if (!gl) {
    fail("This page needs WebGL2, which this browser does not provide (or has turned off): no view can be drawn.");
    $("views").hidden = true;
    return;
  }
  const floatTargets = !!gl.getExtension("EXT_color_buffer_float");

  const VERT = `#version 300 es
void main() { vec2 p = vec2(float((gl_VertexID << 1) & 2), float(gl_VertexID & 2));
  gl_Position = vec4(p * 2.0 - 1.0, 0.0, 1.0); }`;

  const PRELUDE = `#version 300 es
precision highp float; precision highp int; precision highp sampler3D; precision highp sampler2D;
const float PI = 3.14159265358979;
vec3 srgb(vec3 x) { x = clamp(x, 0.0, 1.0);
  return mix(1.055 * pow(x, vec3(1.0 / 2.4)) - 0.055, 12.92 * x, vec3(lessThanEqual(x, vec3(0.0031308)))); }
// Rusinkiewicz angles (polyjax.data._merl.directions_to_rusinkiewicz), continuous MERL indices, trilinear look-up
vec3 merl_lookup(sampler3D t, vec3 n, vec3 u, vec3 v, float period) {
  if (u.z <= 0.0 || v.z <= 0.0) return vec3(0.0);
  u = normalize(u); v = normalize(v);
  vec3 h = normalize(u + v);
  float th = atan(length(h.xy), h.z), ph = atan(h.y, h.x);
  float cp = cos(ph), sp = sin(ph), ct = cos(th), st = sin(th);
  float x = cp * u.x + sp * u.y, y = -sp * u.x + cp * u.y, z = u.z;
  float dx = x * ct - z * st, dz = x * st + z * ct;
  // y == 0.0 holds for -0.0 too: +0.0 then, so that a pair in the plane of incidence turned by pi reads pi, not
  // -pi (which a table over the whole turn would put at 0)
  float td = atan(length(vec2(dx, y)), dz), pd = atan(y == 0.0 ? 0.0 : y, dx);
  if (pd < 0.0) pd += period;  // PI: folded by reciprocity; 2 PI: a table over the whole turn
  vec3 idx = vec3(pd / period * n.z, td / (0.5 * PI) * n.y, sqrt(max(th, 0.0) / (0.5 * PI)) * n.x);
  return texture(t, (idx + 0.5) / vec3(n.z, n.y, n.x)).rgb;
}
`;

  const SPHERE = `
uniform vec2 res; uniform vec3 eye, camW, camR, camU, lightPos, lightI; uniform float halfH, exposure, gain;
uniform int itemA, itemB, mode, envOn; uniform sampler2D envTex;
out vec4 color;
// the environment map by the midpoint rule over its texels (polyjax.view._environment): sum L f cos+ dW
vec3 envTerm(int k, vec3 n, vec3 tx, vec3 bx, vec3 vl) {
  ivec2 sz = textureSize(envTex, 0); vec3 acc = vec3(0.0);
  for (int i = 0; i < sz.y; i++) {
    float th = (float(i) + 0.5) * PI / float(sz.y), st = sin(th), ct = cos(th);
    float dw = st * (PI / float(sz.y)) * (2.0 * PI / float(sz.x));
    for (int j = 0; j < sz.x; j++) {
      float ph = (float(j) + 0.5) * 2.0 * PI / float(sz.x) - PI;
      vec3 d = vec3(st * sin(ph), ct, -st * cos(ph)); float c = dot(n, d);
      if (c <= 0.0) continue;
      acc += max(brdf(k, vec3(dot(d, tx), dot(d, bx), c), vl), 0.0) * texelFetch(envTex, ivec2(j, i), 0).rgb * (c * dw);
    }
  }
  return acc;
}
vec3 envRadiance(vec3 d) {  // EnvironmentLight.radiance: the texel the direction falls in
  ivec2 sz = textureSize(envTex, 0);
  float th = acos(clamp(d.y, -1.0, 1.0)), ph = atan(d.x, -d.z);
  int i = clamp(int(floor(th / PI * float(sz.y))), 0, sz.y - 1), j = clamp(int(floor((ph + PI) / (2.0 * PI) * float(sz.x))), 0, sz.x - 1);
  return texelFetch(envTex, ivec2(j, i), 0).rgb;
}
void main() {
  float X = (2.0 * gl_FragCoord.x / res.x - 1.0) * (res.x / res.y), Y = 2.0 * gl_FragCoord.y / res.y - 1.0;
  vec3 d = normalize(camW + halfH * (X * camR + Y * camU)), o = eye;
  float b = dot(o, d), c = dot(o, o) - 1.0, disc = b * b - c;
  float sq = sqrt(max(disc, 0.0)), t = -b - sq;
  if (!(t > 0.0)) t = -b + sq;
  if (disc < 0.0 || !(t > 0.0)) {
    vec3 bg = envOn == 1 && mode == 0 ? envRadiance(d) : vec3(0.0);
    color = vec4(srgb(bg * exp2(exposure)), 1.0); return; }
  vec3 n = o + t * d;
  vec3 tx = vec3(n.z, 0.0, -n.x); float tl = length(tx);
  tx = tl > 1e-6 ? tx / tl : vec3(1.0, 0.0, 0.0);
  vec3 bx = cross(n, tx);
  vec3 delta = lightPos - n; float d2 = dot(delta, delta); vec3 l = delta / sqrt(d2);
  vec3 w = lightI * (max(dot(n, l), 0.0) / d2);
  vec3 ul = vec3(dot(l, tx), dot(l, bx), dot(l, n)), vl = vec3(dot(-d, tx), dot(-d, bx), dot(-d, n));
  vec3 ra = max(brdf(itemA, ul, vl), 0.0) * w;
  if (envOn == 1) ra += envTerm(itemA, n, tx, bx, vl);
  vec3 x = ra;
  if (mode == 1) {
    vec3 rb = max(brdf(itemB, ul, vl), 0.0) * w;
    if (envOn == 1) rb += envTerm(itemB, n, tx, bx, vl);
    x = abs(ra - rb) * gain;
  }
  color = vec4(srgb(x * exp2(exposure)), 1.0);
}`;

  const SLICE = `
uniform vec2 res; uniform float exposure, gain; uniform int itemA, itemB, mode;
out vec4 color;
void main() {
  float th = gl_FragCoord.x / res.x * 0.5 * PI, td = gl_FragCoord.y / res.y * 0.5 * PI;
  vec3 dd = vec3(0.0, sin(td), cos(td));  // phi_d = 90 degrees
  float c = cos(th), s = sin(th);
  vec3 u = vec3(dd.x * c + dd.z * s, dd.y, dd.z * c - dd.x * s), v = vec3(-dd.x * c + dd.z * s, -dd.y, dd.z * c + dd.x * s);
  vec3 fa = max(brdf(itemA, u, v), 0.0), x = fa;
  if (mode == 1) x = abs(fa - max(brdf(itemB, u, v), 0.0)) * gain;
  x = x * exp2(exposure);
  color = vec4(srgb(x / (1.0 + x)), 1.0);
}`;

  const EVAL = `
uniform sampler2D uTex, vTex; uniform int item;
out vec4 color;
void main() { ivec2 p = ivec2(gl_FragCoord.xy);
  color = vec4(brdf(item, texelFetch(uTex, p, 0).xyz, texelFetch(vTex, p, 0).xyz), 1.0); }`;

  function compile(src, kind) {
    const sh = gl.createShader(kind);
    gl.shaderSource(sh, src);
    gl.compileShader(sh);
    if (!gl.getShaderParameter(sh, gl.COMPILE_STATUS)) throw new Error("shader: " + gl.getShaderInfoLog(sh));
    return sh;
  }
  function program(body) {
    const p = gl.createProgram();
    gl.attachShader(p, compile(VERT, gl.VERTEX_SHADER));
    gl.attachShader(p, compile(PRELUDE + BRDFS + body, gl.FRAGMENT_SHADER));
    gl.linkProgram(p);
    if (!gl.getProgramParameter(p, gl.LINK_STATUS)) throw new Error("program: " + gl.getProgramInfoLog(p));
    return p;
  }

  function bytes(b64) {
    const s = atob(b64), out = new Uint8Array(s.length);
    for (let i = 0; i < s.length; i++) out[i] = s.charCodeAt(i);
    return out.buffer;
  }

  const tables = [];  // [item index, texture]
  function uploadTables() {
    ITEMS.forEach((it, i) => {
      if (it.kind !== "table") return;
      const [nh, nd, np] = it.resolution, tex = gl.createTexture();
      gl.activeTexture(gl.TEXTURE0 + 2 + tables.length);
      gl.bindTexture(gl.TEXTURE_3D, tex);
      gl.pixelStorei(gl.UNPACK_ALIGNMENT, 1);
      gl.texImage3D(gl.TEXTURE_3D, 0, gl.RGB16F, np, nd, nh, 0, gl.RGB, gl.HALF_FLOAT, new Uint16Array(bytes(it.table)));
      gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MIN_FILTER, gl.LINEAR);
      gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_MAG_FILTER, gl.LINEAR);
      gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_WRAP_S, gl.REPEAT);  // phi_d: periodic (pi, or 2 pi for a table over the whole turn)
      gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_WRAP_T, gl.CLAMP_TO_EDGE);
      gl.texParameteri(gl.TEXTURE_3D, gl.TEXTURE_WRAP_R, gl.CLAMP_TO_EDGE);
      tables.push([i, 2 + tables.length]);
    });
  }

  const ENV_UNIT = 14, INT_UNIFORMS = new Set(["itemA", "itemB", "mode", "envOn", "item", "uTex", "vTex"]);
  function uploadEnvironment() {
    const env = DATA.environment, tex = gl.createTexture();
    gl.activeTexture(gl.TEXTURE0 + ENV_UNIT);
    gl.bindTexture(gl.TEXTURE_2D, tex);
    const w = env ? env.width : 1, h = env ? env.height : 1, rgba = new Float32Array(4 * w * h);
    if (env) { const rgb = new Float32Array(bytes(env.texels));
      for (let i = 0; i < w * h; i++) rgba.set([rgb[3 * i], rgb[3 * i + 1], rgb[3 * i + 2], 1], 4 * i); }
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, w, h, 0, gl.RGBA, gl.FLOAT, rgba);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
    gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST);
  }

  function use(p, uniforms) {
    gl.useProgram(p);
    for (const [i, unit] of tables) {
      const loc = gl.getUniformLocation(p, "table_" + i);
      if (loc) gl.uniform1i(loc, unit);
    }
    const envLoc = gl.getUniformLocation(p, "envTex");
    if (envLoc) gl.uniform1i(envLoc, ENV_UNIT);
    for (const [name, val] of Object.entries(uniforms)) {
      const loc = gl.getUniformLocation(p, name);
      if (loc === null) continue;
      if (INT_UNIFORMS.has(name)) gl.uniform1i(loc, val);
      else if (typeof val === "number") gl.uniform1f(loc, val);
      else if (val.length === 2) gl.uniform2fv(loc, val);
      else gl.uniform3fv(loc, val);
    }
  }

  // a canvas of w x h pixels; its figure as wide as it (captions wrap under it), both shrinking with the window
  function sized(c, w, h) {
    c.width = w; c.height = h;
    if (c.parentElement.tagName === "FIGURE") c.parentElement.style.width = w + "px";
    return c;
  }

  function drawTo(canvasId, p, uniforms, w, h) {
    glCanvas.width = w; glCanvas.height = h;
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    gl.viewport(0, 0, w, h);
    use(p, Object.assign({ res: [w, h] }, uniforms));
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    sized($(canvasId), w, h).getContext("2d").drawImage(glCanvas, 0, 0);
  }

  // evaluate item k at n direction pairs on the GPU (float render target); returns Float32Array (n, 4)
  function evaluate(k, us, vs) {
    const n = us.length / 3, W = Math.min(n, 1024), H = Math.ceil(n / W);
    const pack = (a) => { const t = new Float32Array(W * H * 4);
      for (let i = 0; i < W * H; i++) { const j = i < n ? i : -1;
        t[4 * i] = j < 0 ? 0 : a[3 * j]; t[4 * i + 1] = j < 0 ? 0 : a[3 * j + 1]; t[4 * i + 2] = j < 0 ? 1 : a[3 * j + 2]; }
      return t; };
    const tex = (unit, a) => { const t = gl.createTexture(); gl.activeTexture(gl.TEXTURE0 + unit);
      gl.bindTexture(gl.TEXTURE_2D, t);
      gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, W, H, 0, gl.RGBA, gl.FLOAT, pack(a));
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MIN_FILTER, gl.NEAREST);
      gl.texParameteri(gl.TEXTURE_2D, gl.TEXTURE_MAG_FILTER, gl.NEAREST); return t; };
    const tu = tex(0, us), tv = tex(1, vs);
    const out = gl.createTexture();
    gl.activeTexture(gl.TEXTURE0 + 15);
    gl.bindTexture(gl.TEXTURE_2D, out);
    gl.texImage2D(gl.TEXTURE_2D, 0, gl.RGBA32F, W, H, 0, gl.RGBA, gl.FLOAT, null);
    const fb = gl.createFramebuffer();
    gl.bindFramebuffer(gl.FRAMEBUFFER, fb);
    gl.framebufferTexture2D(gl.FRAMEBUFFER, gl.COLOR_ATTACHMENT0, gl.TEXTURE_2D, out, 0);
    gl.viewport(0, 0, W, H);
    use(progs.evaluate, { uTex: 0, vTex: 1, item: k });
    gl.drawArrays(gl.TRIANGLES, 0, 3);
    const px = new Float32Array(W * H * 4);
    gl.readPixels(0, 0, W, H, gl.RGBA, gl.FLOAT, px);
    gl.bindFramebuffer(gl.FRAMEBUFFER, null);
    [tu, tv, out].forEach((t) => gl.deleteTexture(t));
    gl.deleteFramebuffer(fb);
    return px.subarray(0, 4 * n);
  }

  // ------------------------------------------------------------------ state and controls
  const L0 = S.light, R = Math.hypot(L0[0], L0[1], L0[2]);
  const init = { azimuth: Math.atan2(L0[0], L0[2]) / DEG, elevation: Math.asin(L0[1] / R) / DEG };
  const state = view.state = { azimuth: init.azimuth, elevation: init.elevation, radius: R, exposure: S.exposure,
                               gain: 4, incidence: 45, itemA: 0, itemB: -1, light: null, photoLight: 0,
                               environment: !!DATA.environment };
  const isFn = (k) => k >= 0 && ITEMS[k].kind !== "points";

  function lightPosition() {
    const a = state.azimuth * DEG, e = state.elevation * DEG;
    return [R * Math.cos(e) * Math.sin(a), R * Math.sin(e), R * Math.cos(e) * Math.cos(a)];
  }
  function moveLight(dAz, dEl) {
    state.azimuth = ((state.azimuth + dAz + 540) % 360) - 180;
    state.elevation = Math.max(-89, Math.min(89, state.elevation + dEl));
    schedule();
  }

  function setupControls() {
    const A = $("itemA"), B = $("itemB");
    ITEMS.forEach((it, i) => { A.add(new Option(`${i}: ${it.name}`, i)); B.add(new Option(`${i}: ${it.name}`, i)); });
    B.add(new Option("none", -1), 0);
    state.itemB = ITEMS.length > 1 ? 1 : -1;
    B.value = String(state.itemB);
    A.addEventListener("change", () => { state.itemA = +A.value; schedule(true); });
    B.addEventListener("change", () => { state.itemB = +B.value; schedule(true); });
    const range = (id, key, fmt, plots) => { const el = $(id); el.value = String(key === "gain" ? Math.log2(state.gain) : state[key]);
      const out = () => { const x = +el.value; state[key] = key === "gain" ? 2 ** x : x; $(id + "Out").textContent = fmt(state[key]); };
      out(); el.addEventListener("input", () => { out(); schedule(plots); }); };
    range("exposure", "exposure", (x) => x.toFixed(2), false);
    range("errorGain", "gain", (x) => String(x), false);
    range("incidence", "incidence", (x) => String(x), true);
    const env = $("environment");
    env.checked = state.environment; env.parentElement.hidden = !DATA.environment;
    env.addEventListener("change", () => { state.environment = env.checked; schedule(); });
    $("photoLight").addEventListener("input", () => schedule());
    $("resetLight").addEventListener("click", () => { state.azimuth = init.azimuth; state.elevation = init.elevation; schedule(); });
    let drag = null;
    ["sphereA", "sphereB", "sphereErr"].forEach((id) => {
      const c = $(id);
      c.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; c.focus(); e.preventDefault(); });
      c.addEventListener("keydown", (e) => {
        const step = e.shiftKey ? 1 : 5;
        const moves = { ArrowLeft: [-step, 0], ArrowRight: [step, 0], ArrowUp: [0, step], ArrowDown: [0, -step] };
        if (moves[e.key]) { moveLight(...moves[e.key]); e.preventDefault(); }
      });
    });
    // a drag of one pixel turns the light by half a degree: right = +azimuth, up = +elevation
    window.addEventListener("mousemove", (e) => { if (!drag) return;
      moveLight(0.5 * (e.clientX - drag[0]), -0.5 * (e.clientY - drag[1])); drag = [e.clientX, e.clientY]; });
    window.addEventListener("mouseup", () => { drag = null; });
  }

  // ------------------------------------------------------------------ views
  let progs = null, pending = false, plotsDirty = true;
  function schedule(plots) { plotsDirty = plotsDirty || !!plots; if (!pending) { pending = true; requestAnimationFrame(redraw); } }

  function camera() {
    const sub = (a, b) => a.map((x, i) => x - b[i]), norm = (a) => { const l = Math.hypot(...a); return a.map((x) => x / l); };
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const w = norm(sub(S.target, S.eye)), r = norm(cross(w, S.up));
    return { eye: S.eye, camW: w, camR: r, camU: cross(r, w), halfH: Math.tan(0.5 * S.fov_deg * DEG) };
  }

  function drawSpheres() {
    const n = S.size, light = lightPosition();
    state.light = { position: light, intensity: [S.intensity, S.intensity, S.intensity] };
    const common = Object.assign(camera(), { lightPos: light, lightI: state.light.intensity, exposure: state.exposure,
                                             envOn: state.environment ? 1 : 0,
                                             gain: state.gain, itemA: Math.max(state.itemA, 0), itemB: Math.max(state.itemB, 0) });
    const both = isFn(state.itemA) && isFn(state.itemB) && state.itemB !== state.itemA;
    if (isFn(state.itemA)) drawTo("sphereA", progs.sphere, Object.assign({}, common, { mode: 0 }), n, n);
    if (isFn(state.itemB)) drawTo("sphereB", progs.sphere, Object.assign({}, common, { mode: 0, itemA: state.itemB }), n, n);
    if (both) drawTo("sphereErr", progs.sphere, Object.assign({}, common, { mode: 1 }), n, n);
    if (isFn(state.itemA)) drawTo("sliceA", progs.slice, Object.assign({}, common, { mode: 0 }), n, n);
    if (both) drawTo("sliceErr", progs.slice, Object.assign({}, common, { mode: 1 }), n, n);
    document.querySelectorAll(".needsB").forEach((el) => { el.hidden = !both; });
    $("sphereB").parentElement.hidden = !isFn(state.itemB) || state.itemB === state.itemA;
    $("sphereACap").textContent = isFn(state.itemA) ? "A: " + ITEMS[state.itemA].name : "";
    $("sphereBCap").textContent = isFn(state.itemB) ? "B: " + ITEMS[state.itemB].name : "";
    $("sphereView").hidden = $("polarView").hidden = !isFn(state.itemA);
    $("lightOut").textContent = `light azimuth ${state.azimuth.toFixed(1)}\u00b0, elevation ${state.elevation.toFixed(1)}\u00b0`;
  }

  function polarData(k) {
    // the plane of incidence xz: light at azimuth 180 degrees, view theta_o in [-90, 90] (positive: specular side)
    const ti = state.incidence * DEG, m = 91, us = new Float32Array(3 * m), vs = new Float32Array(3 * m), th = [];
    for (let i = 0; i < m; i++) {
      const t = (-90 + 2 * i) * DEG; th.push(-90 + 2 * i);
      us.set([-Math.sin(ti), 0, Math.cos(ti)], 3 * i); vs.set([Math.sin(t), 0, Math.cos(t)], 3 * i);
    }
    const f = evaluate(k, us, vs), values = [];
    for (let i = 0; i < m; i++) values.push([f[4 * i], f[4 * i + 1], f[4 * i + 2]]);
    return { item: k, theta_in_deg: state.incidence, theta_out_deg: th, u: Array.from(us), v: Array.from(vs), values };
  }

  function albedoData(k) {
    // a(theta_v) = int f cos dw_u = pi / (Ns Nphi) sum f over midpoints of s = cos^2 theta_u and phi
    const nv = 16, ns = 16, nphi = 32, n = nv * ns * nphi, us = new Float32Array(3 * n), vs = new Float32Array(3 * n), th = [];
    let q = 0;
    for (let i = 0; i < nv; i++) { const tv = (i + 0.5) / nv * 90 * DEG; th.push((i + 0.5) / nv * 90);
      for (let j = 0; j < ns; j++) { const c = Math.sqrt((j + 0.5) / ns), s = Math.sqrt(1 - c * c);
        for (let l = 0; l < nphi; l++, q++) { const p = (l + 0.5) / nphi * 2 * Math.PI;
          us.set([s * Math.cos(p), s * Math.sin(p), c], 3 * q); vs.set([Math.sin(tv), 0, Math.cos(tv)], 3 * q); } } }
    const f = evaluate(k, us, vs), values = [];
    for (let i = 0; i < nv; i++) { const a = [0, 0, 0];
      for (let j = 0; j < ns * nphi; j++) for (let c = 0; c < 3; c++) a[c] += f[4 * (i * ns * nphi + j) + c];
      values.push(a.map((x) => x * Math.PI / (ns * nphi))); }
    return { item: k, theta_v_deg: th, values };
  }

  function plotAxes(ctx, w, h) { ctx.fillStyle = "#000"; ctx.fillRect(0, 0, w, h); ctx.strokeStyle = "#555"; ctx.lineWidth = 1; }
  const COLOURS = ["#f55", "#5d5", "#58f"];

  function drawPolar(curves) {
    const n = S.size, c = sized($("polar"), n, n), ctx = c.getContext("2d");
    plotAxes(ctx, n, n);
    const cx = n / 2, cy = n - 8, R0 = n / 2 - 10;
    ctx.beginPath(); ctx.arc(cx, cy, R0, Math.PI, 2 * Math.PI); ctx.moveTo(cx - R0, cy); ctx.lineTo(cx + R0, cy); ctx.stroke();
    const ti = state.incidence * DEG;
    ctx.strokeStyle = "#aa8"; ctx.beginPath(); ctx.moveTo(cx, cy); ctx.lineTo(cx - R0 * Math.sin(ti), cy - R0 * Math.cos(ti)); ctx.stroke();
    let fmax = 1e-12;
    curves.forEach((d) => d.values.forEach((v) => { fmax = Math.max(fmax, ...v.filter(Number.isFinite)); }));
    curves.forEach((d, j) => {
      ctx.setLineDash(j ? [4, 3] : []);
      for (let ch = 0; ch < 3; ch++) { ctx.strokeStyle = COLOURS[ch]; ctx.beginPath();
        d.theta_out_deg.forEach((t, i) => { const r = R0 * Math.max(d.values[i][ch], 0) / fmax;
          const x = cx + r * Math.sin(t * DEG), y = cy - r * Math.cos(t * DEG); i ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
        ctx.stroke(); }
    });
    ctx.setLineDash([]); ctx.fillStyle = "#ccc"; ctx.font = "11px sans-serif"; ctx.fillText(`max ${fmax.toPrecision(3)} 1/sr`, 4, 12);
  }

  function drawCurves(id, curves, xkey, xmax, label) {
    const n = S.size, c = sized($(id), n, n), ctx = c.getContext("2d");
    plotAxes(ctx, n, n);
    const x0 = 24, y0 = n - 16, W = n - x0 - 6, H = n - 30;
    let ymax = 1e-12;
    curves.forEach((d) => d.values.forEach((v) => { ymax = Math.max(ymax, ...v.filter(Number.isFinite)); }));
    ctx.strokeRect(x0, y0 - H, W, H);
    curves.forEach((d, j) => { ctx.setLineDash(j ? [4, 3] : []);
      for (let ch = 0; ch < 3; ch++) { ctx.strokeStyle = COLOURS[ch]; ctx.beginPath();
        d[xkey].forEach((t, i) => { const x = x0 + W * t / xmax, y = y0 - H * d.values[i][ch] / ymax; i ? ctx.lineTo(x, y) : ctx.moveTo(x, y); });
        ctx.stroke(); } });
    ctx.setLineDash([]); ctx.fillStyle = "#ccc"; ctx.font = "11px sans-serif";
    ctx.fillText(`${label}, max ${ymax.toPrecision(3)}`, x0 + 2, 12); ctx.fillText("0", x0 - 8, y0 + 12); ctx.fillText(`${xmax}\u00b0`, n - 26, y0 + 12);
  }

  function drawPoints(kData, kFit) {
    const it = ITEMS[kData], n = it.n;
    const u = new Float32Array(bytes(it.u)), v = new Float32Array(bytes(it.v)), meas = new Float32Array(bytes(it.values));
    const fit = isFn(kFit) ? evaluate(kFit, u, v) : null;
    const th = [], lum = (a, i, s) => (a[s * i] + a[s * i + 1] + a[s * i + 2]) / 3;
    let ymin = Infinity, ymax = -Infinity, se = 0, sm = 0;
    for (let i = 0; i < n; i++) {
      const h = [u[3 * i] + v[3 * i], u[3 * i + 1] + v[3 * i + 1], u[3 * i + 2] + v[3 * i + 2]];
      th.push(Math.atan2(Math.hypot(h[0], h[1]), h[2]) / DEG);
      for (const y of [lum(meas, i, 3)].concat(fit ? [lum(fit, i, 4)] : [])) if (y > 0) { ymin = Math.min(ymin, Math.log10(y)); ymax = Math.max(ymax, Math.log10(y)); }
      if (fit) { for (let ch = 0; ch < 3; ch++) { se += (fit[4 * i + ch] - meas[3 * i + ch]) ** 2; sm += meas[3 * i + ch] ** 2; } }
    }
    if (!(ymax > ymin)) { ymin = -3; ymax = 1; }
    const w = 2 * S.size, hgt = S.size, c = sized($("points"), w, hgt), ctx = c.getContext("2d");
    plotAxes(ctx, w, hgt);
    const X = (t) => 30 + (w - 40) * t / 90, Y = (y) => hgt - 16 - (hgt - 30) * (Math.log10(Math.max(y, 1e-30)) - ymin) / (ymax - ymin);
    for (let i = 0; i < n; i++) {
      ctx.fillStyle = "#ddd"; ctx.fillRect(X(th[i]) - 1.5, Y(lum(meas, i, 3)) - 1.5, 3, 3);
      if (fit) { ctx.strokeStyle = "#f0a040"; const x = X(th[i]), y = Y(lum(fit, i, 4)); ctx.beginPath();
        ctx.moveTo(x - 3, y - 3); ctx.lineTo(x + 3, y + 3); ctx.moveTo(x - 3, y + 3); ctx.lineTo(x + 3, y - 3); ctx.stroke(); }
    }
    ctx.fillStyle = "#ccc"; ctx.font = "11px sans-serif";
    ctx.fillText(`log10 f: ${ymin.toFixed(2)} .. ${ymax.toFixed(2)} against theta_h 0..90\u00b0`, 34, 12);
    const rel = fit ? Math.sqrt(se / Math.max(sm, 1e-300)) : null;
    view.points = { item: kData, fit: fit ? kFit : null, n, theta_h_deg: th, relative_rms: rel };
    $("pointsOut").textContent = fit ? `${ITEMS[kFit].name} at the ${n} samples of ${it.name}: relative RMS error ${rel.toPrecision(4)}` :
      `${n} samples of ${it.name}`;
  }

  function info(id, k) {
    const el = $(id); el.textContent = "";
    if (k < 0) return;
    const t = document.createElement("table"); t.className = "info";
    const row = (a, b) => { const r = t.insertRow(); r.insertCell().textContent = a; r.insertCell().textContent = b; };
    row("item", `${k}: ${ITEMS[k].name}`);
    for (const [key, val] of Object.entries(ITEMS[k].info)) row(key, typeof val === "string" ? val : JSON.stringify(val));
    el.appendChild(t);
  }

  function drawPlots() {
    const a = state.itemA, b = state.itemB, curves = [], alb = [];
    if (isFn(a) && floatTargets) { curves.push(polarData(a)); alb.push(albedoData(a)); }
    if (isFn(b) && b !== a && floatTargets) { curves.push(polarData(b)); alb.push(albedoData(b)); }
    view.polar = curves; view.albedo = alb;
    if (curves.length) { drawPolar(curves); drawCurves("albedo", alb, "theta_v_deg", 90, "albedo"); }
    const pts = ITEMS[a].kind === "points" ? [a, b] : (b >= 0 && ITEMS[b].kind === "points" ? [b, a] : null);
    $("pointsView").hidden = !pts;
    view.points = null;
    if (pts) drawPoints(pts[0], pts[1]);
    info("infoA", a); info("infoB", b === a ? -1 : b);
  }

  let photos = null;
  function drawPhotos() {  // a capture as A or B: its photographs, relit by the other item when that is a function
    const a = state.itemA, b = state.itemB, cap = ITEMS[a].capture ? a : (b >= 0 && ITEMS[b].capture ? b : -1);
    $("photoView").hidden = cap < 0;
    view.photos = cap < 0 ? null : photos.draw(cap, floatTargets ? (cap === a ? b : a) : -1);
  }

  function redraw() {
    pending = false;
    try {
      drawSpheres();
      if (plotsDirty) { drawPlots(); plotsDirty = false; }
      drawPhotos();
      view.frame += 1;
      view.ready = true;
    } catch (e) {
      fail("polyjax view: " + e.message);
    }
  }

  try {
    uploadTables();
    uploadEnvironment();
    progs = { sphere: program(SPHERE), slice: program(SLICE), evaluate: program(EVAL) };
    photos = polyjaxPhotos({ ITEMS, S, state, evaluate, bytes, $ });
    // item k at directions u, v (flat arrays of 3n numbers) on the GPU, as the views evaluate it: (n, 3) values
    view.evaluate = (k, u, v) => { const f = evaluate(k, Float32Array.from(u), Float32Array.from(v)), out = [];
      for (let i = 0; i < f.length / 4; i++) out.push([f[4 * i], f[4 * i + 1], f[4 * i + 2]]);
      return out; };
    if (!floatTargets) fail("This browser's WebGL2 cannot render to float textures (EXT_color_buffer_float): the plots are off.");
    setupControls();
    $("textView").hidden = !$("text").textContent.trim();
    window.addEventListener("resize", () => schedule());
    schedule(true);
  } catch (e) {
    fail("polyjax view: " + e.message);
  }
})();
