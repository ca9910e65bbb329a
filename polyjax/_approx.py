r"""Approximation error of the polynomial model for a known true BRDF (paper, section 5).

For a true model ``eta`` sampled at the fitted directions, the least-squares fit
``f = Z beta_hat`` has, at design row ``z`` (equation (14)),

.. math::
    MSE(z) = \underbrace{z (Z'Z)^{-1} z' \sigma^2}_{\text{variance}}
           + \underbrace{\{z (Z'Z)^{-1} Z' \eta - \eta(z)\}^2}_{\text{bias}^2},

and the maximum approximation error (equation (16)) is
``delta_max = max_i {z_i (Z'Z)^{-1} Z' eta - eta_i}^2``. With ``weighted=True`` the same is computed
for the weighted fit polyjax actually performs (weights ``W = w cos^2 theta_u``):
``f = Z (Z'WZ)^+ Z'W eta`` and ``Var = sigma^2 ||z (Z'WZ)^+ Z' W^{1/2}||^2`` (errors of variance sigma^2);
``W = I`` gives equation (14) exactly. Everything goes through the SVD of ``W^{1/2} Z``; no ``n x n``
hat matrix is formed.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Bool, Float

from ._design import fitted_design
from ._directions import safe_normalize
from ._metrics import fit_weights
from ._solve.linalg import svd
from ._variables import get_variables


class ApproximationError(eqx.Module):
    """Equation (14) per sample and equation (16).

    Attributes:
        fitted: ``(n,)`` the least-squares fit of the true values.
        bias: ``(n,)`` ``fitted - eta`` (0 at samples not used).
        variance: ``(n,)`` variance term ``sigma^2 z (Z'Z)^{-1} z'``.
        mse: ``(n,)`` ``variance + bias^2``.
        delta_max: equation (16), ``max_i bias_i^2`` over the used samples.
        used: ``(n,)`` samples inside the cutoff.
    """

    fitted: Float[Array, " n"]
    bias: Float[Array, " n"]
    variance: Float[Array, " n"]
    mse: Float[Array, " n"]
    delta_max: Float[Array, ""]
    used: Bool[Array, " n"]


def approximation_error(
    u: ArrayLike,
    v: ArrayLike,
    true_values: ArrayLike,
    variables: str = "lafortune",
    degree: int = 5,
    *,
    sigma2: float = 0.0,
    weights: ArrayLike | None = None,
    cutoff_deg: float | None = 80.0,
    weighted: bool = False,
    basis: str = "legendre",
    interactions: bool = False,
) -> ApproximationError:
    """Variance/bias split of the MSE (equation (14)) and ``delta_max`` (equation (16)).

    Args:
        u, v: ``(n, 3)`` directions.
        true_values: ``(n,)`` values ``eta`` of the true BRDF at those directions.
        variables, degree, basis, interactions: the polynomial model, as in :func:`fit_polynomial`.
        sigma2: measurement-noise variance ``sigma^2`` for the variance term.
        weights, cutoff_deg: as in :func:`fit_polynomial` (the cutoff decides the samples used).
        weighted: False for the paper's ordinary least squares (equation (14)); True for the
            ``w cos^2 theta_u`` weighted fit.
    """
    eta = jnp.asarray(true_values)
    dtype = eta.dtype if jnp.issubdtype(eta.dtype, jnp.floating) else jnp.result_type(float)
    eta = eta.astype(dtype)
    u, _ = safe_normalize(jnp.asarray(u, dtype))
    v, _ = safe_normalize(jnp.asarray(v, dtype))
    w, wc2 = fit_weights(u, v, weights, None, cutoff_deg)
    used = w > 0
    x = get_variables(variables).fn(u, v)
    _, _, _, z = fitted_design(x, used, int(degree), basis, interactions)
    ww = wc2 if weighted else used.astype(dtype)
    sw = jnp.sqrt(ww)
    a = z * sw[:, None]
    uu, s, vt = svd(a)
    tol = jnp.finfo(dtype).eps * max(a.shape) * s[0]
    sinv = jnp.where(s > tol, 1.0 / jnp.where(s > tol, s, 1.0), 0.0)
    g = (z @ vt.T) * sinv  # rows z_i V S^+
    fitted = g @ (uu.T @ (sw * jnp.where(used, eta, 0.0)))
    bias = jnp.where(used, fitted - eta, 0.0)
    # Var(f_i) = sigma^2 || g_i U^T W^{1/2} ||^2 = sigma^2 g_i (U^T W U) g_i^T ; W = I on used rows gives ||g_i||^2
    m = uu.T @ (uu * ww[:, None]) if weighted else uu.T @ uu
    variance = sigma2 * jnp.einsum("ij,jk,ik->i", g, m, g)
    variance = jnp.where(used, variance, 0.0)
    return ApproximationError(
        fitted=fitted, bias=bias, variance=variance, mse=variance + bias**2, delta_max=jnp.max(bias**2), used=used
    )
