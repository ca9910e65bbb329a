"""BRDFs as the renderer sees them: callables ``f(u, v) -> (..., 3)`` linear RGB.

Every BRDF the renderer accepts is a callable taking the light direction ``u`` and the view
direction ``v`` as ``(..., 3)`` unit vectors in the local shading frame (normal ``+z``, see
:mod:`polyjax._directions`) and returning ``(..., 3)`` RGB values (or ``(...)`` grey values,
broadcast to the three channels). Fitted models, measured data and analytic BRDFs are all
wrapped into this one protocol by :func:`rgb_brdf`.

Light transport uses ``max(f, 0)`` (:func:`transported`, applied by :func:`evaluate_rgb`): a fitted model (a
polynomial, above all) can be negative where the data has a narrow peak or no samples, and a negative BRDF would
emit negative radiance. The model's own values (``model(u, v)``) are not clamped.
"""

from __future__ import annotations

from typing import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._arrays import is_traced
from .._directions import reflect, safe_normalize
from .._errors import InputError
from .._model import PolynomialBRDF

BRDF = Callable[[Array, Array], Array]


def _above(u, v):
    return (u[..., 2] > 0) & (v[..., 2] > 0)


def transported(f, maximum=jnp.maximum, zero=0.0):
    """The BRDF light is transported with, ``max(f, 0)``: the one definition behind the renderer
    (:func:`evaluate_rgb`), the importance sampler's tables (through :func:`evaluate_rgb`) and every export (the
    expression program of :mod:`polyjax.export._expr` calls it with its own ``max`` and constant 0).

    Args:
        f: BRDF values (any array, or an expression of the export program).
        maximum: the two-argument maximum of ``f``'s kind (``jnp.maximum`` for arrays).
        zero: the 0 of ``f``'s kind.
    """
    return maximum(f, zero)


def evaluate_rgb(brdf: BRDF, u: Array, v: Array) -> Float[Array, "... 3"]:
    """Evaluate ``brdf``, bring the result to ``(..., 3)`` and clamp it at 0: ``max(f(u, v), 0)``.

    This is the BRDF the renderer transports light with: a fitted model that goes negative
    somewhere reflects nothing there instead of emitting negative radiance. The gradient is that
    of ``f`` where ``f > 0`` and 0 where it is clamped.

    Accepts outputs of shape ``(..., 3)`` (RGB) or ``(...)`` (grey, repeated in R, G and B).

    Raises:
        InputError: the output has any other shape (e.g. a leading channel axis; wrap such
            models with :func:`rgb_brdf` or :class:`ChannelsFirst`).
    """
    shape = jnp.broadcast_shapes(u.shape, v.shape)[:-1]
    out = jnp.asarray(brdf(u, v))
    if out.shape == shape + (3,):
        return transported(out)
    if out.shape == shape:
        return jnp.broadcast_to(transported(out)[..., None], shape + (3,))
    raise InputError(
        f"brdf {type(brdf).__name__}: expected an output of shape {shape + (3,)} (RGB) or {shape} (grey) "
        f"for directions of shape {shape + (3,)}, found {out.shape}; wrap models with a leading channel "
        "axis in polyjax.render.ChannelsFirst"
    )


class ChannelsFirst(eqx.Module):
    """Adapter for a BRDF whose output has a leading channel axis, ``(C, ...)`` with ``C`` in {1, 3}.

    A :class:`polyjax.PolynomialBRDF` fitted to RGB data has batch shape ``(3,)`` and returns
    ``(3, ...)``; this module returns ``(..., 3)`` (``C = 1`` is repeated into grey RGB).
    """

    brdf: BRDF

    def __call__(self, u: Array, v: Array) -> Float[Array, "... 3"]:
        return _channels_last(self.brdf, u, v)


