r"""A simulated capture of a flat spatially varying sample: texels photographed under K point lights.

Geometry (the sample's local frame is the world frame): the sample is the square ``|x|, |y| <= size / 2`` of the
plane ``z = 0``, normal ``+z``, divided into ``H x W`` texels (row ``i`` along ``y``, column ``j`` along ``x``,
texel centres ``((j + 1/2) / W - 1/2, (i + 1/2) / H - 1/2) size``). A fixed pinhole camera at ``camera`` sees
every texel: its view direction is ``v = normalize(camera - p)``, one per texel. A capture may have ``C`` cameras
(``camera (C, 3)``, a multi-view gonioreflectometer or a hand-held capture): every camera photographs the sample
under every light, so a texel has ``C K`` observations, ``K`` light directions under each of ``C`` view directions.
Point light ``k`` at ``l_k`` with intensity ``I`` (W/sr, RGB or grey) gives the texel the irradiance
``E = I / |l_k - p|^2`` on a surface facing it and the light direction ``u = normalize(l_k - p)``. The
photograph's pixel of a texel is its outgoing radiance

.. math::
    L_k = f(u_k, v)\, E_k \cos\theta_{u_k},

evaluated directly at each texel's own directions (one pixel per texel: the camera's image of the sample
resampled onto the texel grid, no pixel footprint, no shadows or interreflection, which a flat sample does not
have). This is the same radiance the renderer computes for a point light (``polyjax.render``); evaluating it
directly keeps the texel-to-pixel correspondence exact. A texel's true BRDF is the blend
``f = sum_m a_m f_m`` of the materials' BRDFs (e.g. neural MERL materials) with the blend map ``a (H, W, M)``.
"""

from __future__ import annotations

from typing import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._errors import InputError

#: a BRDF: ``f(u (..., 3), v (..., 3)) -> (..., 3)`` RGB values in 1/sr (e.g. a neural MERL material)
BRDFFn = Callable[[Array, Array], Array]


def texel_positions(height: int, width: int, size: float = 1.0, rows: slice | None = None) -> np.ndarray:
    """Texel centres ``(H, W, 3)`` on the plane ``z = 0`` (or rows ``rows`` of them)."""
    if int(height) < 1 or int(width) < 1:
        raise InputError(f"height, width: expected positive texture sizes, found {height} x {width}")
    rows = slice(0, height) if rows is None else rows
    y = ((np.arange(height)[rows] + 0.5) / height - 0.5) * size
    x = ((np.arange(width) + 0.5) / width - 0.5) * size
    yy, xx = np.meshgrid(y, x, indexing="ij")
    return np.stack([xx, yy, np.zeros_like(xx)], axis=-1)


def hemisphere_lights(k: int, radius: float = 2.5, min_elevation_deg: float = 15.0) -> np.ndarray:
    """``k`` light positions ``(k, 3)`` on a Fibonacci spiral over the hemisphere of ``radius`` above the sample,
    at elevations of at least ``min_elevation_deg``."""
    if int(k) < 1:
        raise InputError(f"k: expected at least one light, found {k}")
    i = np.arange(k) + 0.5
    z_min = np.sin(np.radians(min_elevation_deg))
    z = 1.0 - i / k * (1.0 - z_min)
    r = np.sqrt(1.0 - z * z)
    phi = np.pi * (1.0 + 5**0.5) * i
    return radius * np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1)


def spread_cameras(c: int, radius: float = 2.9, max_elevation_deg: float = 70.0,
                   min_elevation_deg: float = 15.0) -> np.ndarray:
    """``c`` camera positions ``(c, 3)`` on the hemisphere of ``radius`` above the sample, a multi-view rig whose
    views spread over the domain of the Lafortune variables: elevations evenly from ``max_elevation_deg`` (near
    the normal: ``u_z v_z`` up to about ``cos 20 deg``) down to ``min_elevation_deg`` (grazing:
    ``|u_x v_x + u_y v_y|`` up to about ``sin 75 deg``), azimuths ``-90 + 360 i / c`` degrees (the first camera on
    the side of the default camera)."""
    if int(c) < 1:
        raise InputError(f"c: expected at least one camera, found {c}")
    el = np.radians(np.linspace(max_elevation_deg, min_elevation_deg, int(c)))
    az = np.radians(-90.0 + 360.0 * np.arange(int(c)) / int(c))
    return radius * np.stack([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)], axis=-1)


