"""Environment lighting from a latitude-longitude map, with importance sampling.

Convention (world ``+y`` up): pixel row ``i`` of an ``H x W`` map covers the polar angle
``theta in [i pi / H, (i + 1) pi / H]`` measured from ``+y``; column ``j`` covers the azimuth
``phi in [2 pi j / W - pi, 2 pi (j + 1) / W - pi]``, and direction
``d = (sin theta sin phi, cos theta, -sin theta cos phi)`` (the map's centre column looks
along ``-z``). Radiance is constant over a pixel.

Sampling picks a pixel with probability ``p_ij`` proportional to ``luminance_ij sin theta_i`` and a
point uniformly in ``(theta, phi)`` inside it; the solid-angle density is
``pdf(d) = p_ij H W / (2 pi^2 sin theta)``, so the estimator ``L(d) / pdf(d)`` has no variance
from the map's own radiance variation (only from the BRDF and cosine).
"""

from __future__ import annotations

import os

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._arrays import is_traced
from .._errors import InputError
from ._image import read_exr

_LUMA = np.array([0.2126, 0.7152, 0.0722])


class EnvironmentLight(eqx.Module):
    """A distant environment map (linear RGB radiance) lighting the whole scene.

    Attributes:
        image: ``(H, W, 3)`` radiance (already multiplied by ``scale``).
        cdf: ``(H W,)`` cumulative pixel-selection probabilities (row-major).
        pmf: ``(H W,)`` pixel-selection probabilities ``p_ij``.
    """

    image: Float[Array, "h w 3"]
    cdf: Float[Array, " hw"]
    pmf: Float[Array, " hw"]

    def __init__(self, image: ArrayLike, scale: float = 1.0):
        """Args:
        image: ``(H, W, 3)`` latitude-longitude radiance map (non-negative, finite).
        scale: multiplies the radiance.
        """
        if is_traced(image, scale):
            self._init_traced(image, scale)
            return
        img = np.asarray(image, dtype=float)
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=-1)
        if img.ndim != 3 or img.shape[-1] != 3 or img.shape[0] < 1 or img.shape[1] < 1:
            raise InputError(f"image: expected an (H, W, 3) latitude-longitude map, found shape {img.shape}")
        if not np.all(np.isfinite(img)) or np.any(img < 0):
            raise InputError("image: expected finite, non-negative radiance, found negative or non-finite pixels")
        img = img * float(scale)
        h, w, _ = img.shape
        theta = (np.arange(h) + 0.5) * np.pi / h
        weight = (img @ _LUMA) * np.sin(theta)[:, None]
        if not weight.sum() > 0:  # a black map: sample uniformly over the sphere (all radiance is 0 anyway)
            weight = np.broadcast_to(np.sin(theta)[:, None], (h, w))
        pmf = (weight / weight.sum()).reshape(-1)
        cdf = np.cumsum(pmf)
        cdf[-1] = 1.0
        self.image = jnp.asarray(img)
        self.pmf = jnp.asarray(pmf)
        self.cdf = jnp.asarray(cdf)

    def _init_traced(self, image, scale):
        """Inside ``jit``/``grad``: shape checks only; the sampling tables are computed in JAX from the
        radiance with its derivative stopped (the estimator's samples and densities are fixed; the
        radiance ``L`` they weight stays differentiable)."""
        img = jnp.asarray(image)
        if not jnp.issubdtype(img.dtype, jnp.floating):
            img = img.astype(jnp.result_type(float))
        if img.ndim == 2:
            img = jnp.repeat(img[..., None], 3, axis=-1)
        if img.ndim != 3 or img.shape[-1] != 3 or img.shape[0] < 1 or img.shape[1] < 1:
            raise InputError(f"image: expected an (H, W, 3) latitude-longitude map, found shape {img.shape}")
        img = img * scale
        h, w, _ = img.shape
        theta = (jnp.arange(h) + 0.5) * jnp.pi / h
        lum = jax.lax.stop_gradient(img) @ jnp.asarray(_LUMA, img.dtype)
        weight = jnp.maximum(lum, 0.0) * jnp.sin(theta)[:, None]
        total = jnp.sum(weight)
        weight = jnp.where(total > 0, weight, jnp.broadcast_to(jnp.sin(theta)[:, None], (h, w)))
        pmf = (weight / jnp.sum(weight)).reshape(-1)
        cdf = jnp.cumsum(pmf).at[-1].set(1.0)
        self.image = img
        self.pmf = pmf
        self.cdf = cdf

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.image.shape[:2])

    def radiance(self, d: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
        """Radiance arriving from world directions ``d`` (unit vectors)."""
        h, w = self.shape
        theta = jnp.arccos(jnp.clip(d[..., 1], -1.0, 1.0))
        phi = jnp.arctan2(d[..., 0], -d[..., 2])
        i = jnp.clip(jnp.floor(theta / jnp.pi * h).astype(jnp.int32), 0, h - 1)
        j = jnp.clip(jnp.floor((phi + jnp.pi) / (2 * jnp.pi) * w).astype(jnp.int32), 0, w - 1)
        return self.image.astype(d.dtype)[i, j]

    def sample(self, xi: Float[Array, "... 3"]) -> tuple[Float[Array, "... 3"], Float[Array, "... 3"]]:
        """Importance-sample directions from three uniforms per sample.

        Returns:
            ``(d, L / pdf)``: world directions and radiance divided by the solid-angle density.
        """
        h, w = self.shape
        dtype = xi.dtype
        k = jnp.searchsorted(self.cdf.astype(dtype), xi[..., 0], side="right", method="scan_unrolled")
        k = jnp.clip(k, 0, h * w - 1)
        i, j = k // w, k % w
        theta = (i.astype(dtype) + xi[..., 1]) * (jnp.pi / h)
        phi = (j.astype(dtype) + xi[..., 2]) * (2 * jnp.pi / w) - jnp.pi
        st = jnp.sin(theta)
        d = jnp.stack([st * jnp.sin(phi), jnp.cos(theta), -st * jnp.cos(phi)], axis=-1)
        p = self.pmf.astype(dtype)[k]
        # L / pdf = L * 2 pi^2 sin(theta) / (p H W); p > 0 for every pixel that can be drawn
        inv_pdf = jnp.where(p > 0, 2 * jnp.pi**2 * st / (jnp.where(p > 0, p, 1.0) * h * w), 0.0)
        return d, self.image.astype(dtype)[i, j] * inv_pdf[..., None]


def sample_pool(env: EnvironmentLight, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Draw ``n`` importance samples of ``env`` once (see :func:`pool_indices`).

    Returns:
        ``(d, L / pdf)``: ``(n, 3)`` directions and ``(n, 3)`` radiance over density.
    """
    d, k, inv_pdf = pool_indices(env, n, seed)
    img = jnp.asarray(env.image).reshape(-1, 3)
    if isinstance(k, np.ndarray) and not is_traced(env.image):
        return d, np.asarray(img, dtype=np.float64)[k] * inv_pdf[:, None]
    return d, img[k] * inv_pdf[:, None]


def pool_indices(env: EnvironmentLight, n: int, seed: int = 0):
    """Draw ``n`` importance samples of ``env`` once, in float64 numpy (see :meth:`EnvironmentLight.sample`).

    The renderer draws a pool like this per render and lets each pixel use its own pseudo-random
    subset of it: no random-number generation or trigonometry per pixel and sample, and the same
    arithmetic whatever else the render computes.

    The radiance is not part of the pool: a sample is the map pixel ``k`` it came from and
    ``1 / pdf``, and the renderer weights it by ``L_k`` itself, so the render is differentiable with
    respect to the map's texels (for fixed sample positions and densities: the derivative of the
    estimator, an unbiased estimate of the derivative of the integral).

    When the map's sampling tables are traced (the map was built inside ``jit``/``grad``, or passed into
    ``jit`` as an argument), the same uniforms (numpy, from ``seed``; they do not depend on the map) are
    inverted through the traced tables in JAX, so a traced render draws the same pixels as an eager one.

    Returns:
        ``(d, k, 1 / pdf)``: ``(n, 3)`` directions, ``(n,)`` flat pixel indices, ``(n,)`` inverse densities.
    """
    h, w, _ = env.image.shape
    if is_traced(env.pmf):
        return _pool_traced(env, n, seed)
    x0, perm, ri, rj = _pool_uniforms(n, seed)
    pmf = np.asarray(env.pmf, dtype=np.float64)
    cdf = np.cumsum(pmf)
    cdf /= cdf[-1]
    k = np.clip(np.searchsorted(cdf, x0, side="right"), 0, h * w - 1)
    k = k[perm]
    i, j = k // w, k % w
    theta = (i + ri) * np.pi / h
    phi = (j + rj) * 2 * np.pi / w - np.pi
    st = np.sin(theta)
    d = np.stack([st * np.sin(phi), np.cos(theta), -st * np.cos(phi)], axis=-1)
    p = pmf[k]
    inv_pdf = np.where(p > 0, 2 * np.pi**2 * st / (np.where(p > 0, p, 1.0) * h * w), 0.0)
    return d, k, inv_pdf


def _pool_uniforms(n: int, seed: int):
    """The pool's random numbers, which do not depend on the map: the pixel-selection coordinate stratified
    over ``n`` strata, the shuffle, and the jitter within the chosen pixel (rows, columns)."""
    rng = np.random.default_rng(seed)
    x0 = (np.arange(n) + rng.random(n)) / n
    perm = rng.permutation(n)
    return x0, perm, rng.random(n), rng.random(n)


def _pool_traced(env: EnvironmentLight, n: int, seed: int):
    h, w, _ = env.image.shape
    dtype = env.pmf.dtype
    pmf = jax.lax.stop_gradient(env.pmf)
    cdf = jnp.cumsum(pmf)
    cdf = cdf / cdf[-1]
    x0, perm, ri, rj = (jnp.asarray(a) for a in _pool_uniforms(n, seed))
    k = jnp.clip(jnp.searchsorted(cdf, x0.astype(dtype), side="right"), 0, h * w - 1)
    k = k[perm]
    i, j = k // w, k % w
    theta = (i + ri.astype(dtype)) * jnp.pi / h
    phi = (j + rj.astype(dtype)) * 2 * jnp.pi / w - jnp.pi
    st = jnp.sin(theta)
    d = jnp.stack([st * jnp.sin(phi), jnp.cos(theta), -st * jnp.cos(phi)], axis=-1)
    p = pmf[k]
    inv_pdf = jnp.where(p > 0, 2 * jnp.pi**2 * st / (jnp.where(p > 0, p, 1.0) * h * w), 0.0)
    return d, k, inv_pdf


def load_envmap(path: str | os.PathLike, scale: float = 1.0) -> EnvironmentLight:
    """Read a latitude-longitude environment map from an OpenEXR file (linear RGB)."""
    return EnvironmentLight(read_exr(path), scale)


def procedural_sky(height: int = 64, width: int = 128, sun_elevation_deg: float = 40.0, sun_azimuth_deg: float = 40.0,
                   sun_radiance: float = 400.0, sun_radius_deg: float = 3.0, sky_radiance: float = 1.0
                   ) -> EnvironmentLight:
    """A built-in sky: a zenith-to-horizon gradient, a darker ground and a small bright sun disc.

    The sky radiance goes from blue-ish ``(0.35, 0.55, 1.0)`` at the zenith to ``(1, 1, 1)`` at the
    horizon (times ``sky_radiance``); the ground is ``(0.25, 0.2, 0.15)``; the sun is a disc of
    radius ``sun_radius_deg`` at the given elevation and azimuth (azimuth from ``-z`` towards ``+x``).
    """
    theta = (np.arange(height) + 0.5) * np.pi / height
    phi = (np.arange(width) + 0.5) * 2 * np.pi / width - np.pi
    T, P = np.meshgrid(theta, phi, indexing="ij")
    d = np.stack([np.sin(T) * np.sin(P), np.cos(T), -np.sin(T) * np.cos(P)], -1)
    up = np.clip(d[..., 1], 0.0, 1.0)[..., None]
    zenith = np.array([0.35, 0.55, 1.0])
    sky = sky_radiance * (up * zenith + (1 - up) * np.ones(3))
    ground = np.array([0.25, 0.2, 0.15]) * sky_radiance
    img = np.where(d[..., 1:2] > 0, sky, ground)
    el, az = np.deg2rad(sun_elevation_deg), np.deg2rad(sun_azimuth_deg)
    sun = np.array([np.cos(el) * np.sin(az), np.sin(el), -np.cos(el) * np.cos(az)])
    in_sun = d @ sun > np.cos(np.deg2rad(sun_radius_deg))
    if not in_sun.any():  # a disc smaller than a pixel: light the nearest pixel
        in_sun = np.zeros(in_sun.shape, bool)
        in_sun[np.unravel_index(np.argmax(d @ sun), in_sun.shape)] = True
    img = np.where(in_sun[..., None], sun_radiance * np.array([1.0, 0.95, 0.85]), img)
    return EnvironmentLight(img)


__all__ = ["EnvironmentLight", "load_envmap", "pool_indices", "procedural_sky", "sample_pool"]
