"""Fits to real photographs under calibrated lights: the DiLiGenT ball, relit under lights the fit has not seen.

Claim: on the 48 lights of ``$POLYJAX_DATA/diligent/ballPNG`` split into alternate halves (even indices fitted,
odd indices held out), the best closed-form polynomial predicts the held-out photographs with a relative RMS at or
below 0.9x that of the data-driven anchor (the mean of the k = 8 nearest fitted BRDF samples in
``(theta_h, theta_d, phi_d)``), ``polyjax fit-photos``'s defaults at or below 1.0x, and a fit takes under 1 s after
compilation; in the other direction (``--fit odd``) the defaults stay bounded (clamped). Error = relative RMS of the
predicted pixel values over the mask's pixels of the held-out images (camera units; pixels with a saturated channel
left out); PSNR with the camera's white (1.0) as peak.

Compared in the same run: one Lambertian albedo (a degree-0 polynomial), a Lambertian albedo per pixel, polynomial
configurations (variables, degree, link, weighting), the nonlinear baselines by ``baselines.fit_to_images`` (on
every second pixel in each direction), and the anchor. The degree of the best fit is also chosen without the
held-out half: the fitted lights are split again into alternate halves (``_inner_choice``). The remaining error
is then split: the images' noise (from second differences of neighbouring pixels) and the lights' calibration
(the gain that best maps each prediction onto its photograph; reported for the fitted half, and for the held-out
half as a diagnosis only).

The split's other direction, ``--fit odd`` (the odd-index lights fitted, the even ones held out), checks choices made
on the first: alternate indices are alternate rows of the capture's grid of lights, so the two halves do not cover
the same directions. The even half holds the most frontal and the most oblique lights, so fitted on the odd half
every model extrapolates in ``theta_d`` (``theta_l / 2`` under the view ``(0, 0, 1)``); the table also gives the
error over the held-out lights whose polar angle lies within the fitted lights' range (all of them for ``--fit
even``), and every polynomial's error with its components clamped to the fitted box (``PolynomialBRDF.clamp``, the
same fit; ``polyjax fit-photos`` clamps by default), beside the other way of bounding it measured here: a ridge
penalty on the defaults' coefficients (refitted with numpy, ``_ridge``).

Run: ``python benchmarks/bench_photometric.py [--fit even|odd]`` (needs scipy for the nearest-neighbour anchor).
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import equinox as eqx
import jax
import numpy as np

jax.config.update("jax_enable_x64", True)

import polyjax as pj  # noqa: E402
from polyjax.cli._photos import DEFAULTS  # noqa: E402

K_NEAREST = 8
POLYNOMIALS = [  # (label, variables, degree, options)
    ("rusinkiewicz p=4, interactions, log, brdf", "rusinkiewicz", 4, dict(interactions=True, link="log",
                                                                       weighting="brdf")),
    ("lafortune p=7, radiance", "lafortune", 7, dict(weighting="radiance")),
    ("ashikhmin-shirley p=5, radiance", "ashikhmin-shirley", 5, dict(weighting="radiance")),
    ("rusinkiewicz p=8, interactions, radiance", "rusinkiewicz", 8, dict(interactions=True, weighting="radiance")),
    ("rusinkiewicz p=8, interactions, brdf + 2 robust", "rusinkiewicz", 8, dict(interactions=True, weighting="brdf",
                                                                            robust_steps=2)),
    ("rusinkiewicz p=8, interactions, log, brdf", "rusinkiewicz", 8, dict(interactions=True, link="log",
                                                                       weighting="brdf")),
    ("rusinkiewicz p=10, interactions, brdf", "rusinkiewicz", 10, dict(interactions=True, weighting="brdf")),
    ("rusinkiewicz p=12, interactions, brdf", "rusinkiewicz", 12, dict(interactions=True, weighting="brdf")),
]
#: degrees the fitted half chooses among by an inner split of its own lights (no held-out image involved)
INNER_DEGREES = (8, 10, 12)
BASELINES = ("cook-torrance", "ward")
#: closed-form fits timed as the fastest of this many calls after the compiling one (the machine is shared)
REPEATS = 3
#: ridge penalties compared with clamping (:func:`_ridge`), relative to the weighted design's largest singular value
#: squared
RIDGE = (1e-6, 1e-4, 1e-3, 1e-2)


def within_range(train, test):
    """Indices of the held-out lights whose polar angle lies within the fitted lights' range (the lights whose
    ``theta_d = theta_l / 2`` the fit covers)."""
    th_fit, th = (np.arccos(np.clip(np.asarray(c.light_directions)[:, 2], -1, 1)) for c in (train, test))
    return [i for i, t in enumerate(th) if th_fit.min() <= t <= th_fit.max()]


def held_out_errors(predicted, capture):
    """``(relative RMS, PSNR dB)`` over the held-out images' mask pixels without a saturated channel."""
    images = np.asarray(capture.images)
    keep = np.asarray(capture.mask)[None] & np.all(images < capture.saturation, axis=-1)
    d = np.asarray(predicted)[keep] - images[keep]
    rel = float(np.sqrt(np.sum(d**2) / np.sum(images[keep] ** 2)))
    return rel, float(10 * np.log10(capture.saturation**2 / np.mean(d**2)))


