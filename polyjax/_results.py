"""One result code for every fitter (polynomial, Zernike, nonlinear baselines).

:data:`RESULTS` is an :class:`equinox.Enumeration` with a message per code; :class:`Result` is the same codes as
an :class:`enum.IntEnum`, for the ``int32`` ``status`` arrays the fits return (``status == Result.OK``). A code
means the same thing in every fit. :func:`raise_on_status` is the ``throw=`` of every fitter.
"""

from __future__ import annotations

import enum

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._errors import FitError


class RESULTS(eqx.Enumeration):
    """Result of one fit (one lane of a batch); ``RESULTS[item]`` is its message."""

    ok = "the fit succeeded"
    rank_deficient = (
        "the weighted design has lower numerical rank than parameters (minimum-norm solution returned)"
    )
    no_samples = "no sample survived the cutoff and the masks (coefficients 0, L2 inf)"
    nonfinite = ("non-finite numbers: NaN/inf among the values fitted, or a non-finite (overflowing) L2 or solution; "
                 "also negative or non-finite weights under jit (eagerly an InputError)")
    max_steps = "the solver reached its step limit before its tolerances"
    failed = "the solver failed"


class Result(enum.IntEnum):
    """The codes of :data:`RESULTS` as integers (the ``status`` arrays of every fit)."""

    OK = 0
    #: the weighted design has lower numerical rank than parameters; the minimum-norm solution is returned
    RANK_DEFICIENT = 1
    #: no sample survived the cutoff and masks; coefficients are 0 and L2 is inf
    NO_SAMPLES = 2
    #: NaN/inf among the values of a lane (flagged where no Python error can be raised, e.g. under ``jit``),
    #: a non-finite L2 (values so large that the error overflows), or a solver that ended non-finite
    NONFINITE = 3
    NONFINITE_VALUES = 3
    #: the nonlinear solver reached its step limit before its tolerances
    MAX_STEPS = 4
    #: any other solver failure
    FAILED = 5


for _item in Result:  # the two spellings of the codes must agree
    assert int(getattr(RESULTS, _item.name.lower().replace("_values", ""))._value) == int(_item)


def message(code: int) -> str:
    """The message of a result code."""
    return RESULTS[getattr(RESULTS, Result(int(code)).name.lower().replace("_values", ""))]


_WHAT = {
    Result.OK: "succeeded", Result.RANK_DEFICIENT: "are rank-deficient",
    Result.NO_SAMPLES: "have no samples left to fit",
    Result.NONFINITE: "have non-finite values, L2 or solution", Result.MAX_STEPS: "reached the step limit",
    Result.FAILED: "failed",
}


def _is_concrete(x) -> bool:
    return not isinstance(x, jax.core.Tracer)


def raise_on_status(caller: str, status, tree, describe=None):
    """``throw=True`` of a fitter: raise if any lane's ``status`` is not ``OK``; returns ``tree``.

    Concrete ``status``: raises :class:`polyjax.FitError` naming how many lanes failed, the first one, its
    code's message and (``describe(first_index)``) what the fit saw there. Traced (under ``jit``): returns
    ``tree`` guarded by :func:`equinox.branched_error_if`, which raises at run time with the message of the first
    bad lane's code.
    """
    if _is_concrete(status):
        st = np.asarray(status)
        bad = np.argwhere(st != Result.OK)
        if len(bad) == 0:
            return tree
        first = tuple(int(i) for i in bad[0])
        code = Result(int(st[first] if st.ndim else st))
        where = f"first at batch index {first}" if first else "the fit"
        extra = f": {describe(first)}" if describe is not None else ""
        raise FitError(
            f"{caller}: {len(bad)} of {st.size} fits {_WHAT[code]} ({where}{extra}): {code.name}, {message(code)}; "
            "pass throw=False (and rank_deficient='flag') to get the result and read its status instead"
        )
    flat = jnp.ravel(status)
    bad = flat != Result.OK
    first_code = flat[jnp.argmax(bad)]
    msgs = tuple(f"{caller}: a fit ended with {c.name}: {message(c)}" for c in sorted(set(Result)))
    return eqx.branched_error_if(tree, jnp.any(bad), first_code, msgs)
