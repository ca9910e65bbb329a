"""A capture's ``.glb`` card rendered by Blender under held-out lights, beside the photographs (DiLiGenT, 8-bit).

Claim: the card that ``polyjax export FIT --to gltf`` writes of a capture fit (``polyjax.export.gltf_card``: the
image plane as a quad, an orthographic camera, glTF metallic-roughness textures fitted to the fit's BRDF maps)
reproduces, once imported and rendered by Blender (3.4, Cycles, ``benchmarks/blender/render_card.py``) under a sun
in the direction of a light the fit has not seen, the photograph under that light. Reported per object and light,
PSNR over the mask's pixels (peak: the photograph's maximum over the mask), for three images against the
photograph and one between two of them:

- ``fit``: the capture fit's own BRDF ``rho_d / pi + sum_k m_k f_k`` on its normals (what the fit predicts);
- ``glTF``: the card's maps through the glTF 2.0 BRDF (``polyjax.export.render_card``, specification appendix B):
  what the projection of the fit onto glTF's model costs;
- ``Blender``: Blender's render of the ``.glb`` (8-bit textures, Principled BSDF: Burley's diffuse);
- ``B-vs-glTF``: Blender's render against ``glTF`` (the renderer's own departure from the specification).

The capture fit: ``--fit capture`` is ``polyjax.fit_capture`` (normals and BRDF from the photographs alone) where
this polyjax has it; ``--fit reference`` (the default where it does not) is made here, on the ground-truth normals
(``Normal_gt.mat``), to the same contract: per pixel an RGB diffuse albedo and the weight of one shared lobe (a
Blinn-Phong microfacet lobe ``(e + 2) / (2 pi) cos^e theta_h / (4 max(cos theta_u, cos theta_v))``, the exponent
``e`` the best of a grid on the fitted lights), least squares (SVD) per pixel over the fitted lights with
``n . l > 0.1`` and no saturated channel; where the weight comes out negative, or fewer than 6 lights are
lit, the weight is 0 and the albedo refitted alone. Fitted on the even-index lights; the held-out
lights are three odd-index ones (the 10th, 50th and 90th percentiles of their elevation). ``bear``: the first 20
images are left out (DiLiGenT's calibration problem). Images strided to at most 128 pixels a side.

Run: ``python benchmarks/bench_capture_gltf.py [--objects cat,pot1,...] [--fit reference|capture]`` (needs
``blender`` and ``POLYJAX_BLENDER_PYTHONPATH``, as ``tests/test_blender.py``); writes ``benchmarks/capture_card.png``
(per object: photograph, fit, glTF, Blender under the median held-out light).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)

import polyjax as pj  # noqa: E402
import polyjax.render as pr  # noqa: E402

HERE = Path(__file__).resolve().parent
OBJECTS = ("cat", "pot1", "bear", "pot2", "goblet")
EXPONENTS = (5.0, 10.0, 20.0, 40.0, 80.0, 160.0, 320.0)
MAX_SIDE, SAMPLES = 128, 4


def blinn_lobe(u, v, e):
    """The shared lobe of the reference fit (module notes) at local directions ``(n, 3)``."""
    h = u + v
    hz = h[..., 2] / jnp.maximum(jnp.linalg.norm(h, axis=-1), 1e-12)
    d = (e + 2.0) / (2.0 * jnp.pi) * jnp.maximum(hz, 0.0) ** e
    return d / (4.0 * jnp.maximum(jnp.maximum(u[..., 2], v[..., 2]), 1e-6))


class ReferenceFit(eqx.Module):
    """A capture fit to the contract of ``polyjax.CaptureFit``, on ground-truth normals (module notes)."""

    normals: jax.Array
    mask: jax.Array
    diffuse: jax.Array
    mix: jax.Array
    exponent: float = eqx.field(static=True)

    def lobes(self, u, v):
        return blinn_lobe(jnp.asarray(u), jnp.asarray(v), self.exponent)[None, :, None] * jnp.ones(3)


def local(n, w):
    """Directions ``w`` (``(3,)`` or ``(P, 3)``) in the frame of unit normals ``n (P, 3)`` (any tangent: the
    lobes are isotropic)."""
    a = np.where(np.abs(n[:, :1]) < 0.9, np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))
    t = np.cross(a, n)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    b = np.cross(n, t)
    w = np.broadcast_to(w, n.shape)
    return np.stack([np.sum(w * t, 1), np.sum(w * b, 1), np.sum(w * n, 1)], 1)


def fit_image(fit, d, e) -> np.ndarray:
    """The fit's image ``(H, W, 3)`` under light ``d`` of irradiance ``e`` (``E max(0, n.l) f``)."""
    m = np.asarray(fit.mask)
    n = np.asarray(fit.normals)[m]
    u, v = local(n, np.asarray(d)), local(n, np.array([0.0, 0.0, 1.0]))
    lobes = np.asarray(fit.lobes(jnp.asarray(u), jnp.asarray(v)))  # (K, P, 3)
    f = np.asarray(fit.diffuse)[m] / np.pi + np.einsum("pk,kpc->pc", np.asarray(fit.mix)[m], lobes)
    out = np.zeros(m.shape + (3,))
    out[m] = np.asarray(e) * np.maximum(u[:, 2:], 0.0) * f
    return out


