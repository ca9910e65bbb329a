"""Compact model families: each a model of a few numbers per material, fitted in closed form or by a few
closed-form solves, bounded and non-negative at every direction above the horizon.

The protocol every family follows (``FAMILIES`` maps a family's name to its instance)::

    class Family(Protocol):
        name: str
        def configs(self, budget: int) -> list[Hashable]   # static configurations with n_numbers(c) <= budget
        def n_numbers(self, config) -> int                  # numbers stored per material, 3 channels counted
        def fit(self, config, u, v, values, weights, mask, metric: str) -> PyTree  # values (*batch, 3, n)
        def evaluate(self, config, params, u, v) -> Array  # (*batch, 3, n); finite, >= 0, bounded

Families: ``basis`` (a principal-component basis of ``log(1 + f)`` learned from measured materials, shipped in
``polyjax/_compact/data/basis.npz``; configurations ``(k, d)``: ``k`` basis rows and the Legendre terms of total
degree ``d`` of the grid's coordinates, ``d = -1`` for none; :class:`BasisFamily` takes another basis, e.g. a
leave-one-out one, and says which materials it was learned from in ``trained_on``), ``polynomial`` (the log-link,
clamped polynomial; configurations ``(variables, degree, interactions)``, the fitted
:class:`polyjax.PolynomialBRDF` as parameters), ``skew`` (the learned basis plus a non-reciprocal part, the first
``m`` rows times ``cos(theta_u) - cos(theta_v)``; configurations ``(k, m)``: :class:`SkewBasisFamily`), ``shared``
(one shape for the three channels, each channel its own offset and scale: the basis rows, skew rows and symmetric
polynomial terms; configurations ``(k, m, p)``: :class:`SharedShapeFamily`), ``sparse`` (the same one shape, its
``k`` terms chosen per material from a dictionary of basis rows, skew rows, symmetric terms and hats in the grid's
half and difference angles, the choice stored as a bit mask; configurations ``(k, D)``: :class:`SparseShapeFamily`).

No deviation from the protocol above. ``metric`` is ``"log"`` (the default: the basis fit weighs the log metric and,
by ``basis.MIX_LOG``, equation (11)'s L2) or ``"l2"`` (the L2 alone). The fits are not jitted as a whole here (the
basis fit's solves are); a caller jits ``fit`` with ``config`` static.
"""

from typing import Hashable, Protocol

from .basis import BasisFamily
from .polynomial import PolynomialFamily
from .shared import SharedShapeFamily
from .skew import SkewBasisFamily
from .sparse import SparseShapeFamily


class Family(Protocol):
    """A compact model family (module docstring)."""

    name: str

    def configs(self, budget: int) -> list[Hashable]: ...

    def n_numbers(self, config) -> int: ...

    def fit(self, config, u, v, values, weights, mask, metric: str): ...

    def evaluate(self, config, params, u, v): ...

    # what the choice calls (``polyjax/_compact/select.py``): ``program(config)``, ``(key, arrays)``: a static key
    # shared by configurations that share one compiled fit and the configuration's arrays (data);
    # ``fit_program(key, arrays, u, v, values, weights, mask, metric)``, ``evaluate_program(key, arrays, params, u,
    # v)`` and ``unpad(config, params)``, the shared program's fit, evaluation and the configuration's own
    # parameters from its result (a family without shared programs: ``program(config) = (config, ())`` and the
    # other three its own ``fit``, ``evaluate`` and the identity).
    # optional: ``candidates(budget)``, the configurations the choice may try (a thinned ``configs``; else
    # ``configs``); ``candidate_chains(budget)``, the same as lists walked in order while the held-out error falls
    # (else each candidate alone); ``design(key, arrays, u, v)`` and ``from_design(key, arrays, phi, params)``,
    # the program's columns and its values from them (the choice then fits every fold from shared
    # factorisations); ``fit_folds(key, arrays, u, v, values, weights, mask, held, parts, metric)``, every fold's
    # fit at once (``(*batch, K, ...)``); else each fold by ``fit_program`` with its held-out samples masked out.


FAMILIES: dict[str, Family] = {f.name: f for f in (BasisFamily(), PolynomialFamily(), SkewBasisFamily(),
                                                SharedShapeFamily(), SparseShapeFamily())}

__all__ = ["FAMILIES", "BasisFamily", "Family", "PolynomialFamily", "SharedShapeFamily", "SkewBasisFamily",
           "SparseShapeFamily"]
