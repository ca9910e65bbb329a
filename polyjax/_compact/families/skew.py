r"""The ``skew`` family: the learned basis with a non-reciprocal part, for measurements with ``f(u, v) != f(v, u)``.

The basis family (``basis.py``) is reciprocal by construction: its rows are tabulated on the folded grid
(``_grid.py``), the same for ``(u, v)`` and ``(v, u)``. Real measurements need not be: the RGL-EPFL files, evaluated
as their authors' code evaluates them, differ from their swap by 0.7x (paper) and 1.6x (satin) the L2 error of a
33-number basis fit (``benchmarks/RESULTS.md``). The model of one channel adds the first ``m`` basis rows times the
odd factor ``t = cos(theta_u) - cos(theta_v)``:

.. math::
    g(u, v) = \sum_{j < k} c_j B_j(u, v) + t(u, v) \sum_{j < m} e_j B_j(u, v), \qquad
    f(u, v) = \max\big(0, (\exp(\min(g, G_{max})) - 1) / K\big),

so ``g(u, v) - g(v, u) = 2 t \sum_j e_j B_j``: the part of ``log(1 + K f)`` that changes sign under the swap, shaped
like the material's own lobes (a peak where the basis has one) rather than like a low-degree polynomial. ``|t| <= 1``
and the rows are bounded, so ``g`` is bounded by the coefficients at every direction above the horizon (and by
``G_MAX``); ``f`` is never negative. ``3 (k + m)`` numbers per material.

The fit is the basis family's, on the ``k + m`` columns: one linearised weighted solve, then ``basis.STEPS``
Gauss-Newton steps on the log metric mixed with equation (11)'s L2 (QR, then the SVD of the triangle).

Configurations ``(k, m)``: ``m`` in :data:`SKEW_ROWS` and, for each, only the largest ``k >= max(m, MIN_ROWS)``
within the budget (a handful of candidates per budget for the cross-validation, and the configuration of a saved
model is found again among those of its own size).
"""

import jax.numpy as jnp

from . import _grid
from ._on_basis import OnLearnedBasis
from .basis import _fit, _value, mix_for

#: the numbers of basis rows the non-reciprocal part may use
SKEW_ROWS = (1, 2, 3, 5, 8, 13, 21)
#: the numbers of skew rows :func:`polyjax.fit_compact` tries (:meth:`SkewBasisFamily.candidates`)
CANDIDATE_ROWS = (1, 2)
#: the fewest symmetric basis rows the family offers beside its skew rows (:meth:`SkewBasisFamily.configs`)
MIN_ROWS = 6


def skew_factor(u, v):
    """``t = cos(theta_u) - cos(theta_v)`` ``(n,)``: odd under the swap of light and view, in ``[-1, 1]``."""
    return jnp.clip(u[..., 2], 0.0, 1.0) - jnp.clip(v[..., 2], 0.0, 1.0)


class SkewBasisFamily(OnLearnedBasis):
    """The learned basis with a non-reciprocal part (module docstring); ``basis`` and ``trained_on`` as
    :class:`BasisFamily` (default: the shipped basis); parameters ``(*batch, 3, k + m)``."""

    name = "skew"

    def configs(self, budget: int) -> list[tuple[int, int]]:
        """``(k, m)``: for each ``m`` of :data:`SKEW_ROWS`, the largest ``k`` (``max(m, MIN_ROWS) <= k <=`` the
        basis rows) with ``3 (k + m)`` at most ``budget``. Below :data:`MIN_ROWS` symmetric rows the skew rows take
        the numbers the shape needs: ``(2, 1)`` (9 numbers) reached 16x the data's maximum on gold-metallic-paint's
        MERL grid (``tests/test_compact.py``'s sweep), so the family starts at 21 numbers."""
        out = []
        for m in SKEW_ROWS:
            k = min(budget // 3 - m, self._rows)
            if k >= max(m, MIN_ROWS):
                out.append((k, m))
        return out

    def candidates(self, budget: int) -> list[tuple[int, int]]:
        """The configurations :func:`polyjax.fit_compact` tries within ``budget``: those of :meth:`configs` with
        ``m`` in :data:`CANDIDATE_ROWS` (what MERL's reciprocal materials choose; a strongly non-reciprocal
        measurement, the RGL satin, chooses the ``shared`` family's skew rows, ``shared.py``)."""
        return [c for c in self.configs(budget) if c[1] in CANDIDATE_ROWS]

    def candidate_chains(self, budget: int) -> list[list[tuple[int, int]]]:
        """Each candidate a chain of its own (every one is cross-validated): the held-out error is not monotone
        in ``m`` (MERL's reciprocal materials do best with 1-2 skew rows, the RGL satin with 5 at 33 numbers), so
        no order of them can be walked while it falls."""
        return [[c] for c in self.candidates(budget)]

    def n_numbers(self, config) -> int:
        k, m = config
        return 3 * (int(k) + int(m))

    def columns(self, config, u, v):
        """``(n, k + m)``: the first ``k`` basis rows read at the directions, then the first ``m`` times ``t``."""
        return self.design(config, self.program(config)[1], u, v)

    # the choice's program interface (polyjax/_compact/select.py; program, fit and evaluate: OnLearnedBasis)

    def design(self, config, arrays, u, v):
        """``(n, k + m)``: :meth:`columns` of the basis table ``arrays[0]``."""
        k, m = config
        phi = _grid.sample(arrays[0][:k], u, v)
        return jnp.concatenate([phi, skew_factor(u, v)[:, None] * phi[:, :m]], -1)

    def from_design(self, config, arrays, phi, params):
        return _value(jnp.einsum("nk,...k->...n", phi, params))

    def fit_program(self, config, arrays, u, v, values, weights, mask, metric: str = "log"):
        return _fit(self.design(config, arrays, u, v), u, v, jnp.asarray(values), weights, mask, mix_for(metric))

    def evaluate_program(self, config, arrays, params, u, v):
        return self.from_design(config, arrays, self.design(config, arrays, u, v), params)

