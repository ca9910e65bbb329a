"""The public front door of the polynomial fits: :func:`fit_polynomial` checks the link and hands the fit to the
closed form (:mod:`polyjax._fit.closed_form`) or the log-space fit built on it (:mod:`polyjax._fit.log`)."""

from __future__ import annotations

import inspect
from typing import Sequence

from jaxtyping import ArrayLike

from .._basis import n_terms
from .._errors import InputError
from .._measurements import Measurements
from .._model import SPEC_FIELDS, PolynomialBRDF, PolynomialSpec, spec_of, with_clamp
from .._solve.threads import one_lapack_thread
from .._variables import get_variables
from .closed_form import LANE_BLOCK, fit_closed_form
from .log import fit_log_polynomial


@one_lapack_thread
def fit_polynomial(
    u,
    v: ArrayLike | None = None,
    values: ArrayLike | None = None,
    variables: str = "lafortune",
    degree: int | Sequence[int] = 5,
    *,
    weights: ArrayLike | None = None,
    mask: ArrayLike | None = None,
    cutoff_deg: float | None = 80.0,
    basis: str = "legendre",
    interactions: bool = False,
    method: str = "qr",
    rcond: float | None = None,
    rank_deficient: str = "flag",
    nonfinite: str = "error",
    throw: bool = False,
    lane_block: int = LANE_BLOCK,
    link: str = "identity",
    eps: float = 1e-3,
    steps: int = 3,
    clamp: bool = False,
    spec: PolynomialSpec | None = None,
) -> PolynomialBRDF:
    r"""Fit the polynomial BRDF of equation (3) by weighted least squares, in closed form. (Over 80 lines because
    this docstring documents every argument; the body dispatches on the link: the closed form,
    :func:`polyjax._fit.closed_form.fit_closed_form`, or the log-space fit.)

    Minimises the Ngan et al. objective of equation (11),
    ``sum_i w_i cos^2(theta_u,i) (b_i - f(u_i, v_i))^2``, over the samples with ``theta_u`` and
    ``theta_v`` at most ``cutoff_deg``. The explanatory variables (section 3) are transformed to
    principal components over those samples, the design of equation (13) is built, and the
    solve is QR + SVD of the square-root-weighted design (:func:`polyjax.weighted_lstsq`).
    Inputs follow the rules every fitter shares (``polyjax/_inputs.py``); the fit is differentiable and
    batches under ``jit``/``vmap`` (``throw`` then raises through :func:`equinox.error_if`).

    Args:
        u: ``(n, 3)`` light directions, or a :class:`polyjax.Measurements` (then ``v``/``values``
           and its ``weights``/``mask`` are taken from it), or ``(*dbatch, n, 3)``: directions of their own for
           every lane (each texel of a capture), ``dbatch`` a leading part of the batch shape of ``values``
           (``values (H, W, 3, n)``, ``u (H, W, n, 3)``: a texel's channels share its directions and its design).
           Each such lane gets its own PCA and design, exactly as if fitted alone.
        v: view directions, the shape of ``u``.
        values: ``(*batch, n)`` measured BRDF, samples last; every leading axis (materials, channels)
           is fitted independently in the same call.
           The fit runs in the dtype of ``values`` (float32 or float64; integers are converted to the
           default float, float16/bfloat16 to float32; complex values are rejected).
        variables: a registered variable set: ``"ward"``, ``"ashikhmin-shirley"``, ``"lafortune"``,
           ``"lafortune-anisotropic"`` or a user's own.
        degree: ``p``, or a sequence of degrees: the result then has a leading degree axis.
        weights: solid-angle weights ``w_i`` (``(n,)`` or ``(*batch, n)``; ``(*dbatch, n)`` with per-lane
           directions), ones by default.
        mask: ``(n,)`` (shared by every lane) or ``(*batch, n)`` (``(*dbatch, n)``) validity mask; False samples
           are not fitted.
        cutoff_deg: grazing cutoff in degrees (80 in the paper); None keeps all samples above the horizon.
        basis: ``"legendre"`` (default, well conditioned) or ``"monomial"`` (the paper's literal powers);
           both span the same space and give the same fit.
        interactions: fit the full response surface of equation (2) instead of equation (3).
        method: ``"qr"`` (default) or ``"svd"``.
        rcond: relative singular-value cutoff for the rank; default ``eps * max(m, sqrt(n))``.
        rank_deficient: ``"flag"`` (minimum-norm solution, ``status = RANK_DEFICIENT``) or ``"error"``
           (the same as ``throw=True``).
        nonfinite: ``"error"`` (raise on NaN/inf in ``values`` where the mask is True; under an outer ``jit``,
           where nothing can be raised before the fit, such a lane is flagged ``NONFINITE``) or ``"mask"``
           (drop those samples).
        throw: raise :class:`polyjax.FitError` naming the first lane whose status is not ``OK``
           (rank-deficient, no samples, non-finite values or L2); under ``jit`` an
           :func:`equinox.error_if` error with that code's message. Lanes with no samples are always
           ``NO_SAMPLES`` (L2 = inf); a lane whose L2 overflows is ``NONFINITE``.
        lane_block: lanes fitted at once when lanes have samples of their own (per-lane weights, masks or
           directions): a :func:`jax.lax.map` over blocks of lanes, ``vmap`` inside a block, so memory grows with
           the block (about ``lane_block * n * m`` floats), not with the batch. Same results for any block size.

        link, eps, steps: ``link="log"`` fits ``f = exp(poly) - eps`` to equation (11) by ``1 + steps``
           weighted solves (:func:`polyjax.fit_log_polynomial`, one integer ``degree``); ``"identity"`` (default)
           is equation (3) itself.
        clamp: the model evaluates its polynomial at the scaled components clamped to the fitted box (a constant
           extension outside the fitted samples' range, :attr:`polyjax.PolynomialBRDF.clamp`); the fit itself is
           the same. Legendre basis only.
        spec: the model's definition as one value (:class:`polyjax.PolynomialSpec`: ``variables``, ``degree``,
           ``basis``, ``interactions``, ``link``, ``eps``, ``clamp``), instead of those keywords; e.g. a fitted
           model's ``.spec`` to fit the same family to other data. Keywords that differ from it are refused.

    Inputs sharded over their leading batch axis (a :class:`jax.sharding.NamedSharding` on a device mesh,
    e.g. from :func:`jax.device_put`) are fitted where they are, each device its own lanes
    (:func:`jax.shard_map`), and the result comes back sharded the same way (``docs/scale.md``).

    Returns:
        :class:`polyjax.PolynomialBRDF` with batch shape ``values.shape[:-1]`` (preceded by the
        degree axis when ``degree`` is a sequence); ``status`` holds :class:`polyjax.RESULTS` codes.
    """
    if isinstance(u, Measurements) and isinstance(v, str):  # fit_polynomial(data, "ward", degree=3)
        u, v, variables = u, None, v
    spec = spec_of("fit_polynomial", spec, _SPEC_DEFAULTS, variables=variables, degree=degree, basis=basis,
                   interactions=interactions, link=link, eps=eps, clamp=clamp)
    if spec.link == "log":  # log-space model f = exp(poly) - eps: polyjax/_fit/log.py
        if nonfinite != "error":
            raise InputError(f"nonfinite: the log link takes 'error' only (mask bad samples), found {nonfinite!r}")
        return fit_log_polynomial(u, v, values, spec=spec, steps=steps, weights=weights, mask=mask,
                                  cutoff_deg=cutoff_deg, method=method, rcond=rcond, rank_deficient=rank_deficient)
    return with_clamp(fit_closed_form(u, v, values, spec.variables, spec.degree, weights=weights, mask=mask,
                                      cutoff_deg=cutoff_deg, basis=spec.basis, interactions=spec.interactions,
                                      method=method, rcond=rcond, rank_deficient=rank_deficient, nonfinite=nonfinite,
                                      throw=throw, lane_block=lane_block), spec.clamp)


#: the keyword defaults of :func:`fit_polynomial` that :class:`PolynomialSpec` groups
_SPEC_DEFAULTS = {k: inspect.signature(fit_polynomial).parameters[k].default for k in SPEC_FIELDS}


def n_parameters(variables: str, degree: int, interactions: bool = False) -> int:
    """``k p + 1`` for a variable set (equation (3)); ``C(k + p, p)`` with interactions (equation (2))."""
    return n_terms(get_variables(variables).k, degree, interactions)
