r"""Fitting the polynomial BRDF straight from photographs: one closed-form weighted least-squares solve.

For a scene with known geometry, camera and lights, the radiance of a pixel that sees the target
object is linear in its BRDF (:mod:`polyjax.render._linear`): ``L = sum_j c_j f(u_j, v)``. With
the polynomial of equation (3), ``f = sum_i beta_i B_i(u, v)``, every kept pixel is one row of a
linear system in ``beta``,

.. math::
    L_{c} = \sum_i \beta_{c,i} \Big(\sum_j c_{j,c}\, B_i(u_j, v)\Big),

per colour channel ``c``: under one point or directional light the row is ``E cos(theta_u) B(u, v)``
(one observation ``f(u, v) E``), under an environment map a known weighted sum of basis values.
No initial guess, no iteration: the same basis, PCA and solver as :func:`polyjax.fit_polynomial`.
"""

from __future__ import annotations

import functools
import inspect
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from .._arrays import is_concrete
from .._basis import BASES
from .._design import fitted_design as _design_for
from .._errors import InputError
from .._model import RESULTS, SPEC_FIELDS, PolynomialBRDF, PolynomialSpec, spec_of, with_clamp
from .._solve.lstsq import METHODS, weighted_lstsq
from .._solve.threads import one_lapack_thread
from .._variables import get_variables
from ._degree import TOP_DEGREE, step_down
from ._rows import image_rows
from ._samples import WEIGHTINGS, fit_samples


