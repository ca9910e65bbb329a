"""The settings of the multi-start Levenberg-Marquardt fit as one value: :class:`MultiStart`."""

from __future__ import annotations

import equinox as eqx
import numpy as np

from polyjax import InputError

from ._multistart import BACKENDS
from ._starts import check_n_starts

#: the fields of :class:`MultiStart`, in order: the solver's settings wherever they are given by keyword
SOLVER_FIELDS = ("n_starts", "backend", "max_steps", "rtol", "atol", "stage_steps", "refine", "limit_steps")


class MultiStart(eqx.Module):
    r"""How :func:`baselines.fit` (and :func:`baselines.fit_to_images`) solves: Levenberg-Marquardt from
    ``n_starts`` starting points per lane, a frozen, hashable value (``solver=``, equal to the keyword arguments
    of the same names).

    The schedule (:mod:`baselines._multistart`): every start runs ``stage_steps`` steps, the ``refine`` best per
    lane run to convergence (``rtol``, ``atol``; at most ``max_steps`` steps in all), and a kept start that ran out
    of steps next to its parameters' range limits is put on them and given ``limit_steps`` more, twice at most.

    Attributes:
        n_starts: starting points per lane (the model's deterministic guesses first, then random ones).
        backend: ``"optimistix"`` (one traced loop for every stage) or ``"jaxopt"`` (the staged kernel).
        max_steps: step limit per start, both stages together.
        rtol, atol: the solver's relative and absolute tolerances (for jaxopt: ``xtol`` and ``gtol``).
        stage_steps: the screening steps every start runs.
        refine: how many of the best starts per lane run to convergence; None: all of them.
        limit_steps: steps given to a start put on its range limits; 0 turns the rounds off.

    Raises:
        InputError: a field out of its range, naming the field.
    """

    n_starts: int = eqx.field(static=True)
    backend: str = eqx.field(static=True)
    max_steps: int = eqx.field(static=True)
    rtol: float = eqx.field(static=True)
    atol: float = eqx.field(static=True)
    stage_steps: int = eqx.field(static=True)
    refine: int | None = eqx.field(static=True)
    limit_steps: int = eqx.field(static=True)

    def __init__(self, n_starts: int = 16, backend: str = "optimistix", max_steps: int = 100, rtol: float = 1e-6,
                 atol: float = 1e-8, stage_steps: int = 6, refine: int | None = 1, limit_steps: int = 20):
        check_n_starts(n_starts)
        if backend not in BACKENDS:
            raise InputError(f"backend: expected one of {BACKENDS}, found {backend!r}")
        counts = [("max_steps", max_steps, 1), ("stage_steps", stage_steps, 1), ("limit_steps", limit_steps, 0)]
        for name, x, low in counts + ([("refine", refine, 1)] if refine is not None else []):
            if isinstance(x, bool) or not isinstance(x, (int, np.integer)) or x < low:
                raise InputError(f"{name}: expected a {'positive' if low else 'non-negative'} integer, found {x!r}")
        for name, x in (("rtol", rtol), ("atol", atol)):
            if isinstance(x, bool) or not isinstance(x, (int, float, np.floating)) or not (np.isfinite(x) and x >= 0):
                raise InputError(f"{name}: expected a non-negative tolerance, found {x!r}")
        self.n_starts, self.backend, self.max_steps = int(n_starts), backend, int(max_steps)
        self.rtol, self.atol, self.stage_steps = float(rtol), float(atol), int(stage_steps)
        self.refine, self.limit_steps = None if refine is None else int(refine), int(limit_steps)


def solver_of(fn: str, solver, defaults: dict, **given) -> MultiStart:
    """The solver of a call of ``fn``: ``solver`` if given (a :class:`MultiStart`), else made of the keyword
    arguments ``given``; keyword arguments that differ from their ``defaults`` and from ``solver`` are refused."""
    if solver is None:
        return MultiStart(**given)
    if not isinstance(solver, MultiStart):
        raise InputError(f"{fn}: solver: expected a baselines.MultiStart, found {type(solver).__name__}")
    clash = [k for k, x in given.items() if x != defaults[k] and x != getattr(solver, k)]
    if clash:
        both = ", ".join(f"{k}={given[k]!r} and solver.{k}={getattr(solver, k)!r}" for k in clash)
        raise InputError(f"{fn}: the solver's settings are given twice, found {both}: pass solver= or keywords")
    return solver
