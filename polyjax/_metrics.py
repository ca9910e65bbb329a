"""The error metrics models are scored with: equation (11) of the paper (:func:`l2_error`) and its log-space
form (:func:`log_error`), close to what the eye sees."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._directions import cos_theta, cutoff_mask
from ._errors import InputError


def fit_weights(
    u: ArrayLike,
    v: ArrayLike,
    weights: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    cutoff_deg: float | None = 80.0,
) -> tuple[Float[Array, "*batch n"], Float[Array, "*batch n"]]:
    """Per-sample weights of the Ngan et al. objective (paper, equation (11)).

    Returns:
        ``(w, wc2)``: ``w_i`` (the solid-angle weight, zero for dropped samples) and
        ``w_i cos^2(theta_u,i)``, the weight on the squared residual. Samples with
        ``theta_u`` or ``theta_v`` above ``cutoff_deg``, below the horizon or masked out get 0.
    """
    as_array = (lambda a: a if a is None else jnp.asarray(a))  # noqa: E731
    return _fit_weights(jnp.asarray(u), jnp.asarray(v), as_array(weights), as_array(mask), cutoff_deg)


@jax.jit
def _fit_weights(u, v, weights, mask, cutoff_deg):
    """:func:`fit_weights` in one compiled program (``None`` arguments are part of its structure)."""
    keep = cutoff_mask(u, v, cutoff_deg)
    w = jnp.ones(keep.shape, dtype=u.dtype) if weights is None else jnp.asarray(weights, dtype=u.dtype)
    w = jnp.where(keep, w, 0.0)
    if mask is not None:
        w = jnp.where(jnp.asarray(mask), w, 0.0)
    cu = jnp.where(keep, cos_theta(u), 0.0)
    return w, w * cu * cu


def _check_l2_shapes(values, predicted, u_shape, v_shape, weights, mask) -> None:
    """Shape errors of :func:`l2_error` named by argument (instead of a broadcasting error from JAX)."""
    for name, shape in (("u", u_shape), ("v", v_shape)):
        if len(shape) != 2 or shape[-1] != 3:
            raise InputError(f"{name}: expected directions of shape (n, 3), found {tuple(shape)}")
    if tuple(u_shape) != tuple(v_shape):
        raise InputError(f"u and v: expected the same shape (n, 3), found {tuple(u_shape)} and {tuple(v_shape)}")
    n = u_shape[0]
    if values.ndim < 1 or values.shape[-1] != n:
        raise InputError(f"values: expected shape (..., {n}) with samples last (n = len(u)), found {values.shape}")
    for name, a in (("predicted", predicted), ("weights", weights), ("mask", mask)):
        if a is None:
            continue
        shape = tuple(jnp.shape(a))
        try:
            np.broadcast_shapes(shape, values.shape)
        except ValueError:
            raise InputError(
                f"{name}: expected a shape that broadcasts with values' {values.shape}, found {shape}") from None


def l2_error(
    values: ArrayLike,
    predicted: ArrayLike,
    u: ArrayLike,
    v: ArrayLike,
    weights: ArrayLike | None = None,
    cutoff_deg: float | None = 80.0,
    mask: ArrayLike | None = None,
) -> Float[Array, "*batch"]:
    r"""The L2 error of equation (11) (Ngan, Durand, Matusik 2005):

    .. math::
        \varphi = \Big[\frac{\sum_i w_i\,[\cos\theta_{u,i}\,(b_i - f_i)]^2}{\sum_i w_i}\Big]^{1/2}

    over the samples with both ``theta_u`` and ``theta_v`` at most ``cutoff_deg``.

    Args:
        values: measured ``b``, shape ``(*batch, n)``.
        predicted: model values ``f``, broadcastable to ``values``.
        u, v: ``(n, 3)`` light and view directions.
        weights: solid-angle weights ``w_i``, ``(n,)`` or ``(*batch, n)``; ones when None.
        cutoff_deg: the grazing cutoff (80 degrees in the paper); None keeps all samples above the horizon.
        mask: optional ``(*batch, n)`` validity mask (invalid samples are ignored).

    Returns:
        ``phi`` per batch element. ``inf`` where no sample is kept (never NaN); non-finite
        values or predictions at kept samples are ignored only if masked, otherwise they give ``inf``.
    """
    values = jnp.asarray(values)
    predicted = jnp.asarray(predicted)
    _check_l2_shapes(values, predicted, jnp.shape(u), jnp.shape(v), weights, mask)
    return _l2_core(values, predicted, jnp.asarray(u), jnp.asarray(v), weights, mask, cutoff_deg=cutoff_deg)


@functools.partial(jax.jit, static_argnames=("cutoff_deg",))
def _l2_core(values, predicted, u, v, weights, mask, *, cutoff_deg):
    """Equation (11) in one compiled program (op by op it was about twenty, each lowered anew in every process)."""
    w, wc2 = fit_weights(u, v, weights, mask, cutoff_deg)
    return l2_from_weights(values, predicted, w, wc2)


def l2_from_weights(values, predicted, w, wc2):
    """Equation (11) given the weights ``(w, w cos^2 theta_u)`` of :func:`fit_weights` (a fit that scores many
    predictions of the same samples makes them once): :func:`l2_error`'s arithmetic."""
    r = jnp.where(wc2 > 0, values - predicted, 0.0)
    num = jnp.sum(wc2 * r * r, axis=-1)
    den = jnp.sum(jnp.broadcast_to(w, jnp.broadcast_shapes(w.shape, r.shape)), axis=-1)
    num = jnp.where(jnp.isnan(num), jnp.inf, num)
    nz = (den > 0) & (num != 0)  # sqrt has no derivative at 0: no kept sample or a perfect fit gets 0, not NaN
    l2 = jnp.where(nz, jnp.sqrt(jnp.where(nz, num, 1.0) / jnp.where(nz, den, 1.0)), 0.0)
    return jnp.where(den > 0, l2, jnp.inf)


