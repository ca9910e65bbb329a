"""Benchmark: what the sparse family's two objectives trade on the two RGL-EPFL measurements at 33 numbers.

The sparse family (``polyjax/_compact/families/sparse.py``) has two objectives: the one its greedy selection of
columns minimises (the linearised log rows plus ``MIX`` times equation (11)'s L2 rows, or the L2 rows alone) and
the one its Gauss-Newton fit on the chosen columns minimises (``E_log^2 / E_log,0^2 + MIX E_2^2 / E_2,0^2``, or the
L2 alone). ``metric="log"`` uses ``MIX = 3`` for both, ``metric="l2"`` the L2 alone for both. This script fits
every pair of ``MIX`` in (3, 30, L2 alone) for the selection and (3, 10, 30, 100, L2 alone) for the fit on one
20,000-bin subsample (seed 11) of each file and scores it on another (seed 12), both metrics, as ratios to the
neural BRDF of the same file (675 numbers): the front of one model (22 columns, 33 numbers) between the two
metrics. A last column scores the same fits with the model's 80-degree bound ``g_top`` lifted (the evaluation
then bounded by ``G_MAX`` alone): whether the bound couples the grazing bins to the inside.

Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_compact_objective.py``
"""

import functools
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

from polyjax._compact.families import sparse  # noqa: E402
from polyjax._compact.families.shared import shared_value  # noqa: E402
from polyjax._compact.select import rgb_errors  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _rgl_split import FILES, rgl_split  # noqa: E402

SELECTION = (3.0, 30.0, None)
FIT = (3.0, 10.0, 30.0, 100.0, None)


@functools.partial(jax.jit, static_argnums=(1, 2, 3))
def fit_one(cols, k, mix_select, mix_fit, u, v, values, weights, mask):
    """The sparse family's fit of one material with the selection's and the fit's ``MIX`` apart (None: the L2
    alone)."""
    chosen = sparse.choose_columns(cols, k, mix_select, u, v, values, weights, mask)
    return sparse.fit_with(cols, chosen, k, mix_fit, u, v, values, weights, mask)


def scores(values, pred, d):
    return tuple(float(x) for x in rgb_errors(values, pred, d.u, d.v, d.weights,
                                              jnp.broadcast_to(d.mask, values.shape)))


def label(mix):
    return "L2 alone" if mix is None else f"{mix:g}"


def main():
    t0 = time.perf_counter()
    fam = sparse.SparseShapeFamily()
    config = fam.candidates(33)[0]
    _, arrays = fam.program(config)
    lines = [f"Sparse family `{config}` ({fam.n_numbers(config)} numbers); ratios to the neural BRDF (675 numbers) "
             "on held-out directions.", "",
             "| file | selection MIX | fit MIX | L2 | log | L2, log without the bound |", "|---|---|---|---|---|---|"]
    for name in FILES:
        fit, score, nb = rgl_split(name)
        ref = scores(score.values, nb, score)
        cols = sparse.dictionary(arrays[0], fit.u, fit.v)
        cols_score = sparse.dictionary(arrays[0], score.u, score.v)
        mask = jnp.broadcast_to(jnp.asarray(fit.mask), fit.values.shape)
        for ms in SELECTION:
            for mf in FIT:
                params = fit_one(cols, config[0], ms, mf, fit.u, fit.v, jnp.asarray(fit.values),
                             jnp.asarray(fit.weights), mask)
                l2, lg = scores(score.values, fam.evaluate(config, params, score.u, score.v), score)
                coef, colour = sparse.dense(params, config[0], cols_score.shape[-1])
                free = shared_value(cols_score, cols_score, jnp.concatenate([coef, colour], -1))
                f2, fl = scores(score.values, free, score)
                mark = " (default)" if (ms, mf) == (3.0, 3.0) else " (`metric=\"l2\"`)" if ms is mf is None else ""
                lines.append(f"| {name}{mark} | {label(ms)} | {label(mf)} | {l2 / ref[0]:.3f}x | "
                             f"{lg / ref[1]:.3f}x | {f2 / ref[0]:.3f}x, {fl / ref[1]:.3f}x |")
                print(lines[-1], flush=True)
        lines.append(f"| {name}: neural BRDF | | | {ref[0]:.4f} | {ref[1]:.4f} | |")
    lines.append(f"\nTotal run time {time.perf_counter() - t0:.0f} s.")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
