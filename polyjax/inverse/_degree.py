r"""The degree of a fit from photographs when it is not given (``degree="auto"``): the highest degree up to
:data:`TOP_DEGREE` whose fit is well conditioned.

With few lights the pixels' BRDF samples lie on a few sheets of the variables' space (under one view, a light's
polar angle fixes ``theta_d`` at every pixel of a sphere), and a high degree swings between them, rank-deficient or
not. So the fit starts at :data:`TOP_DEGREE` and steps down one degree at a time while a channel's fit is not
``RESULTS.OK`` (rank-deficient) or the condition number of its weighted design (``PolynomialBRDF.condition``, the
2-norm condition number of the weighted, column-equilibrated design, :func:`polyjax.weighted_lstsq`) exceeds
:data:`MAX_CONDITION`, down to degree 1.

Measured on DiLiGenT (``benchmarks/bench_log_bound.py``, ``benchmarks/RESULTS.md``, "few lights"): with 6-8
lights the fixed ``p = 8`` relit the held-out lights at relative RMS 1.1-19 (bounded by ``PolynomialBRDF.log_top``;
3e27 before the bound) where the degree kept here gives 0.095-0.45; the bound of 50 was chosen on the ball, cat and
pot1 and checked on bear, goblet and pot2 (the degree kept within 1.35x of the best degree's held-out error on all
21 cases); from 12 lights up on the ball it keeps 8 itself. Only for fits on the pixels' BRDF samples
(``weighting="brdf"``, one light sample per pixel), where it was measured: a radiance design summed over an
environment map's samples is worse conditioned at every degree (a sphere under a sky: 4.7e4 at ``p = 8``, 4.0e2 at
``p = 4``), and there ``"auto"`` keeps :data:`TOP_DEGREE`.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .._arrays import is_concrete
from .._errors import InputError
from .._model import RESULTS, PolynomialBRDF

#: the degree ``"auto"`` starts from: the measured best on the ball with its lights (``docs/photometric.md``)
TOP_DEGREE = 8
#: the largest condition number of a kept fit's weighted design, in every channel (module docstring)
MAX_CONDITION = 50.0


def why_not_kept(model: PolynomialBRDF) -> str | None:
    """Why a fit is not kept by the step-down (``"status RANK_DEFICIENT, OK, OK"``, ``"condition number 812 >
    50"``), or None when it is. Needs concrete arrays: raises :class:`InputError` under a trace."""
    if not is_concrete(model.status, model.condition):
        raise InputError("degree='auto' chooses the degree from the fit's rank and condition number, which need "
                         "concrete values: under jax.jit, jax.grad or jax.vmap pass an integer degree (e.g. the one "
                         "a call outside the transformation chose, model.max_degree)")
    names = [RESULTS(int(s)).name for s in np.asarray(model.status).reshape(-1)]
    if any(n != "OK" for n in names):
        return f"status {', '.join(names)}"
    cond = float(np.max(np.asarray(model.condition)))
    return None if cond <= MAX_CONDITION else f"condition number {cond:.3g} > {MAX_CONDITION:g}"


def step_down(fit_at: Callable[[int], PolynomialBRDF], top: int = TOP_DEGREE
              ) -> tuple[PolynomialBRDF, list[tuple[int, str]]]:
    """The fit ``fit_at(p)`` at the highest ``p <= top`` that :func:`why_not_kept` keeps (degree 1 if none above
    it is), and ``[(degree, why), ...]`` of the degrees left out, highest first."""
    left_out = []
    for p in range(int(top), 0, -1):
        model = fit_at(p)
        why = why_not_kept(model)
        if why is None or p == 1:
            return model, left_out
        left_out.append((p, why))
    return fit_at(0), left_out  # top == 0: nothing to step down from