def timed(fn, repeats=1):
    """``(result, seconds of the fastest of `repeats` calls after a first, compiling one)``."""
    out = fn()
    jax.block_until_ready(jax.tree.leaves(out))
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        jax.block_until_ready(jax.tree.leaves(out))
        best = min(best, time.perf_counter() - t0)
    return out, best


def brdf_samples(capture, cutoff_deg=None):
    """Per kept (pixel, light): local ``u``, ``v``, light weight ``c = E cos`` and value, as numpy."""
    rows = pj.image_rows(capture.scenes, capture.images, saturation=capture.saturation, cutoff_deg=cutoff_deg)
    return (np.asarray(rows.u[:, 0]), np.asarray(rows.v), np.asarray(rows.weight[:, 0]), np.asarray(rows.values))


def rusinkiewicz(u, v):
    """``(theta_h, theta_d, phi_d mod pi)`` of local directions (Rusinkiewicz 1998)."""
    h = u + v
    h = h / np.linalg.norm(h, axis=-1, keepdims=True)
    th = np.arccos(np.clip(h[:, 2], -1, 1))
    td = np.arccos(np.clip(np.sum(u * h, -1), -1, 1))
    t = np.cross([0.0, 0.0, 1.0], h)
    tn = np.linalg.norm(t, axis=-1, keepdims=True)
    t = np.where(tn > 1e-9, t / np.maximum(tn, 1e-12), [1.0, 0.0, 0.0])
    b = np.cross(h, t)
    return np.stack([th, td, np.mod(np.arctan2(np.sum(u * b, -1), np.sum(u * t, -1)), np.pi)], -1)


def nearest_neighbour(train, test, k):
    """The anchor: each held-out pixel's BRDF value the mean of the ``k`` nearest fitted samples ``I / c`` in
    ``(theta_h, theta_d, phi_d)``, times its light weight. The samples are those within the 80-degree cutoff (with
    every sample, the noisy grazing ones, ``I / (E cos)``, raise its error from 0.076 to 0.097)."""
    from scipy.spatial import cKDTree

    u, v, c, y = brdf_samples(train, cutoff_deg=80.0)  # its better setting: grazing samples I / (E cos) are noisy
    tree = cKDTree(rusinkiewicz(u, v))
    b = y / c
    rows = pj.image_rows(test.scenes, np.zeros_like(test.images), compact=False, cutoff_deg=None)
    ut, vt, ct = np.asarray(rows.u[:, 0]), np.asarray(rows.v), np.asarray(rows.weight[:, 0])
    lit = np.tile(np.asarray(test.mask).reshape(-1), test.n_lights) & (ct.sum(-1) > 0)
    pred = np.zeros_like(ct)
    t0 = time.perf_counter()
    _, idx = tree.query(rusinkiewicz(ut[lit], vt[lit]), k=k)
    pred[lit] = ct[lit] * b[idx].mean(axis=1)
    return pred.reshape(test.images.shape), time.perf_counter() - t0


def per_pixel_albedo(train, test):
    """A Lambertian albedo per pixel and channel: least squares of ``I = rho E cos / pi`` over the fitted lights."""
    imgs, m = np.asarray(train.images), np.asarray(train.mask)
    cos = np.maximum(np.einsum("hwk,lk->lhw", train.normals, train.light_directions), 0)[..., None]
    c = cos * train.light_intensities[:, None, None, :]
    ok = (imgs < train.saturation).all(-1, keepdims=True) & (cos > 0)
    rho = np.sum(ok * c * imgs, 0) / np.maximum(np.sum(ok * c * c, 0), 1e-12)
    cos_t = np.maximum(np.einsum("hwk,lk->lhw", test.normals, test.light_directions), 0)[..., None]
    return cos_t * test.light_intensities[:, None, None, :] * rho[None] * m[None, ..., None]