@one_lapack_thread
def fit_polynomial_to_images(
    scenes: Sequence,
    images: Sequence[ArrayLike] | ArrayLike,
    variables: str = "rusinkiewicz",
    degree: int | str = "auto",
    *,
    target: int = 0,
    pixel_weights: Sequence[ArrayLike] | ArrayLike | None = None,
    saturation: float | None = None,
    cutoff_deg: float | None = None,
    spp: int = 64,
    seed: int = 0,
    basis: str = "legendre",
    interactions: bool = True,
    method: str = "qr",
    rcond: float | None = None,
    link: str = "log",
    eps: float = 1e-3,
    steps: int = 3,
    weighting: str = "auto",
    robust_steps: int = 0,
    clamp: bool = True,
    spec: PolynomialSpec | None = None,
) -> PolynomialBRDF:
    r"""Fit an RGB polynomial BRDF (equation (3)) to images of one object under known lighting. Over 80 lines
    because of this docstring; the code is three steps: option checks, :func:`image_rows`, ``_solve_images`` (or
    :func:`polyjax.inverse._samples.fit_samples` for the BRDF-sample fits).

    Minimises, per colour channel, ``sum_pixels w_px (I_px - L_px(beta))^2`` over the kept pixels of
    every image, where ``L_px(beta)`` is the render of the polynomial (linear in ``beta``, see the
    module notes): a single weighted least-squares solve (:func:`polyjax.weighted_lstsq`, QR then SVD).

    **Pixels kept**: those whose primary ray hits object ``target``, with finite values in all three
    channels, no channel at or above ``saturation``, lit (some light weight ``> 0``), not in the
    shadow of any point or directional light that faces them (a partly shadowed pixel is excluded,
    as are its shadow edges), with ``theta_v`` and every lit point light's ``theta_u`` within
    ``cutoff_deg`` (grazing pixels have the least reliable normals and footprints; the same 80-degree
    cutoff as :func:`polyjax.fit_polynomial`). The rows come from :func:`polyjax.image_rows`, which
    ``baselines.fit_to_images`` shares.

    **Pixel weighting**: residuals are measured in radiance, the quantity the images hold, with weight
    ``w_px`` (``pixel_weights``, 1 by default): the maximum-likelihood fit for pixel noise of constant
    variance, and the fit that maximises the PSNR of re-renders. In BRDF terms a point-light pixel's
    residual is ``E cos(theta_u) (b - f)``, so the weight on squared BRDF residuals is
    ``(I / r^2)^2 cos^2(theta_u)``: for lights at a fixed distance, the ``cos^2(theta_u)`` weighting of
    the Ngan et al. objective (equation (11)) that ``fit_polynomial`` minimises, with the sphere's
    pixels as the samples. Give each image a weight ``1 / sigma^2`` (its noise) through ``pixel_weights``.

    The principal components and the ``[-1, 1]`` scaling are those of the explanatory variables of
    every (pixel, light sample) pair that enters the fit, as in ``fit_polynomial``.

    Differentiable (under ``jit``) with respect to the images, the pixel weights and the scenes' lights
    and environment texels, through :func:`polyjax.weighted_lstsq`'s derivative; the pixel selection is
    piecewise constant.

    Args:
        scenes: a :class:`polyjax.render.Scene` or a sequence of them, one per image; the BRDF of the
            target object is a placeholder (not used). Direct lighting only (``max_bounces=0``).
        images: ``(H, W, 3)`` linear RGB radiance per scene (a sequence, or an array ``(n, H, W, 3)``).
        variables: explanatory variables (as in :func:`polyjax.fit_polynomial`).
        degree: the polynomial degree ``p`` (one integer), or ``"auto"`` (the default): with BRDF-space weights
            (``weighting="brdf"``, the default for photographs) the highest degree up to 8 whose fit has full rank
            and a condition number of at most 50 in every channel (:mod:`polyjax.inverse._degree`; fewer lights, a
            lower degree; ``model.max_degree`` says which), with radiance weights 8. Needs concrete inputs: under
            ``jax.jit`` or ``jax.grad`` give an integer. With ``spec=``, the spec's degree.
        target: index of the fitted object in each scene's ``objects``.
        pixel_weights: ``(H, W)`` non-negative weights per image (or a scalar per image), 1 by default.
        saturation: pixels with a channel at or above this value are excluded (the clipping level of
            the camera); None keeps every finite pixel.
        cutoff_deg: grazing cutoff in degrees; None keeps every pixel above the horizon.
        spp: environment samples per pixel of the design (scenes with an environment map).
        seed: random seed of the environment samples.
        basis, interactions, method, rcond: as in :func:`polyjax.fit_polynomial`.
        link, eps, steps: ``link="log"`` fits ``f = exp(poly) - eps`` (:func:`polyjax.fit_log_polynomial`, on the
            pixels' BRDF samples; one light sample per pixel).
        weighting: ``"radiance"`` (the squared pixel residuals, above), ``"brdf"`` (``sum w (I / c - f)^2``:
            the residuals of the pixels' BRDF samples ``I / c``, one light sample per pixel;
            :mod:`polyjax.inverse._samples`), or ``"auto"`` (the default: ``"brdf"`` when every pixel has one light
            sample, photographs under point or directional lights; ``"radiance"`` otherwise).

    **Defaults** (``rusinkiewicz`` with interactions, p = 8 or lower where the lights do not determine it, the log
    link, clamped to the fitted box, BRDF-space weights, no grazing cutoff): the configuration measured best on
    photographs (``benchmarks/bench_photometric.py``, the DiLiGenT ball; the degree's step-down on six DiLiGenT
    objects, ``benchmarks/bench_log_bound.py``), the same as ``polyjax fit-photos``; clamped, so no default
    extrapolates unbounded. Scenes lit by an environment map (several light samples per pixel) need
    ``link="identity"``.
        robust_steps: reweighted solves after the first (Tukey's biweight of the relative residuals, scale from
            their MAD: :mod:`polyjax.inverse._samples`); 0: none. One light sample per pixel.
        clamp: the model evaluates its polynomial at the scaled components clamped to the box of the fitted
            pixels' components (:attr:`polyjax.PolynomialBRDF.clamp`): bounded under lights outside the fitted
            lights' directions, where a high-degree polynomial diverges (``docs/photometric.md``). Legendre basis
            only; the fit is the same.
        spec: the model's definition as one value (:class:`polyjax.PolynomialSpec`, one degree), instead of
            ``variables``, ``degree``, ``basis``, ``interactions``, ``link``, ``eps`` and ``clamp``.

    Returns:
        :class:`polyjax.PolynomialBRDF` with batch shape ``(3,)`` (R, G, B lanes) that renders like any
        fitted model. ``l2`` holds the root-mean-square radiance residual over the kept pixels (image
        units, not equation (11); with ``link="log"``, ``weighting="brdf"`` or robust steps, equation (11) of the
        BRDF samples with their weights); ``n_used`` the number of kept pixels; ``status`` ``NO_SAMPLES`` when
        no pixel was kept and ``RANK_DEFICIENT`` when the pixels do not determine every coefficient.

    Raises:
        InputError: scenes/images disagree in number or size, an image is not ``(H, W, 3)``, bad options,
            or a scene with inter-reflections.
    """
    if isinstance(degree, str) and degree != "auto":
        raise InputError(f"degree: expected one non-negative integer or 'auto', found {degree!r}")
    auto = spec is None and isinstance(degree, str)
    spec = spec_of("fit_polynomial_to_images", spec, _SPEC_DEFAULTS, variables=variables,
                   degree=TOP_DEGREE if auto else degree, basis=basis, interactions=interactions, link=link, eps=eps,
                   clamp=clamp)
    return fit_images(scenes, images, spec, auto, target=target, pixel_weights=pixel_weights, saturation=saturation,
                      cutoff_deg=cutoff_deg, spp=spp, seed=seed, method=method, rcond=rcond, steps=steps,
                      weighting=weighting, robust_steps=robust_steps)[0]


