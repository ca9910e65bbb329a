"""Compact BRDF models: families of models of at most N numbers per material (``families/``), the fitted model
(``model``: :class:`CompactBRDF`), the choice among families by cross-validation (``select``), the front door
(``fit``: :func:`fit_compact`) and its saved-model kind (``saving``)."""

from . import saving  # noqa: F401 - registers the saved-model kind polyjax.CompactBRDF
from .fit import BudgetError, compact_families, fit_compact, fit_compact_family
from .model import CompactBRDF

__all__ = ["BudgetError", "CompactBRDF", "compact_families", "fit_compact", "fit_compact_family"]