def noise_estimate(capture):
    """Relative noise of the photographs from horizontal second differences ``I(x-1) - 2 I(x) + I(x+1)``
    (variance ``6 sigma^2`` for independent noise, a smooth signal's curvature adding a little): an upper bound of
    the part of the held-out error no model can predict."""
    imgs, m = np.asarray(capture.images), np.asarray(capture.mask)
    inner = m[:, :-2] & m[:, 1:-1] & m[:, 2:]
    d2 = imgs[:, :, :-2] - 2 * imgs[:, :, 1:-1] + imgs[:, :, 2:]
    ok = inner[None] & (imgs[:, :, :-2] < 1).all(-1) & (imgs[:, :, 1:-1] < 1).all(-1) & (imgs[:, :, 2:] < 1).all(-1)
    sigma2 = np.mean(d2[ok] ** 2) / 6
    keep = m[None] & (imgs < 1).all(-1)
    return float(np.sqrt(sigma2 / np.mean(imgs[keep] ** 2)))


def gain_spread(predicted, capture):
    """Per image the gain ``g = <I, P> / <P, P>`` that best scales the prediction onto the photograph: the spread
    of ``g`` estimates the lights' intensity calibration error (as a relative error of each image), and
    ``relative RMS after the gains`` what is left when it is removed."""
    imgs, p = np.asarray(capture.images), np.asarray(predicted)
    keep = np.asarray(capture.mask)[None] & (imgs < capture.saturation).all(-1)
    g = np.array([np.sum(i[k] * q[k]) / np.sum(q[k] ** 2) for i, q, k in zip(imgs, p, keep)])
    after = np.sqrt(sum(np.sum((i[k] - gi * q[k]) ** 2) for i, q, k, gi in zip(imgs, p, keep, g))
                    / np.sum(imgs[keep] ** 2))
    return g, float(after)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--fit", choices=("even", "odd"), default="even",
                    help="the half of the lights fitted (alternate indices); the other is held out")
    ap.add_argument("--quick", action="store_true",
                    help="the anchor, the defaults and the named best configuration only (no baselines, ridge, "
                         "inner split or other configurations)")
    args = ap.parse_args()
    root = pj.data_root()
    folder = os.path.join(root, "diligent", "ballPNG")
    t0 = time.perf_counter()
    capture = pj.data.load_photometric(folder).cropped()
    load_s = time.perf_counter() - t0
    first = 0 if args.fit == "even" else 1
    train, test = (capture.select(range(first, capture.n_lights, 2)),
                   capture.select(range(1 - first, capture.n_lights, 2)))
    inside = within_range(train, test)
    held = "odd" if args.fit == "even" else "even"
    print(f"# DiLiGenT ball: {capture.n_lights} lights, {int(np.sum(capture.mask))} mask pixels, cropped to "
          f"{capture.mask.shape}; fitted on {train.n_lights} {args.fit}-index lights, held out {test.n_lights} "
          f"{held}, {len(inside)} of them within the fitted lights' polar angles (load {load_s:.1f} s; load "
          f"average {os.getloadavg()[0]:.2f})", flush=True)
    table = []

    def add(label, predicted, seconds, clamped=None):
        """A row: the held-out errors of ``predicted`` and, for a polynomial, of the same fit ``clamped``."""
        rel, ps = held_out_errors(predicted, test)
        rel_in = held_out_errors(np.asarray(predicted)[inside], test.select(inside))[0]
        rel_c = float("nan") if clamped is None else held_out_errors(clamped, test)[0]
        table.append((label, rel, ps, seconds, rel_in, rel_c))
        print(f"  {label}: {rel:.4f} ({ps:.2f} dB; {rel_in:.4f} within range; clamped {rel_c:.4f}), fit "
              f"{seconds:.2f} s", flush=True)

    nn_pred, nn_s = nearest_neighbour(train, test, K_NEAREST)
    add(f"data-driven: mean of the {K_NEAREST} nearest samples (anchor)", nn_pred, nn_s)
    for k in (4, 16):
        add(f"data-driven: mean of the {k} nearest samples", nearest_neighbour(train, test, k)[0], float("nan"))
    one, s = timed(lambda: pj.fit_polynomial_to_images(train.scenes, train.images, "lafortune", 0,
                                                       saturation=1.0, cutoff_deg=None, **BASE), REPEATS)
    add("one Lambertian albedo (p = 0)", pj.relight(one, test), s)
    t0 = time.perf_counter()
    add("per-pixel Lambertian albedo", per_pixel_albedo(train, test), time.perf_counter() - t0)
    fits = _polynomials(train, test, add, quick=args.quick)
    if not args.quick:
        if fits[DEFAULT_LABEL].link == "identity":  # the ridge refit is of the identity link's least squares
            _ridge(train, test, fits[DEFAULT_LABEL], add)
        _inner_choice(train)
        _baselines(train, test, add)
    _report(table, fits, train, test)


