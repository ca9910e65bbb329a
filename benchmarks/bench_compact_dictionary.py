"""Benchmark: the make-up of the ``sparse`` family's dictionary, by held-out error on the two RGL-EPFL measurements.

Each variant sets the dictionary's learned-basis rows, skew rows, degree of the symmetric terms and hats in the
grid's coordinates ``a`` (warped ``theta_h``) and ``b`` (``theta_d``); the sparse family then takes the most
columns its mask leaves within 33 numbers per material, chosen per file by its own greedy selection
(``polyjax/_compact/families/sparse.py``), fitted on one 20,000-bin subsample (seed 11) and scored on another
(seed 12), both metrics, beside the neural BRDF of the same file (675 numbers). The shipped make-up is marked.

Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_compact_dictionary.py``
"""

import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

from polyjax._compact.families import sparse  # noqa: E402
from polyjax._compact.select import rgb_errors  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _rgl_split import FILES, rgl_split  # noqa: E402

#: (basis rows, skew rows, degree, hats in a, hats in b)
VARIANTS = [(40, 16, 3, 10, 10), (40, 16, 5, 10, 10), (40, 16, 3, 20, 20), (40, 16, 5, 20, 20), (86, 20, 5, 20, 20),
            (32, 8, 5, 20, 20), (48, 16, 4, 16, 16), (40, 16, 3, 20, 0), (36, 12, 3, 20, 8), (40, 16, 3, 20, 10),
            (40, 16, 3, 30, 10), (32, 16, 3, 20, 4)]
NAMES = ("D_BASIS", "D_SKEW", "POLY_DEGREE", "N_HATS_A", "N_HATS_B")


def main():
    t0 = time.perf_counter()
    shipped = tuple(getattr(sparse, n) for n in NAMES)
    data, neural = {}, {}
    for name in FILES:
        fit, score, nb = rgl_split(name)
        data[name] = fit, score
        neural[name] = [float(x) for x in rgb_errors(score.values, nb, score.u, score.v, score.weights,
                                                     jnp.broadcast_to(score.mask, score.values.shape))]
    lines = ["| rows, skew rows, degree, hats a, hats b | D | columns at 33 | paper L2, log (ratio to neural) | "
             "satin L2, log (ratio to neural) |", "|---|---|---|---|---|"]
    try:
        for variant in VARIANTS:
            for n, x in zip(NAMES, variant):
                setattr(sparse, n, x)
            sparse._node_hats.cache_clear()
            fam = sparse.SparseShapeFamily()
            config = fam.configs(33)[-1]
            cells = []
            for name, (fit, score) in data.items():
                mask = jnp.broadcast_to(fit.mask, fit.values.shape)
                params = fam.fit(config, fit.u, fit.v, jnp.asarray(fit.values), fit.weights, mask, "log")
                pred = fam.evaluate(config, params, score.u, score.v)
                l2, lg = (float(x) for x in rgb_errors(score.values, pred, score.u, score.v, score.weights,
                                                        jnp.broadcast_to(score.mask, score.values.shape)))
                cells.append(f"{l2:.4f}, {lg:.4f} ({l2 / neural[name][0]:.2f}x, {lg / neural[name][1]:.2f}x)")
            mark = " (shipped)" if variant == shipped else ""
            lines.append(f"| {', '.join(map(str, variant))}{mark} | {fam.size} | {config[0]} | " + " | ".join(cells)
                         + " |")
            print(lines[-1], flush=True)
    finally:
        for n, x in zip(NAMES, shipped):
            setattr(sparse, n, x)
        sparse._node_hats.cache_clear()
    lines.append(f"\nNeural BRDF (675): paper {neural[FILES[0]][0]:.4f}, {neural[FILES[0]][1]:.4f}; satin "
                 f"{neural[FILES[1]][0]:.4f}, {neural[FILES[1]][1]:.4f}. "
                 f"Total run time {time.perf_counter() - t0:.0f} s.")
    print("\n".join(lines))


if __name__ == "__main__":
    main()