@eqx.filter_jit
def _channels_last(brdf, u, v):
    """:class:`ChannelsFirst`'s evaluation, one compiled program per model family and shapes."""
    out = jnp.asarray(brdf(u, v))
    out = jnp.moveaxis(out, 0, -1)
    return jnp.broadcast_to(out, out.shape[:-1] + (3,))


class SwapUV(eqx.Module):
    """The BRDF with light and view exchanged, ``f'(u, v) = f(v, u)``.

    Rendering a scene with ``SwapUV(f)`` instead of ``f`` is the reciprocity check of the paper's
    Fig. 8: a reciprocal BRDF (Helmholtz, ``f(u, v) = f(v, u)``) gives the same image.
    """

    brdf: BRDF

    def __call__(self, u: Array, v: Array) -> Array:
        return self.brdf(v, u)


def rgb_brdf(model) -> BRDF:
    """Wrap anything BRDF-like into the renderer's protocol ``f(u, v) -> (..., 3)``.

    - a :class:`polyjax.PolynomialBRDF`, or any fitted model with a ``batch_shape`` (e.g. a
      ``baselines.BaselineFit``), with batch shape ``()``, ``(1,)`` or ``(3,)`` (grey or channels):
      wrapped in :class:`ChannelsFirst` when it has a channel axis. Other batch shapes (e.g.
      materials) must be indexed first (``model[i]``).
    - any other callable (analytic BRDFs, :class:`TabulatedBRDF`, ``polyjax.data.NeuralBRDF``)
      is returned unchanged; its output is checked when it is evaluated.

    Raises:
        InputError: a polynomial model with a batch shape other than ``()``, ``(1,)``, ``(3,)``.
    """
    if isinstance(model, PolynomialBRDF) or isinstance(getattr(model, "batch_shape", None), tuple):
        bs = tuple(model.batch_shape)
        if bs == ():
            return model
        if bs in ((1,), (3,)):
            return ChannelsFirst(model)
        raise InputError(
            f"model: expected a fitted model with batch shape () or (1,) or (3,) (channels), found {bs}; "
            "select one material first, e.g. model[i]"
        )
    if not callable(model):
        raise InputError(f"model: expected a callable f(u, v) -> (..., 3), found {type(model).__name__}")
    return model


class ParametricBRDF(eqx.Module):
    """A BRDF given as a function of parameters: ``f(u, v) = fn(params, u, v)``.

    ``params`` is any pytree of arrays (the pytree leaves of this module), so ``jax.grad`` of a
    render with respect to a scene holding this BRDF gives the derivative with respect to them
    (e.g. ``eqx.filter_grad``, or build the scene inside the differentiated function).

    Attributes:
        fn: ``fn(params, u, v) -> (..., 3)`` or ``(...)`` (static).
        params: the parameters.
    """

    fn: Callable = eqx.field(static=True)
    params: object

    def __call__(self, u: Array, v: Array) -> Array:
        return self.fn(self.params, u, v)


class Lambertian(eqx.Module):
    r"""The ideal diffuse BRDF ``f = albedo / pi`` (above the horizon, 0 below).

    Attributes:
        albedo: ``(3,)`` RGB (or scalar) reflectance in ``[0, 1]``.
    """

    albedo: Float[Array, "3"]

    def __init__(self, albedo: ArrayLike = 0.8):
        self.albedo = jnp.broadcast_to(jnp.asarray(albedo, dtype=float), (3,))

    def __call__(self, u: Array, v: Array) -> Float[Array, "... 3"]:
        above = _above(u, v)
        return jnp.where(above[..., None], self.albedo / jnp.pi, 0.0)