#: the row of ``polyjax fit-photos``'s defaults (fitted as they are, clamped or not: both columns)
DEFAULT_LABEL = (f"fit-photos defaults: {DEFAULTS['variables']} p={DEFAULTS['degree']}, interactions, "
                 f"{DEFAULTS['link']}, {DEFAULTS['weighting']}")
#: the configuration named in advance as the best closed form
BEST_LABEL = "rusinkiewicz p=8, interactions, log, brdf"


#: the options every configuration of :data:`POLYNOMIALS` starts from (the API's defaults are the photographs'
#: measured choice: log link, interactions, clamped; the rows name what they change)
BASE = dict(interactions=False, link="identity", clamp=False)


def _polynomials(train, test, add, quick: bool = False) -> dict:
    """The polynomial rows: ``fit-photos``'s defaults and :data:`POLYNOMIALS`, each fitted once (timed) and relit as
    fitted (the polynomial everywhere) and clamped to its fitted box (``PolynomialBRDF.clamp``: the same fit)."""
    fits = {}
    model, s = timed(lambda: pj.fit_polynomial_to_images(train.scenes, train.images, saturation=1.0), REPEATS)
    assert model.spec == pj.PolynomialSpec(DEFAULTS["variables"], DEFAULTS["degree"], interactions=DEFAULTS[
        "interactions"], link=DEFAULTS["link"], clamp=DEFAULTS["clamp"])  # the API's defaults are the command's
    fits[DEFAULT_LABEL] = model
    add(DEFAULT_LABEL, pj.relight(dataclasses.replace(model, clamp=False),
                                                                             test), s, pj.relight(model, test))
    for label, variables, degree, opts in POLYNOMIALS:
        if quick and label != BEST_LABEL:
            continue
        model, s = timed(lambda vs=variables, p=degree, o=opts: pj.fit_polynomial_to_images(
            train.scenes, train.images, vs, p, saturation=1.0, cutoff_deg=None, **{**BASE, **o}), REPEATS)
        fits[label] = model
        add(label, pj.relight(model, test), s, pj.relight(dataclasses.replace(model, clamp=True), test))
    return fits


def _ridge(train, test, model, add):
    """The other way of bounding the defaults' fit: a ridge penalty ``lambda s_1^2 |beta|^2`` on its Legendre
    coefficients (``s_1`` the weighted design's largest singular value), refitted here with numpy (the same BRDF
    samples, BRDF-space weights, transform and design as the fit; ``lambda = 0`` is the fit itself) for each
    ``lambda`` of :data:`RIDGE`."""
    rows = pj.image_rows(train.scenes, train.images, saturation=1.0, cutoff_deg=None)
    u, c = np.asarray(rows.u[:, 0]), np.asarray(rows.weight[:, 0])
    lit = np.asarray(rows.keep) & np.all(c > 0, axis=-1)
    u, v, b = u[lit], np.asarray(rows.v)[lit], np.asarray(rows.values)[lit] / c[lit]
    root_w = u[:, 2] / np.maximum(u[:, 2], np.cos(np.deg2rad(80.0)))  # sqrt(w cos^2), w = 1 / max(cos, cos 80)^2
    x = np.asarray(pj.explanatory_variables(model.variables, u, v))
    t = ((x - np.asarray(model.mean[0])) @ np.asarray(model.rotation[0]) - np.asarray(model.centre[0])) \
        / np.asarray(model.halfwidth[0])
    d = np.asarray(pj.design_matrix(t, model.max_degree, model.basis, model.interactions))
    uu, sv, vt = np.linalg.svd(d * root_w[:, None], full_matrices=False)
    utb = uu.T @ (b * root_w[:, None])
    for lam in RIDGE:
        beta = vt.T @ (utb * (sv / (sv**2 + lam * sv[0] ** 2))[:, None])
        ridge = eqx.tree_at(lambda m: m.coefficients, model, jax.numpy.asarray(beta.T))
        add(f"fit-photos defaults with a ridge penalty, lambda = {lam:g} s_1^2", pj.relight(ridge, test),
            float("nan"), pj.relight(dataclasses.replace(ridge, clamp=True), test))


