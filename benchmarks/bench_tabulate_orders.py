"""Benchmark: the second order of a table over the whole turn of ``phi_d``, by the compiled program of the first.

The viewer, the GLSL table export and the Mitsuba plugin tabulate a model in both orders of each direction pair
(``f(u, v)`` and ``f(v, u)`` on the MERL grid, ``polyjax/export/_merl.py``: ``tabulate_both_orders``) to cover
``phi_d`` over ``[0, 2 pi)`` when the model is not reciprocal. The second order was a new closure
``lambda u, v: f(v, u)`` on every call, so the jitted tabulation compiled again each time (and JAX's persistent
cache could not keep it: the closure is a new static argument). ``pj.export.tabulate_merl(model, swap=True)`` passes
the directions exchanged to the program compiled for the first order.

In one run, for one compact fit (``pj.fit_compact`` of a MERL material at 33 numbers) at the MERL resolution
(90 x 90 x 180 bins), after one warm-up call of each: the median over ``--repeats`` calls of

- ``first order``: ``tabulate_merl(model)``;
- ``swapped, closure`` (the code before): ``tabulate_merl(lambda u, v: model(v, u))``, a new closure each call;
- ``swapped, swap=True``: ``tabulate_merl(model, swap=True)``;

and the ratio of the last two. Usage: ``POLYJAX_DATA=<data root> python benchmarks/bench_tabulate_orders.py``
"""

import argparse
import statistics
import time

import jax

jax.config.update("jax_enable_x64", True)

import polyjax as pj  # noqa: E402
from polyjax.render import evaluate_rgb, rgb_brdf  # noqa: E402


def timed(call, repeats):
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        values, _ = call()
        values.block_until_ready()
        out.append(time.perf_counter() - t)
    return statistics.median(out)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--material", default="gold-metallic-paint")
    ap.add_argument("--repeats", type=int, default=5)
    args = ap.parse_args()
    data = pj.data.load_merl_nbrdf(args.material, subsample=20000, seed=11)
    model = pj.fit_compact(data, 33)
    brdf = rgb_brdf(model)
    calls = {
        "first order": lambda: pj.export.tabulate_merl(brdf),
        "swapped, closure (before)": lambda: pj.export.tabulate_merl(lambda u, v: evaluate_rgb(brdf, v, u)),
        "swapped, swap=True": lambda: pj.export.tabulate_merl(brdf, swap=True),
    }
    for call in calls.values():
        call()[0].block_until_ready()
    times = {name: timed(call, args.repeats) for name, call in calls.items()}
    print(f"{args.material}: compact {model.family} {model.config} ({model.n_numbers} numbers), 90 x 90 x 180 bins, "
          f"median of {args.repeats}")
    for name, t in times.items():
        print(f"  {name}: {t:.3f} s")
    ratio = times["swapped, closure (before)"] / times["swapped, swap=True"]
    print(f"  swapped order, closure / swap=True: {ratio:.1f}x")


if __name__ == "__main__":
    main()