def blend_map(height: int, width: int, n_materials: int = 2, rows: slice | None = None) -> np.ndarray:
    """A smooth blend map ``(H, W, M)`` (non-negative, summing to 1 over materials): sums of low-frequency
    sinusoids, so that every texel mixes the materials differently and some are pure."""
    p = texel_positions(height, width, 1.0, rows)
    x, y = p[..., 0], p[..., 1]
    raw = [np.clip(0.5 + 0.75 * np.sin(3.0 * (m + 1) * x + 2.0 * m) * np.cos(2.0 * (m + 1) * y - m), 0.0, 1.0)
           for m in range(n_materials)]
    if n_materials == 1:
        return np.ones(x.shape + (1,))
    a = np.stack(raw[:-1], -1)
    a = a / np.maximum(1.0, a.sum(-1, keepdims=True))
    return np.concatenate([a, 1.0 - a.sum(-1, keepdims=True)], -1)


@jax.jit
def directions(positions: ArrayLike, light: ArrayLike, camera: ArrayLike):
    """``(u, v, distance^2, cos theta_u)`` of texels ``positions (..., 3)`` for lights ``light (K, 3)`` (or
    ``(3,)``): ``u (..., K, 3)``, ``v (..., 3)``."""
    p = jnp.asarray(positions)
    light = jnp.asarray(light, p.dtype)
    d = light - p[..., None, :] if light.ndim == 2 else light - p
    d2 = jnp.sum(d * d, axis=-1)
    u = d / jnp.sqrt(d2)[..., None]
    v = jnp.asarray(camera, p.dtype) - p
    v = v / jnp.linalg.norm(v, axis=-1, keepdims=True)
    return u, v, d2, u[..., 2]


def blended_brdf(materials: Sequence[BRDFFn], blend: Float[ArrayLike, "*texels M"], u, v) -> Array:
    """``sum_m a_m f_m(u, v)`` at texels' directions: ``u, v (*texels, ..., 3)`` -> ``(*texels, ..., 3)``."""
    a = jnp.asarray(blend)
    extra = jnp.ndim(u) - 1 - (a.ndim - 1)
    out = 0.0
    for m, f in enumerate(materials):
        am = a[..., m].reshape(a.shape[:-1] + (1,) * extra + (1,))
        out = out + am * jnp.asarray(f(u, v), jnp.result_type(u))
    return out


def _check_camera(camera, dtype) -> Array:
    cam = jnp.asarray(camera, dtype)
    if cam.shape[-1:] != (3,) or cam.ndim not in (1, 2) or cam.size == 0:
        raise InputError(f"camera: expected a position (3,) or C positions (C, 3), found shape {cam.shape}")
    return cam


def _views(camera: Array, one_view: Callable[[Array], Array]) -> Array:
    """``one_view(camera (3,))`` for one camera, or stacked ``(C, ...)`` over the cameras ``(C, 3)``."""
    if camera.ndim == 1:
        return one_view(camera)
    return jnp.stack([one_view(c) for c in camera])


