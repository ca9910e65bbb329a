"""The design of a polynomial fit: PCA of the explanatory variables over the kept samples, the affine scaling of
the components, and the basis columns of equation (3) (paper equation (13))."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from ._basis import design_matrix
from ._pca import fit_pca


def fitted_design(
    x: Float[Array, "n k"], keep: Bool[Array, " n"], max_degree: int, basis: str = "legendre",
    interactions: bool = False,
):
    """PCA of the kept samples, affine scaling, and the design matrix (equation (13)).

    Args:
        x: ``(n, k)`` explanatory variables (:func:`polyjax.explanatory_variables`).
        keep: ``(n,)`` the samples the fit uses (the PCA and the scaling are taken over them).
        max_degree: the polynomial degree ``p``.
        basis, interactions: as in :func:`polyjax.fit_polynomial`.

    Returns:
        ``(pca, centre, halfwidth, design)``: the :class:`polyjax.PCA`, the ``(k,)`` affine scaling
        ``t = (Z - centre) / halfwidth`` and the ``(n, m)`` design at every sample.


    A component whose range over the kept samples is within rounding of ``x`` (``1e3 eps max|x|``;
    e.g. Lafortune's ``X_1 + X_2 = 1`` when every sample has ``u = v``) carries no information,
    only rounding noise that column equilibration would blow up into huge coefficients. Its
    half-width is set to ``inf``: ``t = 0`` here and wherever the model is evaluated, so its
    columns are constants and the fit is flagged rank-deficient (minimum-norm solution).
    """
    pca, centre, hw, t = fitted_scaling(x, keep, basis)
    return pca, centre, hw, design_matrix(t, max_degree, basis, interactions)


def fitted_scaling(x: Float[Array, "n k"], keep: Bool[Array, " n"], basis: str = "legendre"):
    """The first half of :func:`fitted_design`: ``(pca, centre, halfwidth, t)`` with ``t (n, k)`` the scaled
    components ``(Z - centre) / halfwidth`` from which every design row is built."""
    pca = fit_pca(x, keep)
    z = pca(x)
    big = jnp.finfo(x.dtype).max
    lo = jnp.min(jnp.where(keep[:, None], z, big), axis=0)
    hi = jnp.max(jnp.where(keep[:, None], z, -big), axis=0)
    x_mag = jnp.max(jnp.where(keep[:, None], jnp.abs(x), 0.0))
    centre, hw = range_scaling(lo, hi, jnp.any(keep), x_mag, basis)
    return pca, centre, hw, (z - centre) / hw


def range_scaling(lo: Float[Array, " k"], hi: Float[Array, " k"], any_kept, x_mag, basis: str = "legendre"):
    """``(centre, halfwidth)`` of :func:`fitted_scaling` from the range ``[lo, hi]`` of the components over the kept
    samples (``any_kept``: whether there is one) and the largest ``|x|`` there, ``x_mag``."""
    k = lo.shape[0]
    lo = jnp.where(any_kept, lo, -1.0)
    hi = jnp.where(any_kept, hi, 1.0)
    hw = 0.5 * (hi - lo)
    flat = ~(hw > 1e3 * jnp.finfo(lo.dtype).eps * x_mag)
    if basis == "legendre":
        centre = 0.5 * (lo + hi)
    else:
        centre = jnp.zeros((k,), lo.dtype)
        hw = jnp.ones((k,), lo.dtype)
    hw = jnp.where(flat, jnp.inf, hw)
    return centre, hw
