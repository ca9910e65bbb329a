r"""Images of one object under known lighting as rows of a fit: per kept pixel, its light samples and value.

For a fixed scene without inter-reflection the radiance of a pixel ``i`` that sees the target object is linear in
its BRDF (:mod:`polyjax.render._linear`),

.. math:: L_{i,c} = \sum_j c_{ij,c}\, f(u_{ij}, v_i),

one term per point or directional light (``c = E cos(theta_u) V``) and per environment sample. :func:`image_rows`
gathers, over every image, the light directions ``u_ij``, view direction ``v_i``, RGB weights ``c_ij``, pixel value
``I_i`` and pixel weight ``w_i`` of the kept pixels: the design rows of the closed-form polynomial fit
(:func:`polyjax.fit_polynomial_to_images`) and the residuals ``sqrt(w_i) (sum_j c_ij f(u_ij, v_i) - I_i)`` of the
nonlinear fits (``baselines.fit_to_images``).
"""

from __future__ import annotations

from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float

from .._arrays import device_array, is_concrete
from .._errors import InputError
from ..render._linear import light_samples
from ..render._scene import Scene


class ImageRows(eqx.Module):
    """The kept pixels of a set of images (``N`` pixels, ``J`` light samples each; see :func:`image_rows`).

    Attributes:
        u: ``(N, J, 3)`` light directions in each pixel's local shading frame.
        v: ``(N, 3)`` view directions in the local frame.
        weight: ``(N, J, 3)`` RGB light weights ``c_ij`` (0 for padding, an occluded light or one below the
            horizon, and on every row that is not kept).
        values: ``(N, 3)`` pixel values ``I_i`` (linear RGB; 0 on rows not kept).
        pixel_weights: ``(N,)`` weights ``w_i`` of the squared radiance residuals (0 on rows not kept).
        keep: ``(N,)`` True for a pixel in the fit.
    """

    u: Float[Array, "n j 3"]
    v: Float[Array, "n 3"]
    weight: Float[Array, "n j 3"]
    values: Float[Array, "n 3"]
    pixel_weights: Float[Array, " n"]
    keep: Bool[Array, " n"]


def image_rows(
    scenes: Sequence,
    images: Sequence[ArrayLike] | ArrayLike,
    *,
    target: int = 0,
    pixel_weights: Sequence[ArrayLike] | ArrayLike | None = None,
    saturation: float | None = None,
    cutoff_deg: float | None = 80.0,
    spp: int = 64,
    seed: int = 0,
    compact: bool = True,
) -> ImageRows:
    r"""The pixels of ``images`` that enter a fit from images, with their light samples (module notes).

    **Pixels kept**: those whose primary ray hits object ``target``, with finite values in all three channels, no
    channel at or above ``saturation``, a positive pixel weight, lit (some light weight ``> 0``), not in the shadow
    of any point or directional light that faces them (a partly shadowed pixel is excluded, as are its shadow
    edges), with ``theta_v`` and every lit point light's ``theta_u`` within ``cutoff_deg``.

    Differentiable with respect to the images, pixel weights, lights and environment texels (as
    :func:`polyjax.render.light_samples`); the selection is piecewise constant.

    Args:
        scenes: a :class:`polyjax.render.Scene` or a sequence, one per image (direct lighting only); the target's
            BRDF is not used.
        images: ``(H, W, 3)`` linear RGB per scene (a sequence, or an array ``(n, H, W, 3)``).
        target: index of the fitted object in each scene's ``objects``.
        pixel_weights: ``(H, W)`` non-negative weights per image, a scalar per image, or one ``(H, W)`` array for
            every image; 1 by default.
        saturation: pixels with a channel at or above this value are excluded; None keeps every finite pixel.
        cutoff_deg: grazing cutoff in degrees; None keeps every pixel above the horizon.
        spp: environment samples per pixel (scenes with an environment map).
        seed: random seed of the environment samples.
        compact: with concrete inputs, return the kept rows only (else every pixel of every image, ``keep``
            marking the kept ones; traced inputs always give every pixel).

    Returns:
        :class:`ImageRows`; scenes with fewer light samples than others are padded with zero weights.

    Raises:
        InputError: scenes/images/pixel weights that disagree in number or size, an image not ``(H, W, 3)``,
            negative or non-finite pixel weights, bad options, a scene with inter-reflections.
    """
    scenes, images, pixel_weights = _checked_lists(scenes, images, pixel_weights)
    if cutoff_deg is not None and not (0.0 < float(cutoff_deg) <= 90.0):
        raise InputError(f"cutoff_deg: expected an angle in (0, 90] degrees or None, found {cutoff_deg}")
    if int(spp) < 1:
        raise InputError(f"spp: expected at least 1 sample per pixel, found {spp}")
    dtype = jnp.result_type(float)
    rows = []
    for i, (scene, img, pw) in enumerate(zip(scenes, images, pixel_weights)):
        h, w = scene.camera.height, scene.camera.width
        img = jnp.asarray(img)
        if img.shape != (h, w, 3):
            raise InputError(f"images[{i}]: expected linear RGB of shape ({h}, {w}, 3) (its scene's camera), "
                             f"found {img.shape}")
        img = img.astype(dtype).reshape(-1, 3)
        pw = jnp.ones((h * w,), dtype) if pw is None else jnp.broadcast_to(jnp.asarray(pw, dtype), (h, w)).reshape(-1)
        if is_concrete(pw) and (not np.all(np.isfinite(np.asarray(pw))) or np.any(np.asarray(pw) < 0)):
            raise InputError(f"pixel_weights[{i}]: expected finite, non-negative weights")
        ls = light_samples(scene, target, spp=spp, seed=seed, dtype=dtype)
        rows.append((ls, img, pw, _kept(ls, img, pw, saturation, cutoff_deg)))
    return _gather(rows, compact)


