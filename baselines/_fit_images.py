r"""Fitting a nonlinear model straight from images: multi-start Levenberg-Marquardt on image residuals.

Under one point or directional light per image, the renderer's radiance of a pixel that sees the target object is
``L_c = c_c f(u, v)`` per colour channel ``c`` with ``c_c = E_c cos(theta_u) V`` known from the scene
(:func:`polyjax.render.light_samples`, the render as a linear function of the BRDF). The image residual of a kept
pixel is therefore

.. math:: \sqrt{w_{px}}\,(I_c - c_c f) = \sqrt{w_{px}}\, E_c V \cos\theta_u\,\Big(\frac{I_c}{c_c} - f\Big),

the residual of equation (11) with values ``I_c / c_c`` and weights ``w_px (E_c V)^2``: :func:`baselines.fit` on
those lanes (R, G, B) minimises exactly the squared radiance residuals, with all its starts, stages, result codes and
derivatives (w.r.t. the images, pixel weights and lights, by the implicit function theorem).
"""

from __future__ import annotations

from typing import Sequence

import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from polyjax import InputError, is_concrete

from ._fit import fit
from ._registry import get_model


def fit_to_images(
    name: str,
    scenes: Sequence,
    images: Sequence[ArrayLike] | ArrayLike,
    n_starts: int = 16,
    key=None,
    *,
    target: int = 0,
    pixel_weights: Sequence[ArrayLike] | ArrayLike | None = None,
    saturation: float | None = None,
    cutoff_deg: float | None = 80.0,
    **fit_options,
):
    r"""Fit the nonlinear model ``name`` to images (linear RGB) of one object under known point or directional
    lights: one R, G, B lane each, by :func:`baselines.fit` on the image residuals (see the module notes).

    Minimises, per channel, ``sum_px w_px (I_px - L_px(params))^2`` over the kept pixels of every image, where
    ``L_px`` is the renderer's radiance of the model (:func:`polyjax.render.render` of a
    :class:`polyjax.render.ParametricBRDF`). Pixels are kept as in :func:`polyjax.fit_polynomial_to_images`: on
    the target, finite, below ``saturation``, lit and not shadowed, ``theta_u`` and ``theta_v`` within
    ``cutoff_deg``.

    Args:
        name: a nonlinear model of :data:`baselines.MODELS`.
        scenes: a :class:`polyjax.render.Scene` or a sequence, one per image, each with exactly one point or
            directional light and direct lighting only; the target's BRDF is a placeholder.
        images: ``(H, W, 3)`` per scene (a sequence, or ``(n, H, W, 3)``).
        n_starts, key: as in :func:`baselines.fit`.
        target: index of the fitted object in each scene's ``objects``.
        pixel_weights: ``(H, W)`` non-negative weights per image (or a scalar per image), 1 by default.
        saturation: pixels with a channel at or above this value are excluded; None keeps every finite pixel.
        cutoff_deg: grazing cutoff in degrees; None keeps every lit pixel above the horizon.
        fit_options: passed to :func:`baselines.fit` (``max_steps``, ``rtol``, ``backend``, ...).

    Returns:
        :class:`baselines.BaselineFit` with batch shape ``(3,)`` (R, G, B). Its ``l2`` is the root-mean-square
        radiance residual over the kept pixels divided by the root-mean-square light factor ``E V`` of those
        pixels (equation (11) with the weights above).

    Raises:
        InputError: a scene with several lights or an environment map (its radiance is a sum over light samples:
            not implemented), scenes and images that disagree, a linear model, no kept pixel (concrete inputs).
    """
    from polyjax.render import Scene, light_samples

    if get_model(name).linear:
        raise InputError(f"name: {name} is linear; fit it with polyjax.fit_polynomial_to_images-style solves")
    scenes = [scenes] if isinstance(scenes, Scene) else list(scenes)
    if isinstance(images, (list, tuple)):
        images = list(images)
    else:
        arr = jnp.asarray(images)
        images = [arr] if arr.ndim == 3 else list(arr)
    if not scenes or len(images) != len(scenes):
        raise InputError(f"images: expected one image per scene ({len(scenes)}), found {len(images)}")
    if pixel_weights is None:
        pixel_weights = [None] * len(scenes)
    elif not isinstance(pixel_weights, (list, tuple)):
        pw = jnp.asarray(pixel_weights)
        pixel_weights = list(pw) if pw.ndim in (1, 3) else [pw] * len(scenes)
    if len(pixel_weights) != len(scenes):
        raise InputError(f"pixel_weights: expected one entry per scene ({len(scenes)}), found {len(pixel_weights)}")
    dtype = jnp.result_type(float)
    cos_cut = None if cutoff_deg is None else float(np.cos(np.deg2rad(cutoff_deg)))
    us, vs, cs, ys, ws, keeps = [], [], [], [], [], []
    for i, (scene, img, pw) in enumerate(zip(scenes, images, pixel_weights)):
        if not isinstance(scene, Scene):
            raise InputError(f"scenes[{i}]: expected a polyjax.render.Scene, found {type(scene).__name__}")
        h, w = scene.camera.height, scene.camera.width
        img = jnp.asarray(img)
        if img.shape != (h, w, 3):
            raise InputError(f"images[{i}]: expected linear RGB of shape ({h}, {w}, 3), found {img.shape}")
        ls = light_samples(scene, target, dtype=dtype)
        if ls.u.shape[1] != 1 or not bool(np.all(np.asarray(ls.is_point))):
            raise InputError(f"scenes[{i}]: expected exactly one point or directional light (no environment map); "
                             f"found {ls.u.shape[1]} light samples per pixel")
        img = img.astype(dtype).reshape(-1, 3)
        pw = jnp.ones((h * w,), dtype) if pw is None else jnp.broadcast_to(jnp.asarray(pw, dtype), (h, w)).reshape(-1)
        u, c = ls.u[:, 0], ls.weight[:, 0]
        ok = ls.on_target & ~ls.shadowed & jnp.all(jnp.isfinite(img), axis=-1) & (pw > 0)
        ok = ok & jnp.any(c > 0, axis=-1) & (ls.v[:, 2] > 0) & (u[:, 2] > 0)
        if saturation is not None:
            ok = ok & jnp.all(img < saturation, axis=-1)
        if cos_cut is not None:
            ok = ok & (ls.v[:, 2] >= cos_cut) & (u[:, 2] >= cos_cut)
        us.append(u), vs.append(ls.v), cs.append(c), ys.append(img), ws.append(pw), keeps.append(ok)
    u, v, c, y, wpx, keep = (jnp.concatenate(a) for a in (us, vs, cs, ys, ws, keeps))
    if is_concrete(keep):
        idx = np.flatnonzero(np.asarray(keep))
        if idx.size == 0:
            raise InputError("images: no pixel is kept (on the target, lit, unsaturated, within the cutoff)")
        u, v, c, y, wpx, keep = (a[idx] for a in (u, v, c, y, wpx, keep))
    lit = keep[:, None] & (c > 0)
    c_safe = jnp.where(lit, c, 1.0)
    cos_u = jnp.where(keep, u[:, 2], 1.0)[:, None]
    values = jnp.where(lit, y / c_safe, 0.0).T  # (3, n): I / c
    weights = jnp.where(lit, wpx[:, None] * (c_safe / cos_u) ** 2, 0.0).T  # (3, n): w_px (E V)^2
    return fit(name, u, v, values, weights=weights, mask=lit.T, cutoff_deg=None, n_starts=n_starts, key=key,
               **fit_options)
