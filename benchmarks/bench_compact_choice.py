"""Benchmark: :func:`polyjax.fit_compact`'s greedy search against the exhaustive cross-validation of every candidate.

The choice cross-validates the first candidate of every chain, then walks the best one's chain while the held-out
error falls (``polyjax/_compact/select.py``). This script cross-validates every candidate within the budget (the
same folds, the same programs) and reports, per material, whether the greedy search chose the candidate of least
held-out error, how many candidates each cross-validated, and the held-out error of the greedy choice over the
exhaustive one's. Materials: every ``--step``-th of ``MERL_NAMES``, fitted on ``load_merl_nbrdf(name,
subsample=20000, seed=11)``, with the ``basis``, ``skew`` and ``shared`` families on a basis learned without the
material (``bench_compact.loo_families``).

Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_compact_choice.py [--budget 33] [--step 5]``
"""

import argparse
import sys
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import numpy as np  # noqa: E402

import polyjax as pj  # noqa: E402
from polyjax._compact.fit import _arrays  # noqa: E402
from polyjax._compact.select import candidate_chains, cross_validate, fold_masks, fold_parts, score  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
import learn_compact_basis as lcb  # noqa: E402
from bench_compact import loo_families  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--budget", type=int, default=33)
    ap.add_argument("--step", type=int, default=5, help="every step-th MERL material")
    args = ap.parse_args()
    names_all, tables = lcb.material_tables()
    mass = lcb.node_weights()
    names = pj.data.MERL_NAMES[:: args.step]
    rows, t_all = [], time.perf_counter()
    for name in names:
        data = pj.data.load_merl_nbrdf(name, subsample=20000, seed=11)
        objects = loo_families(name, tables, mass, names_all)
        u, v, values, weights, mask = _arrays(data)
        held, parts = fold_masks(data.n_samples, 3), fold_parts(data.n_samples, 3)
        every = {}
        for chain in candidate_chains(tuple(objects), args.budget, objects):
            for fam_name, config in chain:
                key, arrays = objects[fam_name].program(config)
                _, lg = cross_validate(fam_name, key, arrays, "log", u, v, values, weights, mask, held, parts)
                every[(fam_name, config)] = score(lg)
        best = min(every, key=every.get)
        ch = pj.internal.choose_compact(data, args.budget, families=objects)
        rows.append((name, best, (ch.family, ch.config), ch.tried, len(every),
                     every[(ch.family, ch.config)] / every[best]))
        print(f"  {name}: exhaustive {best}, greedy {(ch.family, ch.config)}, tried {ch.tried} of {len(every)}",
              flush=True)
    same = sum(r[1] == r[2] for r in rows)
    ratio = np.array([r[5] for r in rows])
    lines = [f"{len(rows)} MERL materials (every {args.step}th), budget {args.budget}, leave-one-out bases:", "",
             "| material | exhaustive choice | greedy choice | tried / candidates | greedy / exhaustive held-out log |",
             "|---|---|---|---|---|"]
    lines += [f"| {r[0]} | {r[1][0]} {r[1][1]} | {r[2][0]} {r[2][1]} | {r[3]} / {r[4]} | {r[5]:.4f} |" for r in rows]
    lines += ["", f"Same choice on {same} of {len(rows)}; held-out log error of the greedy choice over the "
              f"exhaustive one: median {np.median(ratio):.4f}, at most {ratio.max():.4f}; candidates cross-validated "
              f"{min(r[3] for r in rows)}-{max(r[3] for r in rows)} of {rows[0][4]}. "
              f"Run time {time.perf_counter() - t_all:.0f} s."]
    print("\n".join(lines))


if __name__ == "__main__":
    main()