@one_lapack_thread
def fit_images(scenes, images, spec: PolynomialSpec, auto: bool, *, target=0, pixel_weights=None, saturation=None,
               cutoff_deg=None, spp=64, seed=0, method="qr", rcond=None, steps=3, weighting="auto",
               robust_steps=0) -> tuple[PolynomialBRDF, list[tuple[int, str]]]:
    """:func:`fit_polynomial_to_images` of the definition ``spec``, its degree fixed or, with ``auto``, the highest
    well-conditioned one up to it (:func:`polyjax.inverse._degree.step_down`; the image rows made once); returns the
    model and ``[(degree, why), ...]`` of the degrees left out (``polyjax fit-photos`` prints them)."""
    variables, degree, basis, interactions, link, eps, clamp = (getattr(spec, k) for k in SPEC_FIELDS)
    vs = _check_image_fit_options(variables, degree, basis, method)
    if int(robust_steps) != robust_steps or int(robust_steps) < 0:
        raise InputError(f"robust_steps: expected a non-negative integer, found {robust_steps!r}")
    if link not in ("identity", "log"):
        raise InputError(f"link: expected 'identity' or 'log', found {link!r}")
    if weighting not in WEIGHTINGS + ("auto",):
        raise InputError(f"weighting: expected one of {WEIGHTINGS + ('auto',)}, found {weighting!r}")
    rows = image_rows(scenes, images, target=target, pixel_weights=pixel_weights, saturation=saturation,
                      cutoff_deg=cutoff_deg, spp=spp, seed=seed)
    if weighting == "auto":  # BRDF-space residuals where each pixel is one BRDF sample (point, directional lights)
        weighting = "brdf" if rows.u.shape[1] == 1 else "radiance"
    fit_at = functools.partial(_fit_rows, rows, vs.name, basis=basis, interactions=bool(interactions), method=method,
                               rcond=rcond, link=link, eps=eps, steps=steps, weighting=weighting,
                               robust_steps=int(robust_steps), clamp=clamp)
    # the step-down's bound was measured on BRDF-space rows (one light sample per pixel); a radiance design summed
    # over an environment's samples is smoother and worse conditioned at every degree (p = 8: 5e4 where four point
    # lights give 5e2), so there "auto" keeps the top degree
    if auto and weighting == "brdf":
        return step_down(fit_at, int(degree))
    return fit_at(int(degree)), []


def _fit_rows(rows, variables, degree, *, basis, interactions, method, rcond, link, eps, steps, weighting,
              robust_steps, clamp) -> PolynomialBRDF:
    """The fit of one degree on the image rows ``rows`` (:func:`image_rows`), options checked."""
    if link != "identity" or weighting != "radiance" or robust_steps:
        options = dict(basis=basis, interactions=interactions, method=method, rcond=rcond)
        if link == "log":
            options.update(link="log", eps=eps, steps=steps)
        return with_clamp(fit_samples(rows, variables, degree, weighting=weighting, robust_steps=robust_steps,
                                      options=options), clamp)
    u, v, c, y, wpx, keep = rows.u, rows.v, rows.weight, rows.values, rows.pixel_weights, rows.keep
    # one design for the three channels when every light is grey (the same weights in R, G and B)
    shared = False
    if is_concrete(c):
        cn = np.asarray(c)
        shared = bool(np.array_equal(cn[..., 0], cn[..., 1]) and np.array_equal(cn[..., 0], cn[..., 2]))
    return with_clamp(_solve_images(u, v, c, y, wpx, keep, variables=variables, degree=degree, basis=basis,
                                    interactions=interactions, method=method, rcond=rcond, shared=shared), clamp)


