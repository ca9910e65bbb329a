"""Checks of a standard material dictionary (``{"model": ..., <parameter>: float or [r, g, b]}``) before an exporter
writes anything: every key known, every value finite and in its range."""

from __future__ import annotations

import math

from .._errors import InputError

#: a parameter's kind: "unit" (a float in [0, 1]), "rgb" (three floats in [0, 1]), "rgb+" (three floats >= 0),
#: "ior" (a float >= 1), "real" (any finite float), "positive" (a float > 0)
Spec = dict[str, str]


def material_of(material) -> dict:
    """The dictionary of ``material``: a dict, or an object whose ``material()`` returns one (a fit of one
    material of a standard model, e.g. ``baselines.fit("gltf-pbr", ...)``)."""
    if isinstance(material, dict):
        return material
    method = getattr(material, "material", None)
    if callable(method):
        out = method()
        if isinstance(out, dict):
            return out
    raise InputError(f"material: expected a standard material dict (see baselines.standard_material) or a fit with "
                     f"a material() method, found {type(material).__name__}")


def _value(key: str, value, kind: str):
    if kind.startswith("rgb"):
        if not isinstance(value, (list, tuple)) or len(value) != 3:
            raise InputError(f"material[{key!r}]: expected a colour [r, g, b], found {value!r}")
        return [_value(f"{key}[{i}]", x, "unit" if kind == "rgb" else "nonnegative") for i, x in enumerate(value)]
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise InputError(f"material[{key!r}]: expected a number, found {value!r}") from None
    ok = {"unit": 0.0 <= x <= 1.0, "nonnegative": x >= 0.0, "ior": x >= 1.0, "positive": x > 0.0,
          "real": True}[kind]
    ranges = {"unit": "in [0, 1]", "nonnegative": ">= 0", "ior": ">= 1", "positive": "> 0", "real": "finite"}
    if not (math.isfinite(x) and ok):
        raise InputError(f"material[{key!r}]: expected a value {ranges[kind]}, found {value!r}")
    return x


def check_material(material: dict, models: dict[str, tuple[Spec, tuple[str, ...]]]) -> dict:
    """``material`` with its values as floats and lists, checked against ``models``: ``{model name: (spec of
    every accepted key, the required keys)}``.

    Raises:
        InputError: naming the model, a missing or unknown key, or a value of the wrong kind or out of range.
    """
    name = material.get("model")
    if name not in models:
        raise InputError(f"material['model']: expected one of {sorted(models)}, found {name!r}")
    spec, required = models[name]
    missing = [k for k in required if k not in material]
    if missing:
        raise InputError(f"material: the {name!r} material needs {missing}, found keys {sorted(material)}")
    unknown = sorted(k for k in material if k != "model" and k not in spec)
    if unknown:
        raise InputError(f"material: unknown keys {unknown} for a {name!r} material (expected {sorted(spec)})")
    return {"model": name, **{k: _value(k, v, spec[k]) for k, v in material.items() if k != "model"}}
