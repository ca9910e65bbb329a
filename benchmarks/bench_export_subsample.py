"""Benchmark: the default subsample of ``polyjax export <measured data> --to gltf|mitsuba-xml|openpbr|usd``.

A standard export of a data set on the MERL grid fits the standard model to a seeded subsample of 20,000 of its
1,111,432 bins unless ``--subsample all`` (``polyjax/cli/_export_standard.py``). Claim: the material fitted to the
subsample is as good on the whole grid as the one fitted to every bin. For each RGL-EPFL file given: the standard
model (``gltf-pbr`` by default, R, G, B jointly, equation (11), 80-degree cutoff, as the export fits it) fitted to
the subsample and to every bin, both scored on every bin by the L2 of equation (11) (mean over R, G, B) and the
log-space error (:func:`polyjax.log_error`, root mean square over R, G, B), with the fit's seconds and the
process's peak memory after each fit.

Usage: ``POLYJAX_DATA=... python benchmarks/bench_export_subsample.py [--files satin_rosaline_rgb,...]
[--model gltf-pbr] [--subsample 20000]``
"""

import argparse
import resource
import time

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import baselines as bl  # noqa: E402
import polyjax as pj  # noqa: E402


def scores(fit, full) -> tuple[float, float]:
    """``(mean L2 of eq. (11), RMS log-space error)`` of ``fit`` on every bin of ``full``."""
    u, v = np.asarray(full.u), np.asarray(full.v)
    pred = fit(u, v)
    l2 = pj.l2_error(full.values, pred, u, v, weights=full.weights, cutoff_deg=80.0, mask=full.mask)
    lg = pj.log_error(full.values, pred, u, v, full.weights, cutoff_deg=80.0, mask=full.mask)
    return float(np.mean(np.asarray(l2))), float(np.sqrt(np.mean(np.square(np.asarray(lg)))))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--files", default="satin_rosaline_rgb,paper_white_rgb")
    ap.add_argument("--model", default="gltf-pbr")
    ap.add_argument("--subsample", type=int, default=20000)
    args = ap.parse_args()
    print("| file | fitted to | bins | fit s | peak RSS GB | L2 eq. (11), all bins | log error, all bins |")
    print("|---|---|---|---|---|---|---|")
    for name in args.files.split(","):
        full = pj.data.load(f"rgl:{name}")
        part = pj.data.load(f"rgl:{name}", subsample=args.subsample)
        rows = {}
        for label, data in (("subsample", part), ("all", full)):
            t0 = time.perf_counter()
            fit = bl.fit(args.model, data)
            np.asarray(fit.l2)
            seconds = time.perf_counter() - t0
            peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20
            rows[label] = scores(fit, full)
            print(f"| {name} | {label} | {data.values.shape[-1]} | {seconds:.1f} | {peak:.2f} | "
                  f"{rows[label][0]:.5g} | {rows[label][1]:.5g} |", flush=True)
        (a, b), (c, d) = rows["subsample"], rows["all"]
        print(f"| {name} | subsample / all | | | | {a / c:.4f} | {b / d:.4f} |", flush=True)


if __name__ == "__main__":
    main()
