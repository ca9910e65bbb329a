"""Shape and material from photographs: :func:`polyjax.fit_capture` on DiLiGenT objects, without their normals.

Claim: fitted on alternate halves of each object's lights (even indices fitted, odd indices held out), the normals'
mean angular error is at most 0.85x that of a Lambertian least-squares fit of the same lights on every object and
at most 0.7x on average; relighting the held-out half has a relative RMS at most 0.9x that of the anchor (each
pixel's own values under its three nearest fitted lights, inverse-angle-distance weights, rescaled by the held-out
light's intensity); a 300 x 300, 48-light object fits in under 60 s on 2 cores after compilation.

Objects: the five 8-bit crops of ``$POLYJAX_DATA/diligent/crop8`` (all 96 lights: 48 fitted) and the 16-bit ball of
``$POLYJAX_DATA/diligent/ballPNG`` (48 lights: 24 fitted); every light kept, bear's first 20 included. The ground-truth
normals score the fits and are never used by them. One setting for every object (``fit_capture``'s defaults).
Error of the normals: mean over the mask's pixels of the angle to the ground truth, degrees. Relighting error:
relative RMS over the mask's pixels of the held-out images with no saturated channel. The fit is run twice (the
second run, warm, is timed; the first runs one alternation, which compiles every program).
``--figure PATH`` writes normal and error maps.

Run: ``python benchmarks/bench_capture.py [--step S] [--objects cat,pot1,...] [--figure benchmarks/capture.png]``.
"""

from __future__ import annotations

import argparse
import os
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import polyjax as pj  # noqa: E402

OBJECTS = ("cat", "pot1", "bear", "pot2", "goblet", "ball")
#: published mean angular errors (degrees) on DiLiGenT's 16-bit originals, 96 lights, ten objects' average
PUBLISHED = {"Lambertian least squares": 15.4, "2014 bivariate-BRDF methods": "10.3-10.6", "PS-FCN (2018)": 8.4,
             "CNN-PS (2018)": 7.2, "universal models (2024)": 4.7}


def folder_of(name: str) -> str:
    root = os.path.join(os.environ.get("POLYJAX_DATA", "data"), "diligent")
    return os.path.join(root, "ballPNG") if name == "ball" else os.path.join(root, "crop8", f"{name}PNG")


def angular_error(n, gt, mask):
    """Per-pixel angle (degrees) between unit normals on the mask."""
    return np.degrees(np.arccos(np.clip(np.sum(np.asarray(n)[mask] * np.asarray(gt)[mask], -1), -1.0, 1.0)))


def lambertian(capture):
    """Plain Lambertian least squares of the grey values over irradiance (every light, no shadow handling)."""
    mask = np.asarray(capture.mask)
    obs = np.asarray(capture.images)[:, mask] / np.asarray(capture.light_intensities)[:, None, :]
    b = np.linalg.lstsq(np.asarray(capture.light_directions), obs.mean(-1), rcond=None)[0].T  # (P, 3)
    n = b / np.maximum(np.linalg.norm(b, axis=1, keepdims=True), 1e-12)
    out = np.zeros(mask.shape + (3,))
    out[..., 2] = 1.0
    out[mask] = n
    return out


def anchor(train, test, k: int = 3):
    """Each pixel's own values under its ``k`` nearest fitted lights (inverse-angle weights) times the held-out
    light's intensity."""
    dtr, dte = np.asarray(train.light_directions), np.asarray(test.light_directions)
    ang = np.arccos(np.clip(dte @ dtr.T, -1.0, 1.0))
    near = np.argsort(ang, axis=1)[:, :k]
    wts = 1.0 / np.maximum(np.take_along_axis(ang, near, 1), 1e-6)
    wts /= wts.sum(1, keepdims=True)
    obs = np.asarray(train.images) / np.asarray(train.light_intensities)[:, None, None, :]
    pred = np.einsum("tj,tjhwc->thwc", wts, obs[near])
    return pred * np.asarray(test.light_intensities)[:, None, None, :]


def relative_rms(pred, capture):
    images, mask = np.asarray(capture.images), np.asarray(capture.mask)
    keep = mask[None] & np.all(images < capture.saturation, axis=-1)
    return float(np.sqrt(np.sum((np.asarray(pred) - images)[keep] ** 2) / np.sum(images[keep] ** 2)))


