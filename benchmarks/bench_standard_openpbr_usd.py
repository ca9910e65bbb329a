"""Benchmark: what accuracy the OpenPBR and UsdPreviewSurface standard models cost on neural-MERL materials.

Claim measured: the L2 of equation (11) and the log metric of ``openpbr``, ``usd-preview`` and
``usd-preview-specular`` fits, beside a Cook-Torrance fit and the better of the published SGD / ABC fits (ratio
to that), with the time per material of each fit after compilation, all in one run.

- Data: the neural-BRDF fits of MERL materials (Sztrajman et al. 2021) on the MERL grid; ``--eval-bins`` valid bins
  (seed 0) to score, ``--fit-bins`` other bins (seed 1) to fit, as ``bench_merl100.py`` does.
- Fits: :func:`baselines.fit`, ``--starts`` starts, every material's R, G, B lanes in one batched call. Each
  model's fit runs twice on the same data: the first call's time includes compilation, the second is reported
  (divided by the number of materials).
- Scores: mean over R, G, B of equation (11) and of the weighted L2 of ``log(1 + f cos theta_u)``
  (``bench_merl100.log_metric``).

Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_standard_openpbr_usd.py [--materials a,b,c]``
(prints a markdown table).
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import baselines as bl  # noqa: E402
import polyjax as pj  # noqa: E402
from benchmarks.bench_merl100 import ISSUE_ROWS, published_predictions, scores  # noqa: E402

MODELS = ("openpbr", "usd-preview", "usd-preview-specular", "cook-torrance")


def _fit_twice(name, dfit, starts):
    """The fit of every lane, and the seconds of its second (compiled) call."""
    fit = bl.fit(name, dfit, n_starts=starts)
    fit.params.block_until_ready()
    t = time.perf_counter()
    fit = bl.fit(name, dfit, n_starts=starts)
    fit.params.block_until_ready()
    return fit, time.perf_counter() - t


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--materials", default=",".join(ISSUE_ROWS))
    ap.add_argument("--eval-bins", type=int, default=20000)
    ap.add_argument("--fit-bins", type=int, default=5000)
    ap.add_argument("--starts", type=int, default=16)
    ap.add_argument("--models", default=",".join(MODELS), help="comma-separated baseline models to fit")
    args = ap.parse_args()
    names = args.materials.split(",")
    d = pj.data.load_merl_nbrdf(names, subsample=args.eval_bins, seed=0)
    dfit = pj.data.load_merl_nbrdf(names, subsample=args.fit_bins, seed=1)
    l2_best, lg_best = np.minimum(*[scores(d.values, published_predictions(k, names, d), d) for k in ("sgd", "abc")])
    rows = []
    for name in args.models.split(","):
        t0 = time.perf_counter()
        fit, t = _fit_twice(name, dfit, args.starts)
        first = time.perf_counter() - t0 - t
        l2, lg = scores(d.values, jnp.asarray(fit(d.u, d.v)), d)
        ok = int(np.sum(np.asarray(fit.success)))
        rows.append(f"| {name} | {bl.get_model(name).n_params} | {np.mean(l2):.4f} | {np.median(l2 / l2_best):.2f} | "
                    f"{np.mean(lg):.4f} | {np.median(lg / lg_best):.2f} | {t / len(names):.2f} | {first:.0f} | "
                    f"{ok} of {fit.success.size} |")
        print(rows[-1], flush=True)
    print(f"\n{len(names)} neural-MERL materials ({', '.join(names)}); scored on {d.u.shape[0]} bins (seed 0), fitted "
          f"on {dfit.u.shape[0]} others (seed 1), {args.starts} starts; ratios to the better of the published SGD and "
          "ABC fits per material.\n")
    print("| model | params / channel | mean L2 (eq. 11) | median L2 ratio | mean log metric | median log ratio | "
          "fit s / material | first call s (compile) | lanes converged |")
    print("|---|---|---|---|---|---|---|---|---|")
    print("\n".join(rows))
    print(f"| published best of SGD / ABC | 10 / 5 | {np.mean(l2_best):.4f} | 1.00 | {np.mean(lg_best):.4f} | 1.00 | "
          "published | - | - |")


if __name__ == "__main__":
    main()
