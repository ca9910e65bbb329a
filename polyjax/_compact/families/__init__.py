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
``polyjax/_compact/data/basis.npz``; :class:`BasisFamily` takes another basis, e.g. a leave-one-out one, and says
which materials it was learned from in ``trained_on``), ``polynomial`` (the log-link, clamped polynomial).
"""

from typing import Hashable, Protocol

from .basis import BasisFamily
from .polynomial import PolynomialFamily


class Family(Protocol):
    """A compact model family (module docstring)."""

    name: str

    def configs(self, budget: int) -> list[Hashable]: ...

    def n_numbers(self, config) -> int: ...

    def fit(self, config, u, v, values, weights, mask, metric: str): ...

    def evaluate(self, config, params, u, v): ...


FAMILIES: dict[str, Family] = {f.name: f for f in (BasisFamily(), PolynomialFamily())}

__all__ = ["FAMILIES", "BasisFamily", "Family", "PolynomialFamily"]
