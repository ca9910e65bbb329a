"""One result code for every fitter (polynomial, Zernike, nonlinear baselines): :class:`RESULTS`.

The ``status`` arrays every fit returns hold these codes as ``int32`` (``status == RESULTS.OK``); a code means the
same thing in every fit, and ``RESULTS.<CODE>.message`` says what. :func:`raise_on_status` is the ``throw=`` of
every fitter. The names of earlier releases (``Result``, ``FitStatus``, ``BaselineStatus`` for the enumeration,
``NONFINITE_VALUES`` for ``NONFINITE``, the lower-case ``RESULTS.ok`` ...) still work, with a ``DeprecationWarning``.
"""

from __future__ import annotations

import enum
import warnings

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._arrays import is_concrete
from ._errors import FitError

_MESSAGES = (
    "the fit succeeded",
    "the weighted design has lower numerical rank than parameters (minimum-norm solution returned)",
    "no sample survived the cutoff and the masks (coefficients 0, L2 inf)",
    "non-finite numbers: NaN/inf among the values fitted, or a non-finite (overflowing) L2 or solution; also negative "
    "or non-finite weights under jit (eagerly an InputError)",
    "the solver reached its step limit before its tolerances",
    "the solver failed",
)


class RESULTS(enum.IntEnum):
    """The result of one fit (one lane of a batch), one name per code; ``RESULTS.<CODE>.message`` is its message."""

    OK = 0
    #: the weighted design has lower numerical rank than parameters; the minimum-norm solution is returned
    RANK_DEFICIENT = 1
    #: no sample survived the cutoff and masks; coefficients are 0 and L2 is inf
    NO_SAMPLES = 2
    #: NaN/inf among the values of a lane (flagged where no Python error can be raised, e.g. under ``jit``),
    #: a non-finite L2 (values so large that the error overflows), or a solver that ended non-finite
    NONFINITE = 3
    #: the nonlinear solver reached its step limit before its tolerances
    MAX_STEPS = 4
    #: any other solver failure
    FAILED = 5

    @property
    def message(self) -> str:
        """What the code means."""
        return _MESSAGES[int(self)]


class _DeprecatedName:
    """A former name of a member of :class:`RESULTS`: the member, with a ``DeprecationWarning``."""

    def __init__(self, old: str, new: str):
        self.old, self.new = old, new

    def __get__(self, obj, owner):
        warnings.warn(f"RESULTS.{self.old} is deprecated: use RESULTS.{self.new}", DeprecationWarning, stacklevel=2)
        return owner[self.new]


for _old, _new in [("NONFINITE_VALUES", "NONFINITE")] + [(m.name.lower(), m.name) for m in RESULTS]:
    setattr(RESULTS, _old, _DeprecatedName(_old, _new))

#: the former names of :class:`RESULTS` itself (``polyjax.Result``, ``polyjax.FitStatus``, ``baselines.BaselineStatus``)
DEPRECATED_ALIASES = ("Result", "FitStatus", "BaselineStatus")


def deprecated_alias(module: str, name: str):
    """:class:`RESULTS` under a former name ``name`` of ``module``, with a ``DeprecationWarning`` (a module's
    ``__getattr__`` calls it)."""
    warnings.warn(f"{module}.{name} is deprecated: use polyjax.RESULTS", DeprecationWarning, stacklevel=3)
    return RESULTS


def message(code: int) -> str:
    """The message of a result code."""
    return RESULTS(int(code)).message


_WHAT = {
    RESULTS.OK: "succeeded", RESULTS.RANK_DEFICIENT: "are rank-deficient",
    RESULTS.NO_SAMPLES: "have no samples left to fit",
    RESULTS.NONFINITE: "have non-finite values, L2 or solution", RESULTS.MAX_STEPS: "reached the step limit",
    RESULTS.FAILED: "failed",
}


def raise_on_status(caller: str, status, tree, describe=None):
    """``throw=True`` of a fitter: raise if any lane's ``status`` is not ``OK``; returns ``tree``.

    Concrete ``status``: raises :class:`polyjax.FitError` naming how many lanes failed, the first one, its
    code's message and (``describe(first_index)``) what the fit saw there. Traced (under ``jit``): returns
    ``tree`` guarded by :func:`equinox.branched_error_if`, which raises at run time with the message of the first
    bad lane's code.
    """
    if is_concrete(status):
        st = np.asarray(status)
        bad = np.argwhere(st != RESULTS.OK)
        if len(bad) == 0:
            return tree
        first = tuple(int(i) for i in bad[0])
        code = RESULTS(int(st[first] if st.ndim else st))
        where = f"first at batch index {first}" if first else "the fit"
        extra = f": {describe(first)}" if describe is not None else ""
        raise FitError(
            f"{caller}: {len(bad)} of {st.size} fits {_WHAT[code]} ({where}{extra}): {code.name}, {message(code)}; "
            "pass throw=False (and rank_deficient='flag') to get the result and read its status instead"
        )
    flat = jnp.ravel(status)
    bad = flat != RESULTS.OK
    first_code = flat[jnp.argmax(bad)]
    msgs = tuple(f"{caller}: a fit ended with {c.name}: {message(c)}" for c in sorted(set(RESULTS)))
    return eqx.branched_error_if(tree, jnp.any(bad), first_code, msgs)


def status_warnings(status, labels=None) -> list[str]:
    """One line per result code other than ``OK`` among the lanes of ``status`` (codes, any shape): how many lanes
    ended with it, which (``labels``, one name per lane in C order, else the lanes' batch indices; the first ten)
    and what the code means (``MAX_STEPS`` with the remedy); ``[]`` when every lane is ``OK``."""
    status = np.asarray(status)
    flat = status.ravel()
    if labels is None:
        labels = [",".join(map(str, i)) for i in np.ndindex(*status.shape)] if status.ndim else ["the fit"]
    known = {int(m) for m in RESULTS}
    out = []
    for code in sorted({int(c) for c in flat} - {int(RESULTS.OK)}):
        lanes = [labels[i] for i in np.flatnonzero(flat == code)]
        shown = "; ".join(lanes[:10]) + (f"; ... ({len(lanes) - 10} more)" if len(lanes) > 10 else "")
        name, what = (RESULTS(code).name, RESULTS(code).message) if code in known else (str(code), "unknown code")
        hint = " (raise max_steps or n_starts)" if code == int(RESULTS.MAX_STEPS) else ""
        out.append(f"{len(lanes)} fit(s) ended {name}: {shown}: {what}{hint}")
    return out
