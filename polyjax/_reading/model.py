"""The fields of a stored :class:`polyjax.PolynomialBRDF` (a saved model, a texture's shards) checked as they are
read: static fields of the right types and values, and arrays whose shapes agree, so that a damaged file is a
:class:`polyjax.DataFormatError` naming it at load, never a broadcasting error when the model is evaluated.

With batch shape ``B = degree.shape`` and ``k`` principal components: ``coefficients (*B, m)`` with
``m = n_terms(k, max_degree, interactions)``; ``mean, centre, halfwidth (*B, k)``; ``rotation (*B, k, k)``;
``degree, l2, rank, condition, n_used, status (*B)``; integer ``degree, rank, n_used, status``, float the rest;
``0 <= degree <= max_degree``; ``k`` that of the variable set when it is registered; ``log_top (*B)`` (optional),
float, not NaN, and only with the log link.
"""

from __future__ import annotations

import numpy as np

from .._basis import BASES, n_terms
from .._errors import DataFormatError, UnknownNameError
from .._model import LINKS
from .._variables import get_variables

_INTEGER = ("degree", "rank", "n_used", "status")
_FLOAT = ("coefficients", "mean", "rotation", "centre", "halfwidth", "l2", "condition")
#: the optional arrays: absent in a model without them (:attr:`polyjax.PolynomialBRDF.log_top`)
_OPTIONAL = ("log_top",)
#: the largest degree a stored model may declare (the fits allow far less; a larger one is a damaged file)
MAX_DEGREE = 64


def _static(path, static: dict) -> dict:
    """The static fields, checked: names and flags of the right types, ``max_degree`` in ``[0, MAX_DEGREE]``."""
    if not isinstance(static, dict):
        raise DataFormatError(path, "the static fields of a polynomial model as a JSON object", type(static).__name__)
    checks = [
        ("variables", lambda x: isinstance(x, str), "a variable set's name"),
        ("basis", lambda x: x in BASES, f"one of {sorted(BASES)}"),
        ("interactions", lambda x: isinstance(x, bool), "true or false"),
        ("max_degree", lambda x: isinstance(x, int) and not isinstance(x, bool) and 0 <= x <= MAX_DEGREE,
         f"an integer in [0, {MAX_DEGREE}]"),
        ("link", lambda x: x in LINKS, f"one of {list(LINKS)}"),
        ("eps", lambda x: isinstance(x, (int, float)) and not isinstance(x, bool) and np.isfinite(x),
         "a finite number"),
        ("clamp", lambda x: isinstance(x, bool), "true or false"),
    ]
    for name, ok, what in checks:
        if name in static and not ok(static[name]):
            raise DataFormatError(path, f"static field {name!r}: {what}", repr(static[name])[:80])
    return static


def check_polynomial_fields(path, static: dict, arrays: dict) -> None:
    """Raise a DataFormatError naming ``path`` unless ``static`` and ``arrays`` make a consistent polynomial model
    (module docstring). Missing fields are left to the model's own check (it names them)."""
    static = _static(path, static)
    for name in _INTEGER + _FLOAT + _OPTIONAL:
        if name in arrays:
            a = np.asarray(arrays[name])
            want = "i" if name in _INTEGER else "f"
            if a.dtype.kind not in ("iu" if want == "i" else "f"):
                raise DataFormatError(path, f"array {name!r} of {'integers' if want == 'i' else 'floats'}",
                                      f"dtype {a.dtype}")
    if any(n not in arrays for n in _INTEGER + _FLOAT) or "max_degree" not in static:
        return
    batch = tuple(np.shape(arrays["degree"]))
    k = int(np.shape(arrays["mean"])[-1]) if np.ndim(arrays["mean"]) == len(batch) + 1 else -1
    m = n_terms(max(k, 0), static["max_degree"], bool(static.get("interactions", False)))
    want = {"mean": batch + (k,), "centre": batch + (k,), "halfwidth": batch + (k,), "rotation": batch + (k, k),
            "coefficients": batch + (m,), **{n: batch for n in ("l2", "rank", "condition", "n_used", "status")}}
    for name, shape in want.items():
        if tuple(np.shape(arrays[name])) != shape or k < 1:
            raise DataFormatError(path, f"array {name!r} of shape {shape} (batch {batch} of degree's, k = {k} of "
                                  f"mean's, {m} coefficients)", f"shape {tuple(np.shape(arrays[name]))}")
    if "log_top" in arrays:
        top = np.asarray(arrays["log_top"])
        if static.get("link", "identity") != "log":
            raise DataFormatError(path, "no array 'log_top' (the log link's bound) with the identity link",
                                  "an array 'log_top'")
        if top.shape != batch or np.isnan(top).any():
            raise DataFormatError(path, f"array 'log_top' of shape {batch}, no NaN",
                                  f"shape {top.shape}{', NaN' if top.shape == batch else ''}")
    degree = np.asarray(arrays["degree"])
    if degree.size and (degree.min() < 0 or degree.max() > static["max_degree"]):
        raise DataFormatError(path, f"degrees in [0, max_degree = {static['max_degree']}]",
                              f"degrees from {degree.min()} to {degree.max()}")
    try:
        known = get_variables(static.get("variables", ""))
    except UnknownNameError:  # a user's variable set, registered before the model is evaluated
        return
    if known.k != k:
        raise DataFormatError(path, f"{known.k} components (variable set {static['variables']!r})",
                              f"k = {k} (the shape of 'mean')")
