"""The one check of the material dictionaries every standard-material exporter takes (``{"model": ..., <input>:
value}``, the form ``BaselineModel.to_material`` returns), made before anything is written, and the atomic write
they share."""

from __future__ import annotations

import math
from pathlib import Path

from .._config import check_output_file
from .._errors import InputError

#: a value's kind: "unit" (a float in [0, 1]), "nonnegative" (>= 0), "ior" (>= 1), "positive" (> 0), "real" (any
#: finite float), "rgb" (three floats in [0, 1]), "rgb+" (three floats >= 0)
Spec = dict[str, str]
_RANGES = {"unit": "[0, 1]", "nonnegative": ">= 0", "ior": ">= 1", "positive": "> 0", "real": ""}


def _holds(kind: str, x: float) -> bool:
    return math.isfinite(x) and {"unit": 0.0 <= x <= 1.0, "nonnegative": x >= 0.0, "ior": x >= 1.0,
                                 "positive": x > 0.0, "real": True}[kind]


def _checked_value(what: str, key: str, value, kind: str):
    """``value`` of the input ``key`` as a float (a list of three for a colour), checked against its ``kind``."""
    if kind.startswith("rgb"):
        each = "unit" if kind == "rgb" else "nonnegative"
        try:
            rgb = [float(x) for x in value]
        except (TypeError, ValueError):
            rgb = []
        if len(rgb) != 3 or not all(_holds(each, x) for x in rgb):
            raise InputError(f"{what}: material[{key!r}] = {value!r}: expected three values [r, g, b] "
                             f"{'in [0, 1]' if kind == 'rgb' else '>= 0'}")
        return rgb
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{what}: material[{key!r}] = {value!r}: expected a number") from None
    if not _holds(kind, x):
        raise InputError(f"{what}: material[{key!r}] = {value!r}: expected a finite value {_RANGES[kind]}".rstrip())
    return x


def check_material(what: str, material, models: dict[str, tuple[Spec, tuple[str, ...]]]) -> dict:
    """``material`` checked, the one check of every standard-material exporter: a dict whose ``"model"`` is a key of
    ``models`` (``{model name: (the kind of every accepted input, the required inputs)}``), holding every required
    input and no unknown one, each value of its kind.

    Returns:
        ``{"model": name, input: float or [r, g, b], ...}`` in the order of ``material``.

    Raises:
        InputError: naming ``what`` (the exporter), the input and what was expected.
    """
    if not isinstance(material, dict):
        raise InputError(f"{what}: expected a material dict (BaselineModel.to_material), "
                         f"found {type(material).__name__}")
    name = material.get("model")
    if name not in models:
        raise InputError(f"{what}: material['model'] = {name!r}: expected one of {sorted(models)}")
    spec, required = models[name]
    missing = [k for k in required if k not in material]
    if missing:
        raise InputError(f"{what}: the material has no {missing[0]!r} (a {name} material needs {list(required)})")
    unknown = sorted(k for k in material if k != "model" and k not in spec)
    if unknown:
        raise InputError(f"{what}: unknown material inputs {unknown} for {name}")
    return {"model": name, **{k: _checked_value(what, k, v, spec[k]) for k, v in material.items() if k != "model"}}


def range_kind(lo: float, hi: float | None) -> str:
    """The kind of a scalar input with the range ``[lo, hi]`` (``hi`` None: no upper limit)."""
    return {(0.0, 1.0): "unit", (0.0, None): "nonnegative", (1.0, None): "ior"}[(float(lo), hi if hi is None
                                                                                   else float(hi))]


def checked_inputs(what: str, material, models: tuple[str, ...], scalars: dict, colors: tuple[str, ...],
                   optional: tuple[str, ...] = ()) -> dict:
    """:func:`check_material` of a material whose models share one set of inputs: ``scalars`` (``{name: (low,
    high)}``) and ``colors`` (three values in ``[0, 1]``), all required but ``optional``. Returns ``{name: float or
    (r, g, b)}`` of the inputs present, scalars then colours (``"model"`` left out)."""
    spec = {**{k: range_kind(lo, hi) for k, (lo, hi) in scalars.items()}, **{k: "rgb" for k in colors}}
    required = tuple(k for k in spec if k not in optional)
    out = check_material(what, material, {m: (spec, required) for m in models})
    return {k: tuple(out[k]) if k in colors else out[k] for k in spec if k in out}


def material_of(material, what: str | None = None) -> dict:
    """The dictionary of ``material``: a dict, or a fit whose ``material()`` returns one (a fit of one material of
    a standard model, e.g. ``baselines.fit("gltf-pbr", ...)``): what every standard-material exporter takes.

    Raises:
        InputError: naming ``what`` (the exporter; else ``material``), for anything else.
    """
    if isinstance(material, dict):
        return material
    method = getattr(material, "material", None)
    if callable(method):
        out = method()
        if isinstance(out, dict):
            return out
    kind = "a standard material dict" if what is None else "a material dict (BaselineModel.to_material)"
    raise InputError(f"{what or 'material'}: expected {kind} (see baselines.standard_material) or a fit with a "
                     f"material() method (a baselines.BaselineFit of a standard model), found "
                     f"{type(material).__name__}")


def output_path(what: str, path, suffix: str) -> Path:
    """``path`` checked for writing (its folder exists, it ends with ``suffix``)."""
    p = check_output_file(path, f"{what}: path")
    if p.suffix.lower() != suffix:
        raise InputError(f"{what}: path {str(p)!r}: expected a {suffix} file name")
    return p


def format_float(x: float) -> str:
    """The shortest string that reads back as ``x`` (float64 round trip)."""
    return repr(float(x))
