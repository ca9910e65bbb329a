"""Checks of the material dictionaries the standard-material exporters take (``{"model": ..., <input>: value}``, the
form ``BaselineModel.to_material`` returns), and the atomic write they share."""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Callable

from .._config import check_output_file
from .._errors import InputError

#: ``(low, high)`` of an input; ``None`` for no upper limit.
Range = tuple[float, "float | None"]


def check_material(what: str, material, models: tuple[str, ...], scalars: dict[str, Range],
                   colors: tuple[str, ...], optional: tuple[str, ...] = ()) -> dict:
    """``material`` checked: a dict whose ``"model"`` is one of ``models``, holding every input of ``scalars`` and
    ``colors`` not in ``optional``, scalars finite and in their range, colours three finite values in ``[0, 1]``.

    Returns:
        ``{name: float or (r, g, b)}`` of the inputs present (``"model"`` left out).

    Raises:
        InputError: naming ``what`` (the exporter), the key and what was expected.
    """
    if not isinstance(material, dict):
        raise InputError(f"{what}: expected a material dict (BaselineModel.to_material), "
                         f"found {type(material).__name__}")
    model = material.get("model")
    if model not in models:
        raise InputError(f"{what}: material['model'] = {model!r}: expected one of {list(models)}")
    needed = [k for k in (*scalars, *colors) if k not in optional]
    missing = [k for k in needed if k not in material]
    if missing:
        raise InputError(f"{what}: the material has no {missing[0]!r} (a {model} material needs {needed})")
    out = {k: _scalar(what, k, material[k], lo, hi) for k, (lo, hi) in scalars.items() if k in material}
    out.update({k: _color(what, k, material[k]) for k in colors if k in material})
    unknown = sorted(set(material) - set(scalars) - set(colors) - {"model"})
    if unknown:
        raise InputError(f"{what}: unknown material inputs {unknown} for {model}")
    return out


def _scalar(what, key, value, lo, hi) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"{what}: material[{key!r}] = {value!r}: expected a number") from None
    if not math.isfinite(x) or x < lo or (hi is not None and x > hi):
        rng = f"[{lo}, {hi}]" if hi is not None else f">= {lo}"
        raise InputError(f"{what}: material[{key!r}] = {value!r}: expected a finite value {rng}")
    return x


def _color(what, key, value) -> tuple[float, float, float]:
    try:
        rgb = tuple(float(x) for x in value)
    except (TypeError, ValueError):
        rgb = ()
    if len(rgb) != 3 or not all(math.isfinite(x) and 0.0 <= x <= 1.0 for x in rgb):
        raise InputError(f"{what}: material[{key!r}] = {value!r}: expected three values [r, g, b] in [0, 1]")
    return rgb


def output_path(what: str, path, suffix: str) -> Path:
    """``path`` checked for writing (its folder exists, it ends with ``suffix``)."""
    p = check_output_file(path, f"{what}: path")
    if p.suffix.lower() != suffix:
        raise InputError(f"{what}: path {str(p)!r}: expected a {suffix} file name")
    return p


def write_atomically(path: Path, write: Callable[[Path], None]) -> Path:
    """``write(tmp)`` to a temporary file beside ``path`` (same suffix), then moved onto ``path``: a failed write
    leaves no half-written file."""
    tmp = path.with_name(f".{path.stem}.{os.getpid()}.tmp{path.suffix}")
    try:
        write(tmp)
        os.replace(tmp, path)
    finally:
        if tmp.exists():
            tmp.unlink()
    return path


def format_float(x: float) -> str:
    """The shortest string that reads back as ``x`` (float64 round trip)."""
    return repr(float(x))