def log_error(
    values: ArrayLike,
    predicted: ArrayLike,
    u: ArrayLike,
    v: ArrayLike,
    weights: ArrayLike | None = None,
    cutoff_deg: float | None = None,
    mask: ArrayLike | None = None,
) -> Float[Array, "*batch"]:
    r"""The log-space error, a metric close to what the eye sees of a BRDF (dark and bright parts alike):

    .. math::
        \varphi_{\log} = \Big[\frac{\sum_i w_i\,\big(\log(1 + f_i^+ \cos\theta_{u,i})
            - \log(1 + b_i^+ \cos\theta_{u,i})\big)^2}{\sum_i w_i}\Big]^{1/2}

    over the samples above the horizon (every one by default: no grazing cutoff), ``x^+ = max(x, 0)`` (a renderer
    shows a negative value as black). Over R, G, B lanes of one material the issue-style metric
    ``sqrt(sum w r^2 / (3 sum w))`` is ``sqrt(mean(log_error**2))`` over the three channels (equal weights).

    Args:
        values: measured ``b``, shape ``(*batch, n)``.
        predicted: model values ``f``, broadcastable to ``values``.
        u, v: ``(n, 3)`` light and view directions.
        weights: solid-angle weights ``w_i``, ``(n,)`` or ``(*batch, n)``; ones when None.
        cutoff_deg: a grazing cutoff as in :func:`l2_error`; None (the default) keeps every sample above the horizon.
        mask: optional ``(*batch, n)`` validity mask.

    Returns:
        ``phi_log`` per batch element; ``inf`` where no sample is kept or a kept prediction is not finite.
    """
    values = jnp.asarray(values)
    predicted = jnp.asarray(predicted)
    _check_l2_shapes(values, predicted, jnp.shape(u), jnp.shape(v), weights, mask)
    return _log_core(values, predicted, jnp.asarray(u), jnp.asarray(v), weights, mask, cutoff_deg=cutoff_deg)


@functools.partial(jax.jit, static_argnames=("cutoff_deg",))
def _log_core(values, predicted, u, v, weights, mask, *, cutoff_deg):
    """:func:`log_error` in one compiled program: equation (11)'s arithmetic on log-compressed values with the
    weights ``w`` (not ``w cos^2``: the cosine is inside the logarithm)."""
    w, _ = fit_weights(u, v, weights, mask, cutoff_deg)
    cu = jnp.clip(cos_theta(u), 0.0, None)
    keep = w > 0
    lf = jnp.log1p(jnp.where(keep, jnp.maximum(predicted, 0.0), 0.0) * cu)
    lb = jnp.log1p(jnp.where(keep, jnp.maximum(values, 0.0), 0.0) * cu)
    return l2_from_weights(lb, lf, w, w)


def psnr(
    image: ArrayLike, reference: ArrayLike, peak: float | None = None, mask: ArrayLike | None = None,
) -> Float[Array, ""]:
    r"""Peak signal-to-noise ratio in dB, ``10 log10(peak^2 / MSE)``.

    Args:
        image, reference: arrays of the same shape (e.g. ``(H, W, 3)``).
        peak: the signal peak; defaults to the maximum of ``reference`` (1.0 for tone-mapped images in [0, 1]).
        mask: optional pixel mask (broadcastable to the images); only those pixels count.

    Returns:
        PSNR in dB; ``inf`` for identical images.
    """
    return _psnr(jnp.asarray(image), jnp.asarray(reference), peak, None if mask is None else jnp.asarray(mask))


@jax.jit
def _psnr(a, b, peak, mask):
    """:func:`psnr` in one compiled program."""
    shape = jnp.broadcast_shapes(a.shape, b.shape)
    m = jnp.ones(shape, bool) if mask is None else jnp.broadcast_to(jnp.asarray(mask), shape)
    d = jnp.where(m, a - b, 0.0)
    mse = jnp.sum(d * d) / jnp.maximum(jnp.sum(m), 1)
    p = jnp.max(jnp.where(m, b, -jnp.inf)) if peak is None else jnp.asarray(peak, dtype=d.dtype)
    return jnp.where(mse > 0, 10.0 * jnp.log10(p * p / jnp.where(mse > 0, mse, 1.0)), jnp.inf)
