r"""Images under one light sample per pixel as BRDF samples: the weighting and robust reweighting of photographs.

Under one point or directional light per image a kept pixel's radiance is ``I = c f(u, v)`` with
``c = E cos(theta_u) V`` (:mod:`polyjax.inverse._rows`), so each pixel is a sample ``b = I / c`` of the BRDF and a
fit from images is :func:`polyjax.fit_polynomial` on those samples (which takes ``link="log"`` and
``interactions``) with weights that set the space the residual is measured in (``weighting``):

- ``"radiance"``: ``sum w (I - c f)^2 = sum w c^2 (b - f)^2``, the squared error of the pixels themselves (the
  maximum-likelihood fit for noise of constant variance); ``fit_polynomial``'s weights ``w (c / cos)^2``.
- ``"brdf"``: ``sum w (b - f)^2 / max(1, cos^2(theta_u) / cos^2(80 deg))``: every pixel's BRDF sample counts
  alike up to the paper's 80-degree cutoff, and beyond it the weight falls as ``cos^2(theta_u)`` (radiance
  space), since there ``b = I / (E cos)`` multiplies the pixel's noise by ``1 / cos`` (and a plain ``1 / cos^2``
  weight reaches 1e10 at the terminator); ``fit_polynomial``'s weights ``w / max(cos, cos 80)^2``. These weights
  are the same in R, G and B (the lights' colours enter the values ``b``, not the weights), so the three channels
  share one design: one solve with three right-hand sides, streamed when tall, where radiance weights need a
  design per channel. Measured on the DiLiGenT ball (``benchmarks/bench_photometric.py``, Rusinkiewicz ``p = 8``
  with interactions, every pixel kept): held-out relative RMS 0.072 (BRDF) and 0.070 (radiance), the BRDF-space
  fit several times faster (0.39 s against 1.5 s), which buys a higher degree (``p = 10``: 0.064; with
  ``link="log"``, ``p = 8``: 0.063). Keeping the grazing pixels (no cutoff) keeps the polynomial from
  extrapolating there under other lights (with an 80-degree cutoff: 0.074 and 0.081).

**Robust reweighting** (``robust_steps > 0``): photographs hold pixels no BRDF explains: inter-reflections, cast
shadows, highlights of neighbouring objects, errors of the normals and lights, clipped values. After each fit the
pixels' relative residuals ``t = (b - f) / (|f| + m)`` (``m`` the median of ``|f|`` over the kept pixels, so dark
pixels are not all outliers; mean of ``t^2`` over the channels) are divided by a robust scale
``s = 1.4826 MAD(t)`` estimated from the data, and the next fit multiplies each pixel's weight by Tukey's
biweight ``(1 - (t / (4.685 s))^2)^2`` (0 beyond ``4.685 s``; 95% efficiency at Gaussian noise). No threshold
depends on the dataset: the scale is the data's own. Each step is one more closed-form solve; the weights are
functions of the data, so the fit stays differentiable (the median and MAD by a sort: piecewise smooth). On the
DiLiGenT ball it does not pay (0.082 against 0.072 with two steps): a convex object has no cast shadows and
little inter-reflection, and its saturated pixels (0.04%) are left out anyway; it is off by default, for captures
with cast shadows and inter-reflections.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from .._errors import InputError
from .._fit.polynomial import fit_polynomial

#: the ``weighting=`` choices of :func:`polyjax.fit_polynomial_to_images`
WEIGHTINGS = ("radiance", "brdf")
#: Tukey's biweight constant (95% asymptotic efficiency under Gaussian noise) and the MAD's consistency factor
TUKEY_C, MAD_SCALE = 4.685, 1.4826
#: ``cos(80 deg)``: below it (more grazing) ``weighting="brdf"`` weighs a sample as radiance does
BRDF_COS_FLOOR = 0.17364817766693041


def samples_of_rows(rows, weighting: str):
    """BRDF samples of :class:`polyjax.ImageRows` with one light sample per pixel: ``(u (n, 3), v (n, 3),
    values (3, n), weights ((n,) or (3, n)), mask (n,))`` (module notes)."""
    if weighting not in WEIGHTINGS:
        raise InputError(f"weighting: expected one of {WEIGHTINGS}, found {weighting!r}")
    if rows.u.shape[1] != 1:
        raise InputError(f"scenes: link='log', weighting='brdf' and robust steps need one point or directional light "
                         f"per image (one light sample per pixel), found {rows.u.shape[1]} samples per pixel: pass "
                         f"link='identity' and weighting='radiance'")
    u, c = rows.u[:, 0], rows.weight[:, 0]
    lit = rows.keep & jnp.all(c > 0, axis=-1)
    c_safe = jnp.where(lit[:, None], c, 1.0)
    cos_u = jnp.where(lit, u[:, 2], 1.0)
    values = jnp.where(lit[:, None], rows.values / c_safe, 0.0).T
    wpx = jnp.where(lit, rows.pixel_weights, 0.0)
    if weighting == "radiance":
        weights = (wpx[:, None] * (c_safe / cos_u[:, None]) ** 2).T
    else:
        weights = wpx / jnp.maximum(cos_u, BRDF_COS_FLOOR) ** 2
    return u, rows.v, values, weights, lit


def tukey_weights(model, u, v, values, mask):
    """Tukey biweight multipliers ``(n,)`` of the relative residuals of ``model`` on the samples (module notes);
    0 off ``mask``."""
    f = jnp.where(mask, model(u, v), 0.0)  # (3, n); rows off the mask never reach a NaN (nor its derivative)
    b = jnp.where(mask, values, 0.0)
    m = masked_median(jnp.mean(jnp.abs(f), axis=0), mask)
    t = jnp.sqrt(jnp.mean(((b - f) / (jnp.abs(f) + jnp.where(m > 0, m, 1.0))) ** 2, axis=0) + 1e-300)
    s = MAD_SCALE * masked_median(jnp.abs(t - masked_median(t, mask)), mask)
    z = t / (TUKEY_C * jnp.where(s > 0, s, 1.0))
    return jnp.where(mask & (z < 1), (1 - jnp.minimum(z, 1.0) ** 2) ** 2, 0.0)


def masked_median(x, mask):
    """The median of ``x`` where ``mask`` (the mean of the two middle values for an even count), by a sort: exact
    derivative almost everywhere (that of the middle values)."""
    xs = jnp.sort(jnp.where(mask, x, jnp.inf))
    k = jnp.maximum(jnp.sum(mask), 1)
    lo, hi = xs[(k - 1) // 2], xs[k // 2]
    return 0.5 * (lo + hi)


def fit_samples(rows, variables, degree, *, weighting, robust_steps, options):
    """:func:`polyjax.fit_polynomial` on the BRDF samples of ``rows`` (one light sample per pixel), then
    ``robust_steps`` reweighted fits (module notes)."""
    u, v, values, weights, mask = samples_of_rows(rows, weighting)
    model = fit_polynomial(u, v, values, variables, degree, weights=weights, mask=mask, cutoff_deg=None, **options)
    for _ in range(int(robust_steps)):
        r = _robust(model, u, v, values, mask)
        model = fit_polynomial(u, v, values, variables, degree, weights=weights * r, mask=mask, cutoff_deg=None,
                               **options)
    return model


_robust = jax.jit(tukey_weights)


__all__ = ["BRDF_COS_FLOOR", "TUKEY_C", "WEIGHTINGS", "fit_samples", "masked_median", "samples_of_rows",
           "tukey_weights"]
