"""Benchmark: the paper's seven nonlinear models and Zernike on the 52 isotropic CUReT samples.

For every model, all materials and all starts are fitted in one batched call (timed after a
warm-up call that compiles). Reported per model: mean/median L2 (paper equation (11)), fits that
did not converge, time per material against the paper's Table 4 (Pentium D, one start) and
against scipy.optimize.least_squares (MINPACK Levenberg-Marquardt) run from the same starting
points on the same residuals and Jacobians (jitted JAX functions). scipy is run on a subset of
the materials and its time per material extrapolated (said in the output). Finally our L2 on
the five Table 2 samples beside the paper's numbers.

Usage: ``POLYJAX_DATA=... python benchmarks/bench_baselines.py [--quick] [--scipy-materials K]``
"""

import argparse
import sys
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import baselines as bl  # noqa: E402
import polyjax as pj  # noqa: E402

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the repository root: `benchmarks` as a package
from benchmarks.paper.constants import PAPER_NONLINEAR_SECONDS as PAPER_TIME  # noqa: E402
from benchmarks.paper.constants import PAPER_TABLE2, TABLE2_IDS  # noqa: E402
from benchmarks.paper.experiments import timed  # noqa: E402
from benchmarks.paper.references import scipy_best_l2  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="scipy on 6 materials, two timing repeats")
    ap.add_argument("--n-starts", type=int, default=16)
    ap.add_argument("--stage-steps", type=int, default=None, help="baselines.fit stage_steps (default: fit's own)")
    ap.add_argument("--refine", type=int, default=None, help="baselines.fit refine (default: fit's own)")
    ap.add_argument("--scipy-materials", type=int, default=None,
                    help="materials for the scipy reference (default 52, quick 6)")
    args = ap.parse_args()
    data = pj.data.load_curet(samples=pj.data.ISOTROPIC_52)
    nm = data.values.shape[0]
    k_sc = args.scipy_materials or (6 if args.quick else nm)
    idx = np.linspace(0, nm - 1, k_sc).round().astype(int) if k_sc < nm else np.arange(nm)
    repeats = 2 if args.quick else 3
    key = jax.random.PRNGKey(0)
    opts = {k: val for k, val in (("stage_steps", args.stage_steps), ("refine", args.refine)) if val is not None}
    print(f"CUReT {nm} isotropic samples x {data.values.shape[-1]} geometries; {args.n_starts} starts per material; "
          f"devices {jax.devices()}")
    if k_sc < nm:
        print(f"scipy reference on {k_sc} of {nm} materials (indices {idx.tolist()}); its time per material is the "
              "mean over those, extrapolated to all")
    hdr = (f"{'model':18s} {'mean L2':>8s} {'median':>8s} {'not conv':>8s} {'compile s':>9s} {'ms/mat':>7s} "
           f"{'paper ms':>8s} {'x paper':>7s} {'scipy ms':>8s} {'x scipy':>7s} {'<=scipy':>8s}")
    print(hdr)
    rows = {}
    all_ok, all_n = 0, 0
    fits = {}
    for name in bl.PAPER_MODELS:
        fit, first, dt = timed(lambda name=name: bl.fit(name, data, n_starts=args.n_starts, key=key, **opts), repeats)
        fits[name] = fit
        per = dt / nm
        l2 = np.asarray(fit.l2)
        notconv = int((~np.asarray(fit.success)).sum())
        nonfinite = int((~np.isfinite(l2)).sum())
        line = f"{name:18s} {l2.mean():8.5f} {np.median(l2):8.5f} {notconv:8d} {first - dt:9.1f} {per * 1e3:7.2f} "
        if name in PAPER_TIME:
            starts = bl.initial_guesses(name, data, n_starts=args.n_starts, key=key)
            ref, sc_per = scipy_best_l2(name, data.u, data.v, data.values, starts, weights=data.weights,
                                         mask=data.mask, lanes=idx)
            ok = l2[idx] <= ref * (1 + 1e-3) + 1e-7
            all_ok += int(ok.sum())
            all_n += len(idx)
            line += (f"{PAPER_TIME[name] * 1e3:8.1f} {PAPER_TIME[name] / per:7.1f} {sc_per * 1e3:8.1f} "
                     f"{sc_per / per:7.1f} {ok.mean() * 100:7.1f}%")
            rows[name] = (PAPER_TIME[name] / per, sc_per / per)
        else:
            line += f"{'-':>8s} {'-':>7s} {'-':>8s} {'-':>7s} {'-':>8s}  (closed form, 55 terms)"
        print(line + (f"  [{nonfinite} non-finite]" if nonfinite else ""), flush=True)
    print()
    print("Table 2 (L2): ours / paper")
    pos = [data.ids.index(i) for i in TABLE2_IDS]
    print(f"{'model':18s} " + " ".join(f"{pj.data.TABLE2_SAMPLES[i]:>17s}" for i in TABLE2_IDS))
    for name in bl.PAPER_MODELS:
        l2 = np.asarray(fits[name].l2)[pos]
        print(f"{name:18s} " + " ".join(f"{a:8.4f}/{b:8.4f}" for a, b in zip(l2, PAPER_TABLE2[name])))
    print()
    xp = min(r[0] for r in rows.values())
    xs = min(r[1] for r in rows.values())
    frac = all_ok / max(all_n, 1)
    print(f"targets: min speed-up vs paper {xp:.1f}x (target >= 50x): {'MET' if xp >= 50 else 'NOT MET'}; "
          f"min speed-up vs scipy {xs:.1f}x (target >= 10x): {'MET' if xs >= 10 else 'NOT MET'}; "
          f"L2 <= scipy on {frac * 100:.1f}% of {all_n} fits (target >= 95%): {'MET' if frac >= 0.95 else 'NOT MET'}")
    print("times exclude compilation (the first call, shown as 'compile s'); paper: Pentium D 2.66 GHz, single start")


if __name__ == "__main__":
    main()