def _solve(cap, e, idx_ok):
    """Per pixel least squares of ``(rho_r, rho_g, rho_b, m)`` for lobe exponent ``e``: fit and residual."""
    m = np.asarray(cap.mask)
    n = np.asarray(cap.normals)[m]
    images = np.asarray(cap.images)[:, m]  # (L, P, 3)
    dirs, ints = np.asarray(cap.light_directions), np.asarray(cap.light_intensities)
    cos = np.einsum("pc,lc->lp", n, dirs)
    v = local(n, np.array([0.0, 0.0, 1.0]))
    lobe = np.stack([np.asarray(blinn_lobe(jnp.asarray(local(n, d)), jnp.asarray(v), e)) for d in dirs])
    ok = idx_ok & (cos > 0.1) & (images.max(-1) < cap.saturation * 0.99)  # (L, P)
    b = images / ints[:, None, :]  # (L, P, 3)
    a = np.zeros(b.shape + (4,))
    for c in range(3):
        a[..., c, c] = cos / np.pi
    a[..., 3] = (cos * lobe)[..., None]
    w = ok[..., None, None].astype(float)
    a_p = np.moveaxis(a * w, 1, 0).reshape(len(n), -1, 4)
    b_p = np.moveaxis(b * w[..., 0], 1, 0).reshape(len(n), -1)
    x = np.einsum("pij,pj->pi", np.linalg.pinv(a_p), b_p)
    drop = (ok.sum(0) < 6) | (x[:, 3] < 0)  # too few lit lights, or a negative lobe: the albedo alone
    x[drop, 3] = 0.0
    for c in range(3):
        alone = np.sum(a_p[..., c] * b_p, 1) / np.maximum(np.sum(a_p[..., c] ** 2, 1), 1e-300)
        x[drop, c] = alone[drop]
    res = b_p - np.einsum("pij,pj->pi", a_p, x)
    return x, float(np.sum(res * res))


def reference_fit(cap) -> ReferenceFit:
    """The reference fit of the capture ``cap`` (its lights all fitted)."""
    ok = np.ones((cap.n_lights, 1), bool)
    best = min(EXPONENTS, key=lambda e: _solve(cap, e, ok)[1])
    x, _ = _solve(cap, best, ok)
    m = np.asarray(cap.mask)
    diffuse, mix = np.zeros(m.shape + (3,)), np.zeros(m.shape + (1,))
    diffuse[m], mix[m, 0] = np.maximum(x[:, :3], 0.0), x[:, 3]
    return ReferenceFit(cap.normals, cap.mask, jnp.asarray(diffuse), jnp.asarray(mix), best)


def blender(glb: Path, prefix: Path, shape, lights) -> list[np.ndarray]:
    """Blender's renders of the card under ``lights`` ``[(d (3,), E (3,))]``."""
    site = os.environ.get("POLYJAX_BLENDER_PYTHONPATH")
    if not site:
        sys.exit("POLYJAX_BLENDER_PYTHONPATH: expected a folder with numpy < 1.24 for Blender's glTF importer")
    h, w = shape
    args = [str(x) for d, e in lights for x in (*d, *e)]
    cmd = ["blender", "-b", "--factory-startup", "-P", str(HERE / "blender" / "render_card.py"), "--", str(glb),
           str(prefix), str(w), str(h), str(SAMPLES), *args]
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=900, env=dict(os.environ, PYTHONPATH=site))
    if res.returncode != 0:
        sys.exit(res.stdout[-2000:] + res.stderr[-2000:])
    return [np.load(f"{prefix}{i}.exr.npy") for i in range(len(lights))]


def held_out(cap, odd):
    """Three held-out lights: the 10th, 50th, 90th percentiles of elevation among ``odd``."""
    z = np.asarray(cap.light_directions)[odd, 2]
    order = odd[np.argsort(z)]
    return [int(order[int(round(q * (len(order) - 1)))]) for q in (0.1, 0.5, 0.9)]


