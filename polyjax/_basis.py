r"""The design matrix of the polynomial model: equation (3) of the paper, in one place.

Equation (3) (Ozturk et al. 2008), in the ``k`` principal components ``Z_1..Z_k``:

.. math::
    f = \beta_0 + \sum_{d=1}^{p} \sum_{j=1}^{k} \beta_{(d-1)k+j}\, Z_j^{\,d}

— ``kp + 1`` parameters, columns ordered ``[1, Z_1..Z_k, Z_1^2..Z_k^2, ..., Z_1^p..Z_k^p]``
(equation (13)). With ``interactions=True`` the design is the full response surface of
equation (2): every monomial ``prod_j Z_j^{e_j}`` of total degree ``<= p`` (``C(k+p, p)`` terms,
graded order), an extension the paper mentions but does not fit.

Two bases span exactly the same space, so fits and L2 errors agree; they differ only in conditioning:

- ``"monomial"``: the literal powers ``Z_j^d`` of the raw principal components (the paper's form).
- ``"legendre"`` (default): each component is mapped affinely onto ``[-1, 1]`` over the fitted
  samples, ``t_j = (Z_j - c_j) / h_j``, and ``Z_j^d`` is replaced by the Legendre polynomial
  ``P_d(t_j)``. Since ``span{P_0..P_p}(t) = span{1, Z, .., Z^p}``, the column space is unchanged,
  but the columns are nearly orthogonal and the condition number stays small at high ``p``.
"""

from __future__ import annotations

import functools
import itertools
import math

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

BASES = ("legendre", "monomial")


def n_terms(k: int, degree: int, interactions: bool = False) -> int:
    """Number of parameters: ``k p + 1`` (equation (3)) or ``C(k + p, p)`` (equation (2))."""
    return math.comb(k + degree, degree) if interactions else k * degree + 1


@functools.lru_cache(maxsize=None)
def exponents(k: int, degree: int, interactions: bool = False) -> np.ndarray:
    """Exponent multi-indices of the design columns, ``(n_terms, k)`` int, in the paper's order.

    Without interactions: ``[0..0]``, then for ``d = 1..p`` and ``j = 1..k`` the index ``d e_j``
    (equation (13)). With interactions: all multi-indices of total degree ``<= p``, by degree,
    then in reverse lexicographic order (so ``Z_1^d`` comes first at each degree).
    """
    if not interactions:
        rows = [np.zeros(k, dtype=np.int64)]
        for d in range(1, degree + 1):
            for j in range(k):
                e = np.zeros(k, dtype=np.int64)
                e[j] = d
                rows.append(e)
        return np.stack(rows)
    rows = []
    for d in range(degree + 1):
        level = [e for e in itertools.product(range(d + 1), repeat=k) if sum(e) == d]
        rows.extend(sorted(level, reverse=True))
    return np.asarray(rows, dtype=np.int64).reshape(-1, k)


def term_degrees(k: int, degree: int, interactions: bool = False) -> np.ndarray:
    """Total degree of each design column."""
    return exponents(k, degree, interactions).sum(axis=1)


def _power_table(t: Float[Array, "n k"], degree: int, basis: str) -> Float[Array, "n k p1"]:
    """``T[i, j, d]`` = ``t_ij^d`` (monomial) or ``P_d(t_ij)`` (Legendre, three-term recurrence)."""
    cols = [jnp.ones_like(t)]
    if degree >= 1:
        cols.append(t)
    for d in range(2, degree + 1):
        if basis == "monomial":
            cols.append(cols[-1] * t)
        else:  # (d) P_d = (2d - 1) t P_{d-1} - (d - 1) P_{d-2}
            cols.append(((2 * d - 1) * t * cols[-1] - (d - 1) * cols[-2]) / d)
    return jnp.stack(cols, axis=-1)


def design_matrix(
    t: Float[Array, "... k"], degree: int, basis: str = "legendre", interactions: bool = False
) -> Float[Array, "... m"]:
    """Design-matrix rows ``z_i`` of equation (13) for (scaled) principal components ``t``.

    Args:
        t: ``(..., k)``; raw components ``Z`` for ``basis="monomial"``, components mapped to
           ``[-1, 1]`` for ``basis="legendre"``.
        degree: ``p``.
        basis: ``"legendre"`` or ``"monomial"``.
        interactions: include the interaction terms of equation (2).

    Returns:
        ``(..., n_terms)``.
    """
    k = t.shape[-1]
    table = _power_table(t, degree, basis)  # (..., k, p+1)
    exps = exponents(k, degree, interactions)
    if not interactions:
        # column 0 is the constant, then degree-major, component-minor
        body = jnp.swapaxes(table[..., 1:], -1, -2).reshape(*t.shape[:-1], k * degree)
        return jnp.concatenate([jnp.ones_like(t[..., :1]), body], axis=-1)
    out = jnp.ones(t.shape[:-1] + (exps.shape[0],), t.dtype)
    for j in range(k):
        out = out * table[..., j, :][..., exps[:, j]]
    return out
