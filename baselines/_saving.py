"""How polyjax stores baseline fits and fits baselines from its command line.

:data:`KIND` is a :class:`polyjax.ModelKind` named ``"baselines.BaselineFit"``, found by polyjax through the
entry point group ``polyjax.models`` (``pyproject.toml``) and registered when :mod:`baselines` is imported;
``pj.save_model(path, baselines.fit(...))`` and ``pj.load_model(path)`` then work as for polynomial fits, and
``polyjax fit --model cook-torrance`` fits any model of :data:`baselines.MODELS`.
"""

from __future__ import annotations

from polyjax import RESULTS
from polyjax.internal import module_kind, register_model_kind

from ._fit import fit
from ._models.registry import MODELS
from ._result import BaselineFit


def _fit(name: str, data, *, cutoff_deg: float | None = 80.0, **options) -> BaselineFit:
    return fit(name, data, cutoff_deg=cutoff_deg, **options)


KIND = register_model_kind(module_kind(
    BaselineFit, "baselines.BaselineFit", models=MODELS, fit=_fit, status_names=tuple(s.name for s in RESULTS),
))
