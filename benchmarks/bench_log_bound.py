"""The log link's bound: a polynomial fitted to few photographs, relit under the lights between them.

Claim: with the bound ``f = exp(min(P, log_top)) - eps`` (``log_top`` the largest ``P`` at the fitted samples:
``PolynomialBRDF.log_top``), ``pj.fit_polynomial_to_images`` at ``p = 8`` (Rusinkiewicz with interactions, log link,
clamped: the defaults' top degree) no longer blows up between few lights: with 6 or 8 fitted lights on every
DiLiGenT object its largest relit value stays within 6x the largest held-out pixel (unbounded: up to 2e29 times),
and its held-out error falls from up to 3e27 to 1.1-19; where the unbounded fit was sound (12 lights and more) the
bound changes nothing (ratio 1.000). The bound stops the blow-up, not the swings beneath it: the default
``degree="auto"`` (the highest well-conditioned degree up to 8, :mod:`polyjax.inverse._degree`; ``fit-photos``
without ``--degree``) stays 3-50x better than the bounded ``p = 8`` with 6 or 8 lights, and keeps 8 where it is well
conditioned.

Compared in one run, on the same fits: the bounded model, the same model without its bound
(``dataclasses.replace(model, log_top=None)``) and the default fit, ``degree="auto"`` (bounded too; its time against
the one fit at ``p = 8``: the step-down fits every degree it leaves out, on the image rows made once; both timed
on a second call, their programs compiled). For each
object (the ball: 48 lights, 16-bit; the five crop8 objects: 96 lights, 8-bit, their scanned normals) ``L`` lights
are fitted (every ``n / L``-th, from the first) and the ``L`` lights half-way between them held out; the error is
the relative RMS over the mask's pixels without a saturated channel, as ``polyjax relight`` prints it. Also printed:
the largest relit value over the largest held-out pixel value (a blow-up shows as a ratio far above 1).

Run: ``python benchmarks/bench_log_bound.py [--objects ball cat ...] [--lights 6 8 12 24]``.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import time

import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import polyjax as pj  # noqa: E402
from polyjax.cli._photos import DEFAULTS, errors_of  # noqa: E402

OBJECTS = ("ball", "cat", "pot1", "bear", "goblet", "pot2")


def folder(name: str) -> str:
    root = os.path.join(pj.data_root(), "diligent")
    return os.path.join(root, "ballPNG") if name == "ball" else os.path.join(root, "crop8", f"{name}PNG")


def split(capture, n_fit: int):
    """The ``n_fit`` lights fitted (every ``n / n_fit``-th) and the ``n_fit`` half-way between them held out."""
    step = capture.n_lights // n_fit
    return capture.select(range(0, capture.n_lights, step)), capture.select(range(step // 2, capture.n_lights, step))


def relit(model, test):
    predicted = np.asarray(pj.relight(model, test))
    images = np.asarray(test.images)
    keep = np.asarray(test.mask)[None] & np.all(images < test.saturation, axis=-1)
    return errors_of(predicted, test)[1], float(np.max(predicted[keep]) / np.max(images[keep]))


def timed(train, **options):
    """The fit of the lights ``train`` with ``options`` and the seconds of its second call (the first compiles)."""
    def fit():
        return pj.fit_polynomial_to_images(train.scenes, train.images, saturation=1.0, **options)

    jax.block_until_ready(fit().coefficients)
    t0 = time.perf_counter()
    model = fit()
    jax.block_until_ready(model.coefficients)
    return model, time.perf_counter() - t0


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", nargs="+", default=list(OBJECTS), choices=OBJECTS)
    ap.add_argument("--lights", nargs="+", type=int, default=[6, 8, 12, 24])
    args = ap.parse_args()
    spec = pj.PolynomialSpec(DEFAULTS["variables"], 8, interactions=DEFAULTS["interactions"],
                             link=DEFAULTS["link"], clamp=DEFAULTS["clamp"])
    print(f"# {spec}; load average {os.getloadavg()[0]:.2f}", flush=True)
    print("| object, lights | p = 8 unbounded: error, max ratio | p = 8 bounded: error, max ratio | bounded / "
          "unbounded | `degree=\"auto\"` (bounded): degree, error | auto / bounded p = 8 | p = 8 fit s (warm) | "
          "auto s / p = 8 s |")
    print("|---|---|---|---|---|---|---|---|")
    for name in args.objects:
        jax.clear_caches()  # each object's shapes compile their own programs: a process keeping them all reaches
        # the kernel's limit on memory maps (about 3 per compiled CPU program; tests/conftest.py)
        capture = pj.data.load_photometric(folder(name)).cropped()
        for n_fit in args.lights:
            train, test = split(capture, n_fit)
            model, seconds = timed(train, spec=spec)
            assert model.log_top is not None
            free, free_max = relit(dataclasses.replace(model, log_top=None), test)
            bound, bound_max = relit(model, test)
            kept, auto_s = timed(train)
            assert kept.spec == dataclasses.replace(spec, degree=kept.max_degree)  # degree="auto", the default
            step, _ = relit(kept, test)
            print(f"| {name}, {n_fit} | {free:.4g}, {free_max:.3g} | {bound:.4g}, {bound_max:.3g} | "
                  f"{bound / free:.3f} | {kept.max_degree}, {step:.4g} | {step / bound:.2f} | {seconds:.1f} | "
                  f"{auto_s / seconds:.2f} |", flush=True)


if __name__ == "__main__":
    main()
