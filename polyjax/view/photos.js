// polyjax view, photographs of a capture (polyjax/view/_capture.py): the photograph under one light, the other
// item relit under it as polyjax.relight renders it (E max(0, n.d) max(f(u, v), 0) in the normal map's frame,
// view (0, 0, 1)), |relit - photograph| x gain, and the relative RMS of every light as `polyjax relight` prints it
// (mask, saturated pixels left out). Read by viewer.js: polyjaxPhotos(api) -> { draw(kCap, kFit) }.
"use strict";
function polyjaxPhotos(api) {
  const { ITEMS, state, evaluate, bytes, $ } = api;
  const cache = new Map();  // "kCap:kFit" -> { predicted: Float32Array (L, P, 3), rows }
  const decoded = new Map();  // kCap -> the capture's arrays

  function arrays(k) {
    if (!decoded.has(k)) {
      const c = ITEMS[k].capture;
      decoded.set(k, { c, index: new Int32Array(bytes(c.index)), normals: new Float32Array(bytes(c.normals)),
                       images: new Float32Array(bytes(c.images)) });
    }
    return decoded.get(k);
  }

  // the light and view of pixel p under light l in the normal map's frame (polyjax.render: t = (0,1,0) x n)
  function directions(a) {
    const P = a.c.pixels, L = a.c.light_directions.length, us = new Float32Array(3 * P * L), vs = new Float32Array(3 * P * L);
    const cos = new Float64Array(P * L);
    for (let p = 0; p < P; p++) {
      const n = [a.normals[3 * p], a.normals[3 * p + 1], a.normals[3 * p + 2]];
      let t = [n[2], 0, -n[0]]; const tl = Math.hypot(t[0], t[1], t[2]);
      t = tl > 1e-6 ? t.map((x) => x / tl) : [1, 0, 0];
      const b = [n[1] * t[2] - n[2] * t[1], n[2] * t[0] - n[0] * t[2], n[0] * t[1] - n[1] * t[0]];
      for (let l = 0; l < L; l++) {
        const d = a.c.light_directions[l], q = l * P + p, dot = (x) => d[0] * x[0] + d[1] * x[1] + d[2] * x[2];
        us.set([dot(t), dot(b), dot(n)], 3 * q); vs.set([t[2], b[2], n[2]], 3 * q);
        cos[q] = Math.max(dot(n), 0);
      }
    }
    return { us, vs, cos };
  }

  function errors(a, pred) {  // per light: relative RMS and PSNR (peak: the saturation); all lights together
    const P = a.c.pixels, L = a.c.light_directions.length, sat = a.c.saturation, rows = [];
    let d2all = 0, r2all = 0;
    for (let l = 0; l < L; l++) {
      let d2 = 0, r2 = 0, k = 0;
      for (let p = 0; p < P; p++) {
        const o = 3 * (l * P + p), img = a.images;
        if (!(img[o] < sat && img[o + 1] < sat && img[o + 2] < sat)) continue;
        for (let ch = 0; ch < 3; ch++) { d2 += (pred[o + ch] - img[o + ch]) ** 2; r2 += img[o + ch] ** 2; }
        k += 1;
      }
      const mse = d2 / Math.max(3 * k, 1);
      rows.push([r2 > 0 ? Math.sqrt(d2 / r2) : Infinity, mse > 0 ? 10 * Math.log10(sat * sat / mse) : Infinity]);
      d2all += d2; r2all += r2;
    }
    return { rows, all: Math.sqrt(d2all / r2all) };
  }

  function relit(kCap, kFit) {
    const key = `${kCap}:${kFit}`;
    if (!cache.has(key)) {
      const a = arrays(kCap), P = a.c.pixels, E = a.c.light_intensities, dir = directions(a);
      const f = evaluate(kFit, dir.us, dir.vs), pred = new Float32Array(3 * dir.cos.length);
      for (let q = 0; q < dir.cos.length; q++) {
        const e = E[Math.floor(q / P)];
        for (let ch = 0; ch < 3; ch++) pred[3 * q + ch] = e[ch] * dir.cos[q] * Math.max(f[4 * q + ch], 0);
      }
      cache.set(key, { predicted: pred, err: errors(a, pred) });
    }
    return cache.get(key);
  }

  const srgb = (x) => { x = Math.min(Math.max(x, 0), 1); return x <= 0.0031308 ? 12.92 * x : 1.055 * x ** (1 / 2.4) - 0.055; };
  function paint(id, a, l, value) {  // value(o, ch) at the masked pixels, 2^exposure, clipped, sRGB, 8 bits
    const w = a.c.width, h = a.c.height, c = $(id), scale = Math.max(1, Math.floor(api.S.size / Math.max(w, h)));
    c.width = w; c.height = h; c.style.width = w * scale + "px";
    c.parentElement.style.width = w * scale + "px";
    const ctx = c.getContext("2d"), im = ctx.createImageData(w, h), g = 2 ** state.exposure, P = a.c.pixels;
    for (let i = 0; i < w * h; i++) im.data[4 * i + 3] = 255;
    for (let p = 0; p < P; p++) {
      const o = 3 * (l * P + p), px = 4 * a.index[p];
      for (let ch = 0; ch < 3; ch++) im.data[px + ch] = Math.round(255 * srgb(g * value(o, ch)));
    }
    ctx.putImageData(im, 0, 0);
  }

  function draw(kCap, kFit) {
    const a = arrays(kCap), L = a.c.light_directions.length, slider = $("photoLight");
    slider.max = String(L - 1);
    const l = state.photoLight = Math.min(Math.max(Math.round(+slider.value), 0), L - 1);
    $("photoLightOut").textContent = `${l + 1} of ${L}: ${a.c.names[l]}`;
    paint("photo", a, l, (o, ch) => a.images[o + ch]);
    $("photoCap").textContent = `photograph ${a.c.names[l]} of ${ITEMS[kCap].name}`;
    const fit = kFit >= 0 && ITEMS[kFit].kind !== "points" ? relit(kCap, kFit) : null;
    document.querySelectorAll(".needsFit").forEach((el) => { el.hidden = !fit; });
    const P = a.c.pixels, out = { item: kCap, fit: fit ? kFit : null, light: l, n_lights: L, width: a.c.width,
                                  height: a.c.height, pixels: P };
    if (fit) {
      paint("photoFit", a, l, (o, ch) => fit.predicted[o + ch]);
      paint("photoErr", a, l, (o, ch) => state.gain * Math.abs(fit.predicted[o + ch] - a.images[o + ch]));
      $("photoFitCap").textContent = `${ITEMS[kFit].name} relit`;
      Object.assign(out, { predicted: Array.from(fit.predicted.subarray(3 * l * P, 3 * (l + 1) * P)),
                           relative_rms: fit.err.rows.map((r) => r[0]), psnr_db: fit.err.rows.map((r) => r[1]),
                           relative_rms_all: fit.err.all });
      const [rel, ps] = fit.err.rows[l];
      $("photoOut").textContent = `${ITEMS[kFit].name} against the photographs (mask, saturated pixels left out): ` +
        `relative RMS ${rel.toPrecision(4)}, PSNR ${ps.toFixed(2)} dB under this light; relative RMS ` +
        `${fit.err.all.toPrecision(4)} over the ${L} lights`;
    } else {
      $("photoOut").textContent = `${L} photographs of ${a.c.width} x ${a.c.height} pixels (choose a fit as the other ` +
        "item to relight it)";
    }
    return out;
  }

  return { draw };
}
