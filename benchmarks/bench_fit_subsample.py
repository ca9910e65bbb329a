"""Benchmark: the default subsample of ``polyjax fit`` on data on the MERL grid (the compact fit).

``polyjax fit`` with no model option on RGB data fits :func:`polyjax.fit_compact` (33 numbers). On a data set on the
MERL grid (``merl:``, ``merl-nbrdf:``, ``nbrdf:``, ``rgl:``; 1,111,432 bins above the horizon) it fits a seeded
subsample of 20,000 bins unless ``--subsample all``, as ``polyjax export`` does (``polyjax/cli/_args.py``). Claim:
the model chosen and fitted on the subsample is as good on the whole grid as the one chosen and fitted on every
bin, at a fraction of the time. For each data set: :func:`polyjax.fit_compact` at ``--budget`` on the subsample
(the loader's default seed, the command's) and on every bin, both scored on every bin by issue 36's two metrics
(the L2 of equation (11), 80-degree cutoff, and the log metric of :func:`polyjax.log_error`, every bin above the
horizon; root mean square over R, G, B), with each fit's seconds. The subsample's fit is timed after one warm-up
fit on another subsample of the same size (its programs compiled, as a second command finds them in the
compilation cache); the fit on every bin compiles for its own sizes, as the command on all bins does.

Usage: ``POLYJAX_DATA=... python benchmarks/bench_fit_subsample.py [--datasets rgl:paper_white_rgb,...]
[--budget 33] [--subsample 20000]``
"""

import argparse
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import polyjax as pj  # noqa: E402

DATASETS = ("rgl:paper_white_rgb", "rgl:satin_rosaline_rgb", "merl-nbrdf:gold-metallic-paint",
            "merl-nbrdf:chrome", "merl-nbrdf:blue-fabric")


def scores(model, full) -> tuple[float, float]:
    """``(L2 of eq. (11), log metric)`` of ``model`` on every bin of ``full``, each the RMS over R, G, B."""
    pred = model(full.u, full.v)
    l2 = pj.l2_error(full.values, pred, full.u, full.v, weights=full.weights, cutoff_deg=80.0, mask=full.mask)
    lg = pj.log_error(full.values, pred, full.u, full.v, full.weights, mask=full.mask)
    return tuple(float(np.sqrt(np.mean(np.square(np.asarray(x))))) for x in (l2, lg))


def timed_fit(data, budget):
    t0 = time.perf_counter()
    model = pj.fit_compact(data, budget)
    np.asarray(model.l2)
    return model, time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--datasets", default=",".join(DATASETS))
    ap.add_argument("--budget", type=int, default=33)
    ap.add_argument("--subsample", type=int, default=20000)
    args = ap.parse_args()
    t_start = time.perf_counter()
    print(f"pj.fit_compact(data, {args.budget}) on {args.subsample} bins and on every bin, scored on every bin\n")
    print("| data set | fitted to | bins | choice | fit s | L2 eq. (11), all bins | log, all bins |")
    print("|---|---|---|---|---|---|---|")
    ratios = []
    for spec in args.datasets.split(","):
        full = pj.data.load(spec)
        part = pj.data.load(spec, subsample=args.subsample)
        timed_fit(pj.data.load(spec, subsample=args.subsample, seed=1), args.budget)  # warm-up: compile
        rows = {}
        for label, data in (("subsample", part), ("all", full)):
            model, seconds = timed_fit(data, args.budget)
            rows[label] = (seconds,) + scores(model, full)
            print(f"| {spec} | {label} | {data.values.shape[-1]} | {model.family} {model.config} | {seconds:.1f} | "
                  f"{rows[label][1]:.5g} | {rows[label][2]:.5g} |", flush=True)
        (ts, a, b), (tf, c, d) = rows["subsample"], rows["all"]
        ratios.append((tf / ts, a / c, b / d))
        print(f"| {spec} | all / subsample (time), subsample / all (errors) | | | {tf / ts:.1f}x | {a / c:.4f} | "
              f"{b / d:.4f} |", flush=True)
    r = np.array(ratios)
    print(f"\nover {len(r)} data sets: time all / subsample {r[:, 0].min():.1f}-{r[:, 0].max():.1f}x; error "
          f"subsample / all: L2 {r[:, 1].min():.4f}-{r[:, 1].max():.4f}, log {r[:, 2].min():.4f}-{r[:, 2].max():.4f}")
    print(f"total run time {time.perf_counter() - t_start:.0f} s")


if __name__ == "__main__":
    main()