class Phong(eqx.Module):
    r"""The energy-normalised, reciprocal modified Phong BRDF (Lewis 1994):

    ``f = kd / pi + ks (n + 2) / (2 pi) max(0, R(u) . v)^n`` with ``R(u) = (-u_x, -u_y, u_z)``.
    Since ``R(u) . v = R(v) . u`` it is reciprocal.

    Attributes:
        kd, ks: ``(3,)`` diffuse and specular RGB reflectances.
        exponent: the lobe exponent ``n``.
    """

    kd: Float[Array, "3"]
    ks: Float[Array, "3"]
    exponent: Float[Array, ""]

    def __init__(self, kd: ArrayLike = 0.5, ks: ArrayLike = 0.3, exponent: ArrayLike = 30.0):
        self.kd = jnp.broadcast_to(jnp.asarray(kd, dtype=float), (3,))
        self.ks = jnp.broadcast_to(jnp.asarray(ks, dtype=float), (3,))
        self.exponent = jnp.asarray(exponent, dtype=float)

    def __call__(self, u: Array, v: Array) -> Float[Array, "... 3"]:
        c = jnp.maximum(jnp.sum(reflect(u) * v, axis=-1), 0.0)
        lobe = (self.exponent + 2.0) / (2.0 * jnp.pi) * c ** self.exponent
        f = self.kd / jnp.pi + self.ks * lobe[..., None]
        return jnp.where(_above(u, v)[..., None], f, 0.0)


