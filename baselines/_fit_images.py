r"""Fitting a nonlinear model straight from images: multi-start Levenberg-Marquardt on image residuals.

The pixels and their light samples come from :func:`polyjax.image_rows` (the rows the closed-form
:func:`polyjax.fit_polynomial_to_images` solves for): the radiance of a kept pixel ``i`` in channel ``k`` is
``L_ik = sum_j c_ijk f(u_ij, v_i)``, and the fit minimises ``sum_i w_i (I_ik - L_ik)^2`` per channel.

- **One light sample per pixel** (one point or directional light per scene): ``L_ik = c_ik f(u_i, v_i)`` with
  ``c_ik = E_k cos(theta_u) V``, so the residual of a kept pixel is

  .. math:: \sqrt{w_i}\,(I_{ik} - c_{ik} f) = \sqrt{w_i}\, E_k V \cos\theta_u\,\Big(\frac{I_{ik}}{c_{ik}} - f\Big),

  the residual of equation (11) with values ``I / c`` and weights ``w (E V)^2``: :func:`baselines.fit` on those
  lanes minimises exactly the squared radiance residuals, with all its starts, stages, range-limit rounds, result
  codes and derivatives.
- **Several light samples per pixel** (several lights, an environment map): the residual is a sum over samples, and
  :mod:`baselines._light_sums` runs the same starts and Levenberg-Marquardt solve on it.

Both differentiate (``jit``, ``grad``, ``jvp``) w.r.t. the images, pixel weights, lights and environment texels by
the implicit function theorem at the kept optimum; the pixel selection and the choice of start are piecewise
constant.
"""

from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

import polyjax as pj
from polyjax import RESULTS, InputError
from polyjax.internal import is_concrete, one_lapack_thread, raise_on_status

from ._fit import fit
from ._light_sums import light_sum_kernel, package
from ._light_sums_joint import joint_light_sum_kernel, joint_package
from ._models.registry import get_model
from ._result import BaselineFit
from ._starts import check_n_starts

#: options of :func:`baselines.fit` that the several-light-samples kernel takes too
_LIGHT_SUM_OPTIONS = ("max_steps", "rtol", "atol", "stage_steps", "throw")


@one_lapack_thread
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
    spp: int = 64,
    seed: int = 0,
    **fit_options,
) -> BaselineFit:
    r"""Fit the nonlinear model ``name`` to images (linear RGB) of one object under known lighting: one R, G, B
    lane each, by multi-start Levenberg-Marquardt on the image residuals (see the module notes).

    Minimises, per channel, ``sum_px w_px (I_px - L_px(params))^2`` over the kept pixels of every image, where
    ``L_px`` is the renderer's radiance of the model (:func:`polyjax.render.render` of a
    :class:`polyjax.render.ParametricBRDF`; under an environment map the same ``spp``-sample estimate). Pixels are
    kept and weighted as in :func:`polyjax.fit_polynomial_to_images` (:func:`polyjax.image_rows`).

    Args:
        name: a nonlinear model of :data:`baselines.MODELS`. A standard material model
            (:data:`baselines.STANDARD_MODELS`) fits the three channels jointly, as :func:`baselines.fit` does: one
            roughness (metallic, IOR, ...) for R, G, B, the colours per channel, the sum of the three channels'
            objectives minimised (:mod:`baselines._light_sums_joint` under several light samples per pixel).
        scenes: a :class:`polyjax.render.Scene` or a sequence, one per image, with point and directional lights and
            environment maps, direct lighting only; the target's BRDF is a placeholder.
        images: ``(H, W, 3)`` per scene (a sequence, or ``(n, H, W, 3)``).
        n_starts, key: as in :func:`baselines.fit`.
        target: index of the fitted object in each scene's ``objects``.
        pixel_weights: ``(H, W)`` non-negative weights per image (or a scalar per image), 1 by default.
        saturation: pixels with a channel at or above this value are excluded; None keeps every finite pixel.
        cutoff_deg: grazing cutoff in degrees; None keeps every lit pixel above the horizon.
        spp, seed: environment samples per pixel and their seed (scenes with an environment map). The samples are
            those of a render with the same ``spp`` and ``seed`` (whether the map is built inside ``jit`` or not),
            so the fit sees the render's own estimate.
        fit_options: passed to :func:`baselines.fit` under one light sample per pixel (``max_steps``, ``rtol``,
            ``backend``, ...); with several, only ``max_steps``, ``rtol``, ``atol``, ``stage_steps`` and ``throw``.

    Returns:
        :class:`baselines.BaselineFit` with batch shape ``(3,)`` (R, G, B). Its ``l2`` is the root-mean-square
        radiance residual over the kept pixels divided by the root-mean-square light factor of those pixels
        (``E V`` under one light, ``sum_j c_j / cos(theta_u,j)`` in general): equation (11) with the weights above.

    Raises:
        InputError: scenes and images that disagree, a linear model, an option the several-sample fit does not
            take, no kept pixel (concrete inputs), and the errors of :func:`polyjax.image_rows`.
    """
    model = get_model(name)
    if model.linear:
        raise InputError(f"name: {name} is linear; fit it with polyjax.fit_polynomial_to_images-style solves")
    check_n_starts(n_starts)
    rows = pj.image_rows(scenes, images, target=target, pixel_weights=pixel_weights, saturation=saturation,
                         cutoff_deg=cutoff_deg, spp=spp, seed=seed)
    if is_concrete(rows.keep) and not bool(np.any(np.asarray(rows.keep))):
        raise InputError("images: no pixel is kept (on the target, lit, unsaturated, within the cutoff)")
    if rows.u.shape[1] == 1:
        return _fit_one_sample(model.name, rows, n_starts, key, fit_options)
    return _fit_light_sums(model.name, rows, n_starts, key, fit_options)