def _inner_choice(train):
    """The degree the fitted half would choose alone: its lights split again into alternate halves, each degree of
    :data:`INNER_DEGREES` fitted on one and scored on the other."""
    a, b = train.select(range(0, train.n_lights, 2)), train.select(range(1, train.n_lights, 2))
    scores = {}
    for p in INNER_DEGREES:
        model = pj.fit_polynomial_to_images(a.scenes, a.images, "rusinkiewicz", p, saturation=1.0, cutoff_deg=None,
                                            **{**BASE, "interactions": True}, weighting="brdf")
        scores[p] = held_out_errors(pj.relight(model, b), b)[0]
    print("inner split of the fitted lights (rusinkiewicz, interactions, brdf): "
          + ", ".join(f"p={p}: {e:.4f}" for p, e in scores.items()) + f"; chosen p={min(scores, key=scores.get)}",
          flush=True)


def _baselines(train, test, add):
    """The nonlinear baselines by ``baselines.fit_to_images`` on every second pixel (multi-start LM)."""
    sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))
    import baselines

    sub = train.strided(2)  # multi-start LM on a quarter of the pixels (4 starts) keeps the run's time bounded
    for name in BASELINES:
        fit, s = timed(lambda m=name: baselines.fit_to_images(m, sub.scenes, sub.images, n_starts=4, saturation=1.0,
                                                              cutoff_deg=None))
        add(f"{name} (baselines.fit_to_images, 1/4 of the pixels)", pj.relight(fit, test), s)


def _report(table, fits, train, test):
    anchor, anchor_in = table[0][1], table[0][4]
    closed = [r for r in table if not r[0].startswith(("data-driven", "cook", "ward"))]
    rows = {r[0]: r for r in table}
    default, named = rows[DEFAULT_LABEL], rows[BEST_LABEL]
    print("\n| model | held-out relative RMS | x anchor | PSNR (dB) | within the fitted polar angles (x anchor) "
          "| clamped to the fitted box (x anchor) | fit (s, after compiling) |")
    print("|---|---|---|---|---|---|---|")
    for label, rel, ps, s, rel_in, rel_c in table:
        clamped = "" if np.isnan(rel_c) else f"{rel_c:.4f} ({rel_c / anchor:.3f})"
        print(f"| {label} | {rel:.4f} | {rel / anchor:.3f} | {ps:.2f} | {rel_in:.4f} ({rel_in / anchor_in:.3f}) "
              f"| {clamped} | {'' if np.isnan(s) else f'{s:.2f}'} |")
    print(f"\nfit-photos defaults (clamped, as the command fits): {default[5] / anchor:.3f}x the anchor (target <= "
          f"1.0; not clamped {default[1] / anchor:.3f}x), fit {default[3]:.2f} s; {BEST_LABEL}: clamped "
          f"{named[5] / anchor:.3f}x (target <= 0.9; not clamped {named[1] / anchor:.3f}x), fit {named[3]:.2f} s "
          f"(target < 1 s); fastest closed-form fit {np.nanmin([r[3] for r in closed]):.2f} s")
    best = min((r for r in closed if r[0] in fits), key=lambda r: r[5])
    model = dataclasses.replace(fits[best[0]], clamp=True)
    noise = noise_estimate(test)
    g_fit, after_fit = gain_spread(pj.relight(model, train), train)
    g_test, after_test = gain_spread(pj.relight(model, test), test)
    print(f"remaining error of the best clamped fit ({best[0]}, {best[5]:.4f}): image noise ~{noise:.4f} (relative, "
          f"second differences); per-image gain spread (calibration) {np.std(g_fit):.4f} on the fitted lights, "
          f"{np.std(g_test):.4f} on the held-out ones; held-out relative RMS with each image's best gain "
          f"{after_test:.4f} (fitted half: {after_fit:.4f}); the rest: the BRDF model, normals and "
          f"inter-reflection; load average {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