class Capture(eqx.Module):
    """Photographs of a flat sample (or of rows ``row0 .. row0 + h`` of it) under point lights, by one camera or
    by ``C`` cameras.

    Attributes:
        images: ``(K, h, W, 3)`` radiance of every texel under each light (the photographs on the texel grid);
            ``(C, K, h, W, 3)`` with ``C`` cameras.
        positions: ``(h, W, 3)`` texel centres.
        lights: ``(K, 3)`` light positions; ``intensity``: ``(3,)`` RGB intensity of every light.
        camera: ``(3,)`` camera position, or ``(C, 3)`` positions of ``C`` cameras.
        blend: ``(h, W, M)`` the true blend map (for evaluation only; the fit does not see it).
        height, width, size, row0: the full texture's shape and side length, and the first row held here.
    """

    images: Float[Array, "*C K h W 3"]
    positions: Float[Array, "h W 3"]
    lights: Float[Array, "K 3"]
    intensity: Float[Array, "3"]
    camera: Float[Array, "*C 3"]
    blend: Float[Array, "h W M"]
    height: int = eqx.field(static=True)
    width: int = eqx.field(static=True)
    size: float = eqx.field(static=True)
    row0: int = eqx.field(static=True, default=0)

    def observations(self):
        r"""The fit's inputs: ``u (h, W, n, 3)``, ``v (h, W, n, 3)``, BRDF values ``b = L / (E cos theta_u)``
        ``(h, W, 3, n)`` and weights ``w = E^2 (h, W, n)``, ``n = K`` observations per texel with one camera,
        ``n = C K`` with ``C`` cameras (camera-major: observation ``c K + k`` is light ``k`` seen by camera ``c``).

        With these weights the objective of :func:`polyjax.fit_polynomial`, ``sum_k w_k cos^2(theta_u) (b_k -
        f(u_k, v_k))^2 = sum_k (L_k - E_k cos(theta_u) f(u_k, v_k))^2``, is the squared error of the photographs
        in radiance. Lights at or below a texel's horizon give no observation (weight 0).
        """
        if self.camera.ndim == 1:
            return _observations(self.images, self.positions, self.lights, self.intensity, self.camera)
        views = [_observations(im, self.positions, self.lights, self.intensity, c)
                 for im, c in zip(self.images, self.camera)]
        u, v, b, w = (jnp.concatenate(parts, axis=ax) for parts, ax in zip(zip(*views), (-2, -2, -1, -1)))
        return u, v, b, w


def _observations(images, positions, lights, intensity, camera):
    """:meth:`Capture.observations` of one camera's photographs ``images (K, h, W, 3)``."""
    u, v, d2, cos = directions(positions, lights, camera)
    e = jnp.asarray(intensity).mean() / d2  # (h, W, K)
    ok = cos > 1e-6
    b = jnp.moveaxis(images, 0, -2) / jnp.where(ok, e * cos, 1.0)[..., None]  # (h, W, K, 3)
    b = jnp.where(ok[..., None], b / (jnp.asarray(intensity) / jnp.asarray(intensity).mean()), 0.0)
    vk = jnp.broadcast_to(v[..., None, :], u.shape)
    return u, vk, jnp.moveaxis(b, -1, -2), jnp.where(ok, e * e, 0.0)


def simulate_capture(
    materials: Sequence[BRDFFn],
    height: int,
    width: int,
    *,
    n_lights: int = 48,
    lights: ArrayLike | None = None,
    camera: ArrayLike = (0.0, -1.5, 2.5),
    intensity: float | ArrayLike = 10.0,
    size: float = 1.0,
    blend: ArrayLike | None = None,
    rows: slice | None = None,
    dtype=None,
) -> Capture:
    """Simulate the photographs of a sample whose texels blend ``materials`` (see the module notes).

    Args:
        materials: ``M`` BRDFs ``f(u, v) -> (..., 3)`` (e.g. :func:`polyjax.data.load_nbrdf` networks).
        height, width: the texture's size in texels.
        n_lights, lights: ``lights (K, 3)`` positions, or ``n_lights`` of :func:`hemisphere_lights`.
        camera: the camera position ``(3,)``, or ``(C, 3)`` positions of ``C`` cameras (each photographs the
            sample under every light); intensity: every light's intensity (grey or RGB).
        size: the sample's side length (same unit as the positions).
        blend: ``(height, width, M)`` blend map; :func:`blend_map` by default.
        rows: simulate only these rows (a process's part of the texture); all by default.
        dtype: float type of the arrays (JAX's default float by default).

    Returns:
        :class:`Capture`.
    """
    if len(materials) < 1:
        raise InputError("materials: expected at least one BRDF")
    dtype = jnp.result_type(float) if dtype is None else dtype
    rows = slice(0, height) if rows is None else slice(*rows.indices(height))
    pos = jnp.asarray(texel_positions(height, width, size, rows), dtype)
    lights = hemisphere_lights(n_lights) if lights is None else np.asarray(lights, float)
    if lights.ndim != 2 or lights.shape[-1] != 3:
        raise InputError(f"lights: expected positions of shape (K, 3), found {lights.shape}")
    a = blend_map(height, width, len(materials), rows) if blend is None else np.asarray(blend)[rows]
    if a.shape != tuple(pos.shape[:2]) + (len(materials),):
        raise InputError(f"blend: expected shape {(height, width, len(materials))}, found {np.shape(blend)}")
    inten = jnp.broadcast_to(jnp.asarray(intensity, dtype), (3,))
    cam = _check_camera(camera, dtype)
    lights_ = jnp.asarray(lights, dtype)
    images = _views(cam, lambda c: jax.lax.map(lambda light: radiance(materials, a, pos, light, inten, c), lights_))
    return Capture(images=images, positions=pos, lights=lights_, intensity=inten, camera=cam,
                   blend=jnp.asarray(a, dtype), height=int(height), width=int(width), size=float(size),
                   row0=int(rows.start))