class TabulatedBRDF(eqx.Module):
    r"""Measured samples ``(u_i, v_i, b_i)`` interpolated into a BRDF (e.g. CUReT's 205 samples).

    Interpolation is inverse-distance weighting over the ``k`` nearest samples,
    ``f(u, v) = sum_j w_j b_j / sum_j w_j`` with ``w_j = 1 / (d_j^2 + eps)``, in a *reciprocal*
    parametrisation: every sample also counts at its swapped position ``(v_i, u_i)``, so
    ``f(u, v) = f(v, u)`` (up to rounding). Distances are between feature vectors:

    - ``isotropic=False``: ``(u, v)`` in R^6 (``d^2 = |u - u_i|^2 + |v - v_i|^2``);
    - ``isotropic=True``: the rotation-invariant ``(cos theta_u, cos theta_v, u . v)``, so a
      sample also stands for every rotation of its configuration about the normal.

    ``k = 1`` is nearest-neighbour lookup. Below the horizon the BRDF is 0.

    Attributes:
        features: ``(2n, d)`` sample features (direct and swapped).
        values: ``(2n, 3)`` sample values (RGB).
        k: neighbours used; isotropic: the parametrisation.
    """

    features: Float[Array, "m d"]
    values: Float[Array, "m 3"]
    k: int = eqx.field(static=True)
    isotropic: bool = eqx.field(static=True)
    eps: float = eqx.field(static=True)

    def __init__(self, u: ArrayLike, v: ArrayLike, values: ArrayLike, *, k: int = 4, isotropic: bool = True,
                 eps: float = 1e-6):
        """Args:
        u, v: ``(n, 3)`` light and view directions of the samples.
        values: ``(n,)`` grey, ``(n, 3)`` or ``(3, n)`` RGB values; non-finite samples are dropped.
        k: number of nearest samples to blend (at most ``n``).
        isotropic: use the rotation-invariant parametrisation.
        eps: regulariser of the weights (squared feature distance).
        """
        if is_traced(u, v, values):
            self._init_traced(u, v, values, k, isotropic, eps)
            return
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        b = np.asarray(values, dtype=float)
        if u.ndim != 2 or u.shape[-1] != 3 or v.shape != u.shape:
            raise InputError(f"u, v: expected two (n, 3) arrays of the same shape, found {u.shape} and {v.shape}")
        n = u.shape[0]
        if b.shape == (n,):
            b = np.repeat(b[:, None], 3, axis=1)
        elif b.shape == (3, n) and b.shape != (n, 3):
            b = b.T
        elif b.shape != (n, 3):
            raise InputError(f"values: expected (n,), (n, 3) or (3, n) with n = {n}, found {b.shape}")
        keep = np.all(np.isfinite(b), axis=1) & np.all(np.isfinite(u), axis=1) & np.all(np.isfinite(v), axis=1)
        if not keep.any():
            raise InputError("values: expected at least one finite sample, found none")
        u, v, b = u[keep], v[keep], b[keep]
        u = u / np.linalg.norm(u, axis=1, keepdims=True)
        v = v / np.linalg.norm(v, axis=1, keepdims=True)
        fa = self._features_np(u, v, isotropic)
        fb = self._features_np(v, u, isotropic)
        self.features = jnp.asarray(np.concatenate([fa, fb]))
        self.values = jnp.asarray(np.concatenate([b, b]))
        self.k = int(min(max(k, 1), 2 * len(b)))
        self.isotropic = bool(isotropic)
        self.eps = float(eps)

    def _init_traced(self, u, v, values, k, isotropic, eps):
        """Inside ``jit``/``grad``: shapes are checked, every sample is kept (non-finite ones are not dropped,
        which would need their count), and the table stays differentiable in ``u``, ``v`` and ``values``."""
        u, v, b = jnp.asarray(u), jnp.asarray(v), jnp.asarray(values)
        if u.ndim != 2 or u.shape[-1] != 3 or v.shape != u.shape:
            raise InputError(f"u, v: expected two (n, 3) arrays of the same shape, found {u.shape} and {v.shape}")
        n = u.shape[0]
        if b.shape == (n,):
            b = jnp.repeat(b[:, None], 3, axis=1)
        elif b.shape == (3, n) and b.shape != (n, 3):
            b = b.T
        elif b.shape != (n, 3):
            raise InputError(f"values: expected (n,), (n, 3) or (3, n) with n = {n}, found {b.shape}")
        u, _ = safe_normalize(u)
        v, _ = safe_normalize(v)
        fa = self._features_jnp(u, v, isotropic)
        fb = self._features_jnp(v, u, isotropic)
        self.features = jnp.concatenate([fa, fb])
        self.values = jnp.concatenate([b, b])
        self.k = int(min(max(k, 1), 2 * n))
        self.isotropic = bool(isotropic)
        self.eps = float(eps)

    @staticmethod
    def _features_jnp(u, v, isotropic):
        if isotropic:
            return jnp.stack([u[:, 2], v[:, 2], jnp.sum(u * v, axis=1)], axis=1)
        return jnp.concatenate([u, v], axis=1)

    @staticmethod
    def _features_np(u, v, isotropic):
        if isotropic:
            return np.stack([u[:, 2], v[:, 2], np.sum(u * v, axis=1)], axis=1)
        return np.concatenate([u, v], axis=1)

    def __call__(self, u: Array, v: Array) -> Float[Array, "... 3"]:
        u, _ = safe_normalize(u)
        v, _ = safe_normalize(v)
        u, v = jnp.broadcast_arrays(u, v)
        if self.isotropic:
            q = jnp.stack([u[..., 2], v[..., 2], jnp.sum(u * v, axis=-1)], axis=-1)
        else:
            q = jnp.concatenate([u, v], axis=-1)
        feats = self.features.astype(q.dtype)
        d2 = jnp.sum(q * q, -1)[..., None] - 2.0 * q @ feats.T + jnp.sum(feats * feats, -1)
        d2 = jnp.maximum(d2, 0.0)
        neg, idx = jax.lax.top_k(-d2, self.k)
        w = 1.0 / (-neg + self.eps)
        vals = self.values.astype(q.dtype)[idx]  # (..., k, 3)
        f = jnp.sum(w[..., None] * vals, axis=-2) / jnp.sum(w, axis=-1, keepdims=True)
        return jnp.where(_above(u, v)[..., None], f, 0.0)


__all__ = [
    "BRDF", "ChannelsFirst", "Lambertian", "ParametricBRDF", "Phong", "SwapUV", "TabulatedBRDF", "evaluate_rgb",
    "rgb_brdf",
]