#: the keyword defaults of :func:`fit_polynomial_to_images` that :class:`polyjax.PolynomialSpec` groups
_SPEC_DEFAULTS = {k: inspect.signature(fit_polynomial_to_images).parameters[k].default for k in SPEC_FIELDS}


def _check_image_fit_options(variables, degree, basis, method):
    """The variable set of ``variables``; raises :class:`InputError` for a bad degree, basis or method."""
    vs = get_variables(variables)
    if basis not in BASES:
        raise InputError(f"basis: expected one of {BASES}, found {basis!r}")
    if method not in METHODS:
        raise InputError(f"method: expected one of {METHODS}, found {method!r}")
    if np.ndim(degree) != 0 or int(degree) != degree or int(degree) < 0:
        raise InputError(f"degree: expected one non-negative integer, found {degree!r}")
    return vs


@functools.partial(
    jax.jit, static_argnames=("variables", "degree", "basis", "interactions", "method", "rcond", "shared")
)
def _solve_images(u, v, c, y, wpx, keep, variables, degree, basis, interactions, method, rcond,
                  shared) -> PolynomialBRDF:
    """The design of equation (3) summed over light samples, and one weighted solve per channel (one solve
    with three right-hand sides when ``shared``: every light weight is the same in R, G and B)."""
    n, n_j, _ = u.shape
    lit = keep[:, None] & (jnp.sum(c, axis=-1) > 0)  # (N, J): the (pixel, light) pairs in the fit
    safe_u = jnp.where(lit[..., None], u, jnp.asarray([0.0, 0.0, 1.0], u.dtype))
    safe_v = jnp.where(keep[:, None], v, jnp.asarray([0.0, 0.0, 1.0], v.dtype))
    x = get_variables(variables).fn(safe_u, safe_v[:, None, :])  # (N, J, k)
    k = x.shape[-1]
    pca, centre, hw, d = _design_for(x.reshape(n * n_j, k), lit.reshape(-1), degree, basis, interactions)
    m = d.shape[-1]
    d = jnp.where(lit.reshape(-1, 1), d, 0.0).reshape(n, n_j, m)
    den = jnp.sum(wpx)

    def rms_of(r):
        ms = jnp.sum(wpx[:, None] * r * r, axis=0) / jnp.where(den > 0, den, 1.0)
        return jnp.where(den > 0, jnp.sqrt(ms), jnp.inf)

    if shared:
        design = jnp.einsum("njm,nj->nm", d, c[..., 0])
        sol = weighted_lstsq(design, y, wpx, method=method, rcond=rcond)
        coef, rms = sol.coefficients.T, rms_of(y - design @ sol.coefficients)
        rank, cond, n_act = (jnp.broadcast_to(a, (3,)) for a in (sol.rank, sol.condition, sol.n_active))
    else:
        design = jnp.einsum("njm,njc->cnm", d, c)  # (3, N, m): one design per channel

        def channel(dc, yc):
            sol = weighted_lstsq(dc, yc, wpx, method=method, rcond=rcond)
            rms = rms_of((yc - dc @ sol.coefficients)[:, None])[0]
            return sol.coefficients, rms, sol.rank, sol.condition, sol.n_active

        coef, rms, rank, cond, n_act = jax.vmap(channel)(design, y.T)
    n_used = jnp.sum(keep).astype(jnp.int32)
    status = jnp.where(n_used == 0, RESULTS.NO_SAMPLES,
                       jnp.where(rank < n_act, RESULTS.RANK_DEFICIENT, RESULTS.OK)).astype(jnp.int32)
    coef = jnp.where((n_used == 0), 0.0, coef)
    three = lambda a: jnp.broadcast_to(a, (3,) + jnp.shape(a))  # noqa: E731
    return PolynomialBRDF(
        coefficients=coef, degree=jnp.full((3,), degree, jnp.int32), mean=three(pca.mean),
        rotation=three(pca.rotation), centre=three(centre), halfwidth=three(hw), l2=rms, rank=rank, condition=cond,
        n_used=jnp.full((3,), n_used), status=status, variables=variables, basis=basis, interactions=interactions,
        max_degree=degree,
    )


__all__ = ["fit_images", "fit_polynomial_to_images"]
