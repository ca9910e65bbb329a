"""Benchmark: polynomial and baseline fits of the RGL-EPFL measured BSDFs, and their renders against Mitsuba's.

For each shared RGL-EPFL file (``$POLYJAX_DATA/rgl_epfl``), loaded with ``pj.data.load_rgl`` on the MERL grid:
fits on a seeded subsample of the grid's bins (``--fit-bins``), scored on another (``--eval-bins``) by the L2 of
equation (11) (``pj.l2_error``, mean over R, G, B, ``theta <= 80`` degrees), beside the L2 of the zero BRDF (the
data's own size). Models: closed-form polynomials (a few variable sets and degrees, and the log link
``pj.fit_log_polynomial``) and the nonlinear baselines (``baselines.fit``, 16 starts). Fit times: the first call
(compiling) and a second call (compiled). Then a unit sphere under a point light (the scene of tests/test_mitsuba.py,
docs/conventions.md) rendered by Mitsuba 3 with its ``measured`` plugin on the file itself, and by polyjax with each
fitted model and with the measured BRDF itself (``load_rgl``'s evaluation: the check that the two renderers and
the two evaluations agree); PSNR of each against Mitsuba's render.

Usage: ``POLYJAX_DATA=... python benchmarks/bench_rgl.py [--fit-bins 20000] [--eval-bins 50000] [--size 96]``
"""

import argparse
import os
import time

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402

import baselines as bl  # noqa: E402
import polyjax as pj  # noqa: E402
import polyjax.render as pr  # noqa: E402

FILES = ("paper_white_rgb", "satin_rosaline_rgb")
POLY = {  # label: (variables, degree, link)
    "poly lafortune p=5": ("lafortune", 5, "identity"),
    "poly ashikhmin-shirley p=6": ("ashikhmin-shirley", 6, "identity"),
    "poly rusinkiewicz p=6": ("rusinkiewicz", 6, "identity"),
    "poly rusinkiewicz p=8 log": ("rusinkiewicz", 8, "log"),
}
BASELINES = ("cook-torrance", "ward", "ashikhmin-shirley")


class ChannelsLast(eqx.Module):
    """An :class:`polyjax.data.RGLBRDF` (values ``(3, n)``) in the renderer's protocol ``f(u, v) -> (..., 3)``."""

    brdf: pj.data.RGLBRDF

    def __call__(self, u, v):
        return jnp.moveaxis(self.brdf(u, v), 0, -1)


def timed(fn):
    t = time.perf_counter()
    out = fn()
    jax.block_until_ready(jax.tree_util.tree_leaves(out))
    return out, time.perf_counter() - t


def l2(d, pred):
    return float(jnp.mean(pj.l2_error(d.values, pred, d.u, d.v, d.weights, mask=d.mask)))


def fit_polynomials(dfit):
    out = {}
    for label, (variables, degree, link) in POLY.items():
        if link == "log":
            fn = lambda v=variables, p=degree: pj.fit_log_polynomial(dfit, variables=v, degree=p)  # noqa: E731
        else:
            fn = lambda v=variables, p=degree: pj.fit_polynomial(dfit, variables=v, degree=p)  # noqa: E731
        _, first = timed(fn)
        model, second = timed(fn)
        out[label] = (model, first, second)
    return out


def fit_baselines(dfit):
    out, key = {}, jax.random.PRNGKey(0)
    for name in BASELINES:
        _, first = timed(lambda n=name: bl.fit(n, dfit, n_starts=16, key=key))
        fit, second = timed(lambda n=name: bl.fit(n, dfit, n_starts=16, key=key))
        out[f"fit {name}"] = (fit, first, second)
    return out


def scene(brdf, size):
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=size, height=size, fov_deg=30.0)
    return pr.Scene(cam, [pr.Sphere(brdf)], [pr.PointLight((3.0, 2.0, 4.0), 30.0)])


def render(brdf, size):
    return np.asarray(pr.render(scene(brdf, size), dtype=jnp.float64).image)


def run_file(name, root, args):
    from polyjax.render._mitsuba import render_mitsuba

    path = pj.data.resolve_rgl_path(name, root)
    (dfit, t_load) = timed(lambda: pj.data.load_rgl(name, subsample=args.fit_bins, seed=1, root=root))
    deval = pj.data.load_rgl(name, subsample=args.eval_bins, seed=0, root=root)
    full, t_full = timed(lambda: pj.data.load_rgl(name, root=root))
    del full
    fits = {**fit_polynomials(dfit), **fit_baselines(dfit)}
    mitsuba = render_mitsuba(scene(pr.Lambertian(0.5), args.size), {"type": "measured", "filename": str(path)})
    measured = render(ChannelsLast(pj.data.read_rgl(path)), args.size)
    rows = [("measured BRDF itself (load_rgl's evaluation)", None, None, None, float(pj.psnr(measured, mitsuba)))]
    zero = l2(deval, jnp.zeros_like(deval.values))
    for label, (model, first, second) in fits.items():
        rows.append((label, l2(deval, model(deval.u, deval.v)), first, second,
                     float(pj.psnr(render(model, args.size), mitsuba))))
    return rows, zero, t_load, t_full


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit-bins", type=int, default=20000)
    ap.add_argument("--eval-bins", type=int, default=50000)
    ap.add_argument("--size", type=int, default=96, help="render width and height in pixels")
    args = ap.parse_args()
    root = pj.data_root()
    print(f"load average at start: {open('/proc/loadavg').read().split()[:3]}; devices {jax.devices()}")
    print(f"fit on {args.fit_bins} MERL-grid bins (seed 1), L2 of eq. (11) on {args.eval_bins} others (seed 0), mean "
          f"over RGB, theta <= 80 deg; sphere {args.size} x {args.size}, point light, PSNR against Mitsuba 3's "
          "render of the measured file ('measured' plugin, scalar_rgb)\n")
    for name in FILES:
        rows, zero, t_load, t_full = run_file(name, root, args)
        print(f"### {name}: L2 of the zero BRDF {zero:.4f}; load_rgl {t_load:.2f} s ({args.fit_bins} bins, first "
              f"call incl. compile), full MERL grid {t_full:.2f} s\n")
        print("| model | L2 (eq. 11) | L2 / zero | fit s (first, compiling) | fit s (compiled) | PSNR vs Mitsuba dB |")
        print("|---|---|---|---|---|---|")
        for label, err, first, second, psnr in rows:
            if err is None:
                print(f"| {label} | - | - | - | - | {psnr:.1f} |")
            else:
                print(f"| {label} | {err:.4f} | {err / zero:.3f} | {first:.2f} | {second:.3f} | {psnr:.1f} |")
        print(flush=True)
    print(f"load average at end: {open('/proc/loadavg').read().split()[:3]}")


if __name__ == "__main__":
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    main()
