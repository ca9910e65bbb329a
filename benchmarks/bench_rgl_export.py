"""Benchmark: what a compact fit loses when written as an RGL-EPFL measured BSDF file (``--to rgl-bsdf``).

Claim: ``pj.export.rgl_bsdf`` writes a fitted model as a file that Mitsuba 3's own ``measured`` plugin renders
(no polyjax in Mitsuba's Python), evaluating as polyjax's reader does, and at the default resolution the file is
within a few per cent of the model's own held-out error against the data on both metrics.

For each data set (the two RGL-EPFL files and four neural-MERL materials) ``pj.fit_compact(data, 33)`` is fitted on
one 20,000-bin subsample (seed 11) and scored on another (seed 12), as ``bench_compact.py``; the model is written at
several resolutions ``(T, S)`` (``polyjax/export/_rgl_bsdf.py``), read back with ``pj.data.read_rgl`` (the
reference evaluation) and scored on the same bins. Printed per data set and resolution: the file's held-out L2
(equation (11)) and log error over the model's (1.000: nothing lost), the file's distance to the model itself on
both metrics, the file's size and its writing time (the model's evaluation at every node, compiled before), and once
per data set the largest difference between Mitsuba's ``measured`` plugin (``scalar_rgb``) and polyjax's reader of
the same file at 300 held-out directions, relative to the largest value.

Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_rgl_export.py [--resolutions 16,32 32,64 64,128]``
(Mitsuba's comparison needs ``pip install mitsuba``; left out with a note when it is missing).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import polyjax as pj  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _rgl_split import FILES  # noqa: E402

MERL = ("gold-metallic-paint", "chrome", "blue-fabric", "dark-red-paint")


def split(name: str):
    if name in FILES:
        path = pj.data_root() / "rgl_epfl" / f"{name}.bsdf"
        return (pj.data.load_rgl(path, subsample=20000, seed=s) for s in (11, 12))
    return (pj.data.load_merl_nbrdf(name, subsample=20000, seed=s) for s in (11, 12))


def errors(values, predicted, d):
    """RMS over R, G, B of equation (11)'s L2 and of the log metric (every bin above the horizon)."""
    mask = jnp.broadcast_to(d.mask, values.shape)
    l2 = pj.l2_error(values, predicted, d.u, d.v, d.weights, mask=mask)
    lg = pj.log_error(values, predicted, d.u, d.v, d.weights, mask=mask)
    return float(jnp.sqrt(jnp.mean(l2**2))), float(jnp.sqrt(jnp.mean(lg**2)))


def mitsuba_gap(path, back, d):
    try:
        sys.path.insert(0, str(Path(__file__).parents[1] / "tests"))
        from _rgl_problems import mitsuba_measured
        u, v = np.asarray(d.u)[:300], np.asarray(d.v)[:300]
        ours = np.asarray(back(u, v)).T
        theirs = mitsuba_measured(path, u, v)
        return f"{float(np.max(np.abs(theirs - ours)) / np.max(np.abs(ours))):.2g}"
    except ImportError as e:
        return f"(no Mitsuba: {e})"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolutions", nargs="+", default=["16,32", "32,64", "64,128"])
    ap.add_argument("--data", nargs="+", default=list(FILES) + list(MERL))
    args = ap.parse_args()
    resolutions = [tuple(int(x) for x in r.split(",")) for r in args.resolutions]
    print(f"# load average {os.getloadavg()[0]:.2f}")
    print("| data, choice | (T, S) | file / model: L2, log | file vs model: L2, log | MB | write s | Mitsuba vs "
          "polyjax's reader |")
    print("|---|---|---|---|---|---|---|")
    out = Path(tempfile.mkdtemp())
    for name in args.data:
        fit, score = split(name)
        model = pj.fit_compact(fit, 33)
        values = score.values
        mine = model(score.u, score.v)
        m_l2, m_log = errors(values, mine, score)
        for k, res in enumerate(resolutions):
            path = out / f"{name}_{res[0]}x{res[1]}.bsdf"
            pj.export.rgl_bsdf(model, path, resolution=res)  # compiles the evaluation at this size
            t0 = time.perf_counter()
            pj.export.rgl_bsdf(model, path, resolution=res)
            seconds = time.perf_counter() - t0
            back = pj.data.read_rgl(path)
            theirs = back(score.u, score.v)
            f_l2, f_log = errors(values, theirs, score)
            d_l2, d_log = errors(mine, theirs, score)
            gap = mitsuba_gap(path, back, score) if k == len(resolutions) // 2 else ""
            print(f"| {name}, {model.family} {model.config} | {res} | {f_l2 / m_l2:.4f}, {f_log / m_log:.4f} | "
                  f"{d_l2:.3g}, {d_log:.3g} | {path.stat().st_size / 1e6:.2f} | {seconds:.2f} | {gap} |", flush=True)


if __name__ == "__main__":
    main()