def measure(name: str, step: int):
    capture = pj.data.load_photometric(folder_of(name))
    if step > 1:
        capture = capture.strided(step)
    train = capture.select(np.arange(0, capture.n_lights, 2))
    test = capture.select(np.arange(1, capture.n_lights, 2))
    gt, mask = np.asarray(capture.normals), np.asarray(capture.mask)
    blind = train.__class__(train.images, train.mask, None, train.light_directions, train.light_intensities,
                            train.names, train.saturation, train.quantisation)
    pj.fit_capture(blind, iterations=1)  # compile (the same programs: one alternation is enough)
    t0, c0 = time.perf_counter(), time.process_time()
    fit = pj.fit_capture(blind)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    lam = lambertian(train)
    e_lam, e_ours = angular_error(lam, gt, mask), angular_error(fit.normals, gt, mask)
    r_anchor, r_ours = relative_rms(anchor(train, test), test), relative_rms(pj.relight(fit, test), test)
    row = dict(object=name, pixels=int(mask.sum()), lights=train.n_lights, lambertian=float(e_lam.mean()),
               ours=float(e_ours.mean()), anchor=r_anchor, relight=r_ours, seconds=seconds, cpu=cpu,
               load=os.getloadavg()[0],
               status=pj.RESULTS(int(fit.status)).name, iterations=fit.iterations)
    maps = dict(gt=gt, lam=lam, ours=np.asarray(fit.normals), mask=mask)
    return row, maps


def figure(path, all_maps):
    """Normal maps (ground truth, Lambertian, ours) and the error maps, one row per object."""
    import matplotlib  # optional: only for --figure

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(all_maps), 5, figsize=(10, 2 * len(all_maps)))
    for row, (name, m) in zip(np.atleast_2d(axes), all_maps.items()):
        for ax, key, title in zip(row[:3], ("gt", "lam", "ours"), ("ground truth", "Lambertian LS", "fit_capture")):
            ax.imshow(np.where(m["mask"][..., None], (m[key] + 1) / 2, 1.0))
            ax.set_title(f"{name}: {title}", fontsize=7)
        for ax, key, title in zip(row[3:], ("lam", "ours"), ("error, Lambertian", "error, fit_capture")):
            err = np.full(m["mask"].shape, np.nan)
            err[m["mask"]] = angular_error(m[key], m["gt"], m["mask"])
            im = ax.imshow(err, vmin=0, vmax=40, cmap="magma")
            ax.set_title(f"{title} (deg)", fontsize=7)
        fig.colorbar(im, ax=row[4], fraction=0.046)
    for ax in np.ravel(axes):
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=60)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--step", type=int, default=1, help="every step-th pixel (1: full resolution)")
    ap.add_argument("--objects", default=",".join(OBJECTS))
    ap.add_argument("--figure", default=None, help="write normal and error maps to this PNG")
    args = ap.parse_args()
    rows, all_maps = [], {}
    print("| object | pixels | lights fitted | Lambertian LS (deg) | fit_capture (deg) | ratio | anchor rel. RMS | "
          "fit_capture rel. RMS | ratio | fit (s) | CPU (s) | load | status |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name in args.objects.split(","):
        row, maps = measure(name, args.step)
        rows.append(row)
        all_maps[name] = maps
        print(f"| {name} | {row['pixels']} | {row['lights']} | {row['lambertian']:.2f} | {row['ours']:.2f} | "
              f"{row['ours'] / row['lambertian']:.3f} | {row['anchor']:.4f} | {row['relight']:.4f} | "
              f"{row['relight'] / row['anchor']:.3f} | {row['seconds']:.1f} | {row['cpu']:.1f} | {row['load']:.1f} | "
              f"{row['status']} "
              f"({row['iterations']} it.) |", flush=True)
    ratios = [r["ours"] / r["lambertian"] for r in rows]
    rel = [r["relight"] / r["anchor"] for r in rows]
    print(f"\nmean Lambertian {np.mean([r['lambertian'] for r in rows]):.2f} deg, mean fit_capture "
          f"{np.mean([r['ours'] for r in rows]):.2f} deg; normals ratio max {max(ratios):.3f} (target 0.85), mean "
          f"{np.mean(ratios):.3f} (target 0.7); relighting ratio max {max(rel):.3f} (target 0.9)")
    print("published (16-bit, 96 lights, ten objects):", PUBLISHED)
    if args.figure:
        figure(args.figure, all_maps)


if __name__ == "__main__":
    main()
