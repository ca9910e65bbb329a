"""One entry point for every dataset: ``load("curet:25")``."""

from __future__ import annotations

import os

from .._errors import UnknownNameError
from .._measurements import Measurements
from ._curet import load_curet


def load(spec: str, root: str | os.PathLike | None = None) -> Measurements:
    """Load a dataset by name.

    Args:
        spec: ``"curet:25"``, ``"curet:25,33"``, ``"curet:quarry tile"`` or ``"curet"`` (all samples).
        root: data root (default ``$POLYJAX_DATA``).
    """
    kind, _, rest = spec.partition(":")
    kind = kind.strip().lower()
    if kind == "curet":
        samples = [s for s in rest.split(",") if s.strip()] or None
        return load_curet(root, samples)
    raise UnknownNameError(f"dataset {spec!r}: expected 'curet:<sample>'")