def radiance(brdf, blend, positions, light, intensity, camera) -> Float[Array, "h W 3"]:
    """The photograph of texels ``positions`` under one point light: ``f(u, v) E cos(theta_u)``, ``f`` the blend
    of ``brdf`` (a sequence of materials) by ``blend``, or ``brdf(u, v)`` itself when it is a callable taking each
    texel's directions (e.g. a fitted per-texel model, see :func:`relight`)."""
    u, v, d2, cos = directions(positions, light, camera)
    f = blended_brdf(brdf, blend, u, v) if not callable(brdf) else brdf(u, v)
    e = jnp.asarray(intensity) / d2[..., None]
    return f * e * jnp.maximum(cos, 0.0)[..., None]


def relight(model, capture: Capture, light: ArrayLike, intensity: float | ArrayLike | None = None,
            camera: ArrayLike | None = None) -> Array:
    """Render a fitted per-texel model (a :class:`polyjax.PolynomialBRDF` of batch ``(h, W, 3)``) under a new
    point light: ``max(f, 0) E cos(theta_u)`` at each texel's own directions, as the renderer transports light.

    Args:
        camera: ``(3,)`` or ``(C, 3)``; the capture's camera(s) by default.

    Returns:
        ``(h, W, 3)`` radiance, or ``(C, h, W, 3)`` with ``C`` cameras.
    """
    inten = capture.intensity if intensity is None else jnp.broadcast_to(jnp.asarray(intensity), (3,))
    dtype = capture.positions.dtype
    cam = capture.camera if camera is None else _check_camera(camera, dtype)

    def per_texel(u, v):  # u, v (h, W, 3): each texel's model at its own directions
        f = jax.vmap(jax.vmap(lambda m, uu, vv: m(uu, vv)))(model, u, v)
        return jnp.maximum(f, 0.0)

    light = jnp.asarray(light, dtype)
    return _views(cam, lambda c: radiance(per_texel, None, capture.positions, light, inten, c))


def photograph(materials: Sequence[BRDFFn], capture: Capture, light: ArrayLike,
               intensity: float | ArrayLike | None = None, camera: ArrayLike | None = None) -> Array:
    """The simulated photograph ``(h, W, 3)`` of the capture's sample (its true blend) under a new light, by the
    capture's camera or ``camera`` (``(C, h, W, 3)`` with ``C`` cameras)."""
    inten = capture.intensity if intensity is None else jnp.broadcast_to(jnp.asarray(intensity), (3,))
    dtype = capture.positions.dtype
    cam = capture.camera if camera is None else _check_camera(camera, dtype)
    light = jnp.asarray(light, dtype)
    return _views(cam, lambda c: radiance(list(materials), capture.blend, capture.positions, light, inten, c))
