"""Directions in the local shading frame.

Convention used throughout polyjax: unit vectors ``(..., 3)`` in the local frame with the
surface normal ``n = +z`` and ``x``, ``y`` the principal directions of anisotropy. ``u`` is the
light (incoming) direction and ``v`` the view (outgoing) direction, both pointing away from
the surface. Spherical angles: ``theta`` from the normal, ``phi`` azimuth from ``+x``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from ._errors import InputError

_EPS = 1e-12


def spherical_to_cartesian(theta: ArrayLike, phi: ArrayLike) -> Float[Array, "... 3"]:
    """Unit vector ``(sin t cos p, sin t sin p, cos t)`` from polar angle ``theta`` and azimuth ``phi`` (radians)."""
    theta = jnp.asarray(theta)
    phi = jnp.asarray(phi)
    st = jnp.sin(theta)
    return jnp.stack([st * jnp.cos(phi), st * jnp.sin(phi), jnp.cos(theta)], axis=-1)


def cartesian_to_spherical(w: ArrayLike) -> tuple[Float[Array, "..."], Float[Array, "..."]]:
    """Inverse of :func:`spherical_to_cartesian` for unit vectors: returns ``(theta, phi)``, phi in (-pi, pi]."""
    w = jnp.asarray(w)
    theta = jnp.arccos(jnp.clip(w[..., 2], -1.0, 1.0))
    phi = jnp.arctan2(w[..., 1], w[..., 0])
    return theta, phi


def safe_normalize(w: ArrayLike) -> tuple[Float[Array, "... 3"], Bool[Array, "..."]]:
    """Normalise vectors; zero (or non-finite) vectors become ``+z`` and are reported invalid.

    Vectors shorter than ``1e-12`` count as having no direction. The length is computed after
    dividing by the largest component, so vectors of any finite length (``1e200``, or ``1e30``
    in float32, whose squared length overflows) are normalised too.

    Returns:
        ``(unit, valid)``: unit vectors and a mask that is False where the input had no direction.
    """
    return _safe_normalize(jnp.asarray(w))


@jax.jit
def _safe_normalize(w):
    # one compiled pass: op by op on a million rows (a MERL grid) it cost ~0.1 s per call
    finite = jnp.all(jnp.isfinite(w), axis=-1)
    big = jnp.max(jnp.abs(jnp.where(finite[..., None], w, 0.0)), axis=-1, keepdims=True)
    scaled = jnp.where(big > 0, w / jnp.where(big > 0, big, 1.0), 0.0)
    norm = jnp.sqrt(jnp.sum(scaled * scaled, axis=-1, keepdims=True))  # in [1, sqrt(3)] where big > 0
    valid = finite & (big[..., 0] * norm[..., 0] > _EPS)
    z = jnp.zeros_like(w).at[..., 2].set(1.0)
    unit = jnp.where(valid[..., None], scaled / jnp.where(valid[..., None], norm, 1.0), z)
    return unit, valid


def half_vector(u: ArrayLike, v: ArrayLike) -> Float[Array, "... 3"]:
    """Half vector ``h = (u + v) / |u + v|``.

    Where ``u = -v`` the sum vanishes and ``h`` is undefined; the normal ``+z`` is returned
    there, so downstream quantities stay finite.
    """
    h, _ = safe_normalize(jnp.asarray(u) + jnp.asarray(v))
    return h


def cos_theta(w: ArrayLike) -> Float[Array, "..."]:
    """``n . w`` with ``n = +z``."""
    return jnp.asarray(w)[..., 2]


def reflect(w: ArrayLike) -> Float[Array, "... 3"]:
    """Mirror direction about the normal: ``(-x, -y, z)``."""
    w = jnp.asarray(w)
    return w * jnp.array([-1.0, -1.0, 1.0], dtype=w.dtype)


def cutoff_mask(u: ArrayLike, v: ArrayLike, cutoff_deg: float | None = 80.0) -> Bool[Array, "..."]:
    """Samples kept by the Ngan et al. rule: both ``theta_u`` and ``theta_v`` at most ``cutoff_deg``.

    Directions below the horizon (``cos theta <= 0``) are always dropped. ``cutoff_deg=None``
    keeps every sample above the horizon. A sample exactly at the cutoff is kept: the comparison
    ``cos theta >= cos(cutoff) - tol`` uses ``tol = max(1e-9, 4 eps)`` of the directions' dtype, so
    float32 and float64 keep the same samples (MERL's grid has bins at exactly 80 degrees).
    """
    return _cutoff_mask(jnp.asarray(u), jnp.asarray(v), cutoff_deg)


@jax.jit
def _cutoff_mask(u, v, cutoff_deg):
    """:func:`cutoff_mask` in one compiled program (``cutoff_deg`` None is part of its structure)."""
    cu = cos_theta(u)
    cv = cos_theta(v)
    keep = (cu > 0) & (cv > 0)
    if cutoff_deg is not None:
        dtype = jnp.result_type(cu)
        c = jnp.cos(jnp.deg2rad(jnp.asarray(cutoff_deg, dtype=dtype)))
        # a tolerance so that samples measured exactly at the cutoff angle are kept: 1e-9, or a few
        # units in the last place when the precision is coarser (float32), so both precisions agree
        tol = max(1e-9, 4 * float(jnp.finfo(dtype).eps)) if jnp.issubdtype(dtype, jnp.floating) else 1e-9
        keep = keep & (cu >= c - tol) & (cv >= c - tol)
    return keep


def call_directions(u: ArrayLike, v: ArrayLike, dtype) -> tuple:
    """A model call's directions checked before any work: ``(..., 3)`` each and broadcasting together (a JAX array,
    traced or not, is kept; anything else becomes a numpy array of ``dtype``). Raises ``InputError`` naming
    ``u, v`` otherwise."""
    u, v = (a if isinstance(a, jax.Array) else np.asarray(a, dtype) for a in (u, v))
    if u.ndim < 1 or v.ndim < 1 or u.shape[-1] != 3 or v.shape[-1] != 3:
        raise InputError(f"u, v: expected directions of shape (..., 3), found {u.shape} and {v.shape}")
    try:
        np.broadcast_shapes(u.shape, v.shape)
    except ValueError:
        raise InputError(f"u and v: expected shapes that broadcast together, found {u.shape} and {v.shape}") from None
    return u, v