def _psnr(a, photo, mask):
    return float(pj.psnr(a, photo, peak=float(photo[mask].max()), mask=mask[..., None]))


def run_object(name, fit_kind, tmp: Path):
    """Fit, card, Blender renders and PSNRs of one object; the figure row."""
    cap = pj.data.load_photometric(str(Path(os.environ["POLYJAX_DATA"]) / "diligent" / "crop8" / f"{name}PNG"))
    cap = cap.strided(int(np.ceil(max(np.shape(cap.mask)) / MAX_SIDE)))
    lights = np.arange(20 if name == "bear" else 0, cap.n_lights)
    even, odd = lights[lights % 2 == 0], lights[lights % 2 == 1]
    t0 = time.perf_counter()
    fit = pj.fit_capture(cap.select(even)) if fit_kind == "capture" else reference_fit(cap.select(even))
    t_fit = time.perf_counter() - t0
    t0 = time.perf_counter()
    maps = pj.export.card_maps(fit)
    glb = pj.export.gltf_card(fit, tmp / f"{name}.glb", crop=False, maps=maps)
    t_card = time.perf_counter() - t0
    test = held_out(cap, odd)
    dirs, ints = np.asarray(cap.light_directions), np.asarray(cap.light_intensities)
    t0 = time.perf_counter()
    theirs = blender(glb, tmp / f"{name}_", np.shape(cap.mask), [(dirs[i], ints[i] * maps.scale) for i in test])
    t_blender = time.perf_counter() - t0
    mask = np.asarray(cap.mask)
    rows, fig = [], None
    for j, i in enumerate(test):
        photo = np.asarray(cap.images[i])
        ours, gl = fit_image(fit, dirs[i], ints[i]), pj.export.render_card(maps, dirs[i], ints[i])
        rows.append((i, np.degrees(np.arccos(dirs[i, 2])), _psnr(ours, photo, mask), _psnr(gl, photo, mask),
                     _psnr(theirs[j], photo, mask), _psnr(theirs[j], gl, mask)))
        if j == 1:
            fig = [photo, ours, gl, theirs[j]]
    lobes = maps.lobes
    info = (f"{name}: {mask.shape[1]} x {mask.shape[0]} px, {len(even)} lights fitted, fit {t_fit:.1f} s, card "
            f"{t_card:.1f} s, Blender {t_blender:.1f} s for {len(test)} renders; lobes: GGX roughness "
            f"{np.round(np.asarray(lobes.roughness), 3).tolist()}, relative L2 "
            f"{np.round(np.asarray(lobes.relative_l2), 3).tolist()}; light scale {maps.scale:.3g}"
            + (f"; Blinn-Phong exponent {fit.exponent:g}" if fit_kind == "reference" else ""))
    return info, rows, fig


def _figure(figs, path: Path):
    h = max(f[0].shape[0] for f in figs)
    w = max(f[0].shape[1] for f in figs)
    padded = [[np.pad(im / max(float(f[0].max()), 1e-6), ((0, h - im.shape[0]), (0, w - im.shape[1]), (0, 0)))
               for im in f] for f in figs]
    pr.write_png(path, pr.mosaic(padded))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default=",".join(OBJECTS))
    ap.add_argument("--fit", choices=("reference", "capture"),
                    default="capture" if hasattr(pj, "fit_capture") else "reference")
    ap.add_argument("--figure", default=str(HERE / "capture_card.png"))
    args = ap.parse_args()
    print(f"capture fit: {args.fit}; Blender Cycles, {SAMPLES} samples a pixel, images at most {MAX_SIDE} px a side")
    figs, table = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.objects.split(","):
            info, rows, fig = run_object(name, args.fit, Path(tmp))
            print(info)
            figs.append(fig)
            table += [(name,) + r for r in rows]
    print("| object | light | theta_l (deg) | fit (dB) | glTF (dB) | Blender (dB) | B-vs-glTF (dB) |")
    print("|---|---|---|---|---|---|---|")
    for name, i, th, a, b, c, d in table:
        print(f"| {name} | {i + 1} | {th:.0f} | {a:.1f} | {b:.1f} | {c:.1f} | {d:.1f} |")
    means = np.mean(np.array([r[3:] for r in table]), 0)
    print("| mean | | | " + " | ".join(f"{x:.1f}" for x in means) + " |")
    _figure(figs, Path(args.figure))
    print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