def _fit_one_sample(name, rows, n_starts, key, fit_options) -> BaselineFit:
    """One light sample per pixel: :func:`baselines.fit` on values ``I / c`` and weights ``w (c / cos)^2``."""
    u, c = rows.u[:, 0], rows.weight[:, 0]
    lit = rows.keep[:, None] & (c > 0)
    c_safe = jnp.where(lit, c, 1.0)
    cos_u = jnp.where(rows.keep, u[:, 2], 1.0)[:, None]
    values = jnp.where(lit, rows.values / c_safe, 0.0).T  # (3, n): I / c
    weights = jnp.where(lit, rows.pixel_weights[:, None] * (c_safe / cos_u) ** 2, 0.0).T  # (3, n): w (E V)^2
    return fit(name, u, rows.v, values, weights=weights, mask=lit.T, cutoff_deg=None, n_starts=n_starts, key=key,
               **fit_options)


def _fit_light_sums(name, rows, n_starts, key, fit_options) -> BaselineFit:
    """Several light samples per pixel: :mod:`baselines._light_sums` (its kernel on constants, then the kept
    optimum with its implicit derivative)."""
    extra = sorted(set(fit_options) - set(_LIGHT_SUM_OPTIONS))
    if extra:
        raise InputError(f"fit_options: {extra} not supported with several light samples per pixel (several "
                         f"lights or an environment map); expected only {list(_LIGHT_SUM_OPTIONS)}")
    opts = dict(max_steps=100, rtol=1e-6, atol=1e-8, stage_steps=6, throw=False) | fit_options
    for k in ("max_steps", "stage_steps"):
        if not isinstance(opts[k], (int, np.integer)) or opts[k] < 1:
            raise InputError(f"{k}: expected a positive integer, found {opts[k]!r}")
    c = jnp.moveaxis(rows.weight, -1, 0)  # (3, N, J)
    y = rows.values.T  # (3, N)
    sg = jax.lax.stop_gradient  # the solver sees constants; the optimum differentiates implicitly
    joint = bool(get_model(name).shared_across_channels)  # a standard model: R, G, B jointly
    kernel, pack = (joint_light_sum_kernel, joint_package) if joint else (light_sum_kernel, package)
    out = kernel(
        name, sg(rows.u), sg(rows.v), sg(c), sg(y), sg(rows.pixel_weights), jax.random.PRNGKey(0) if key is None
        else key, n_starts=int(n_starts), max_steps=int(opts["max_steps"]), stage_steps=int(opts["stage_steps"]),
        rtol=float(opts["rtol"]), atol=float(opts["atol"]),
    )
    out["raw"], out["params"], out["l2"] = pack(name, out["raw"], rows.u, rows.v, c, y, rows.pixel_weights)
    status = out["status"]
    status = jnp.where((status == RESULTS.OK) & ~jnp.isfinite(out["l2"]), RESULTS.NONFINITE, status)
    out.update(status=status.astype(jnp.int32), success=(status == RESULTS.OK) & jnp.isfinite(out["l2"]))
    fitted = BaselineFit(**out, name=name)
    return raise_on_status("fit_to_images", fitted.status, fitted) if opts["throw"] else fitted
