"""The families of compact models, by name (``FAMILIES``), each a :class:`Family`."""

from __future__ import annotations

from collections.abc import Hashable
from typing import Protocol

from ._dev_polynomial import DEV_POLYNOMIAL


class Family(Protocol):
    """A family of compact models: static configurations, their number of stored numbers, a fit and an evaluation.

    ``fit(config, u, v, values, weights, mask, metric)`` takes RGB ``values (*batch, 3, n)`` and returns a pytree of
    arrays with leading axes ``batch``; ``evaluate(config, params, u, v)`` returns ``(*batch, 3, n)``: finite,
    non-negative and bounded everywhere above the horizon.
    """

    name: str

    def configs(self, budget: int) -> list[Hashable]: ...

    def n_numbers(self, config) -> int: ...

    def fit(self, config, u, v, values, weights, mask, metric: str): ...

    def evaluate(self, config, params, u, v): ...


FAMILIES: dict[str, Family] = {f.name: f for f in (DEV_POLYNOMIAL,)}
