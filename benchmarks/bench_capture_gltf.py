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

The capture fit is ``polyjax.fit_capture`` with its defaults (normals and BRDF from the photographs alone, the
ground-truth normals unused), fitted on the even-index lights; the held-out
lights are three odd-index ones (the 10th, 50th and 90th percentiles of their elevation). ``bear``: the first 20
images are left out (DiLiGenT's calibration problem). Images strided to at most 128 pixels a side.

Run: ``python benchmarks/bench_capture_gltf.py [--objects cat,pot1,...]`` (needs
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


def run_object(name, tmp: Path):
    """Fit, card, Blender renders and PSNRs of one object; the figure row."""
    cap = pj.data.load_photometric(str(Path(os.environ["POLYJAX_DATA"]) / "diligent" / "crop8" / f"{name}PNG"))
    cap = cap.strided(int(np.ceil(max(np.shape(cap.mask)) / MAX_SIDE)))
    lights = np.arange(20 if name == "bear" else 0, cap.n_lights)
    even, odd = lights[lights % 2 == 0], lights[lights % 2 == 1]
    t0 = time.perf_counter()
    fit = pj.fit_capture(cap.select(even))
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
            f"{np.round(np.asarray(lobes.relative_l2), 3).tolist()}; light scale {maps.scale:.3g}; fit status "
            f"{pj.RESULTS(int(np.asarray(fit.status))).name}, {fit.iterations} alternations")
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
    ap.add_argument("--figure", default=str(HERE / "capture_card.png"))
    args = ap.parse_args()
    print(f"capture fit: polyjax.fit_capture defaults; Blender Cycles, {SAMPLES} samples a pixel, images at most "
          f"{MAX_SIDE} px a side")
    figs, table = [], []
    with tempfile.TemporaryDirectory() as tmp:
        for name in args.objects.split(","):
            info, rows, fig = run_object(name, Path(tmp))
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