def _checked_lists(scenes, images, pixel_weights):
    """``scenes``, ``images`` and ``pixel_weights`` as lists of one entry per scene (``None``: weight 1)."""
    scenes = [scenes] if isinstance(scenes, Scene) else list(scenes)
    if not scenes:
        raise InputError("scenes: expected at least one polyjax.render.Scene")
    for i, s in enumerate(scenes):
        if not isinstance(s, Scene):
            raise InputError(f"scenes[{i}]: expected a polyjax.render.Scene, found {type(s).__name__}")
    if isinstance(images, (list, tuple)):
        images = list(images)
    else:
        arr = jnp.asarray(images)
        images = [arr] if arr.ndim == 3 else list(arr)
    if len(images) != len(scenes):
        raise InputError(f"images: expected one image per scene ({len(scenes)}), found {len(images)}")
    if pixel_weights is None:
        pixel_weights = [None] * len(scenes)
    elif not isinstance(pixel_weights, (list, tuple)):
        pw = jnp.asarray(pixel_weights)
        pixel_weights = list(pw) if pw.ndim in (1, 3) else [pw] * len(scenes)
    if len(pixel_weights) != len(scenes):
        raise InputError(f"pixel_weights: expected one entry per scene ({len(scenes)}), found {len(pixel_weights)}")
    return scenes, images, list(pixel_weights)


@eqx.filter_jit
def _kept(ls, img, pw, saturation, cutoff_deg):
    """``(N,)`` the pixels of one image that enter the fit (the rules of :func:`image_rows`); one compiled program
    (the options are static)."""
    ok = ls.on_target & ~ls.shadowed & jnp.all(jnp.isfinite(img), axis=-1) & (pw > 0)
    if saturation is not None:
        ok = ok & jnp.all(img < saturation, axis=-1)
    lit = jnp.sum(ls.weight, axis=-1) > 0  # (N, J)
    ok = ok & jnp.any(lit, axis=-1) & (ls.v[:, 2] > 0)
    if cutoff_deg is not None:
        c = jnp.cos(jnp.deg2rad(cutoff_deg))
        grazing = jnp.any(lit & ls.is_point[None, :] & (ls.u[..., 2] < c), axis=-1)
        ok = ok & (ls.v[:, 2] >= c) & ~grazing
    return ok


def _gather(rows, compact):
    """One :class:`ImageRows` of every image's ``(light samples, image, pixel weights, kept)``: light samples
    padded to the largest ``J`` (zero weight), rows not kept zeroed, and with ``compact`` and concrete inputs only
    the kept rows."""
    u, v, c, y, wpx, keep = _stacked(rows)
    if compact and is_concrete(keep):
        idx = np.flatnonzero(np.asarray(keep))
        if idx.size:
            u, v, c, y, wpx, keep = _take_rows((u, v, c, y, wpx, keep), device_array(idx))
    return ImageRows(u=u, v=v, weight=c, values=y, pixel_weights=wpx, keep=keep)


@jax.jit
def _take_rows(arrays, idx):
    """The rows ``idx`` of every array, in one compiled program."""
    return tuple(a[idx] for a in arrays)


@jax.jit
def _stacked(rows):
    """Every image's rows stacked (:func:`_gather` before its compaction) in one compiled program."""
    n_j = max(ls.u.shape[1] for ls, _, _, _ in rows)

    def pad(a):  # (N, J, 3) -> (N, n_j, 3): zero weight, no light
        return jnp.pad(a, ((0, 0), (0, n_j - a.shape[1]), (0, 0)))

    keep = jnp.concatenate([ok for _, _, _, ok in rows])
    v = jnp.concatenate([ls.v for ls, _, _, _ in rows])
    u = jnp.concatenate([pad(ls.u) for ls, _, _, _ in rows])
    c = jnp.where(keep[:, None, None], jnp.concatenate([pad(ls.weight) for ls, _, _, _ in rows]), 0.0)
    y = jnp.where(keep[:, None], jnp.concatenate([img for _, img, _, _ in rows]), 0.0)
    wpx = jnp.where(keep, jnp.concatenate([pw for _, _, pw, _ in rows]), 0.0)
    return u, v, c, y, wpx, keep


__all__ = ["ImageRows", "image_rows"]
