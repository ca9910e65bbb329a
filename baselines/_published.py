"""Published parameters of the SGD and ABC models for the 100 MERL materials.

The tables live below the data root in ``published_fits/`` (``sgd_merl.csv``, ``abc_merl.csv``; their
``SOURCE.md`` gives the provenance and the formulas). Both were fitted by their authors to the raw
MERL measurements, each with its own error metric, not to equation (11).
"""

from __future__ import annotations

import csv
import functools
import os
from typing import Sequence

import numpy as np

from polyjax import DataFormatError, InputError, UnknownNameError
from polyjax.internal import data_file

_FILES = {"sgd": "published_fits/sgd_merl.csv", "abc": "published_fits/abc_merl.csv"}
_SGD_COLS = ("rhoD", "rhoS", "alpha", "p", "f0", "f1", "kap", "lambda", "c", "k", "theta0")
_RGB = ("r", "g", "b")


@functools.lru_cache(maxsize=4)
def _table(name: str, root: str | None) -> tuple[tuple[str, ...], np.ndarray]:
    """``(materials, params (100, 3, P))`` in the parameter order of :func:`baselines.sgd` / :func:`baselines.abc`."""
    path = data_file(_FILES[name], root)
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    if name == "sgd":
        need = ["material"] + [f"{c}_{ch}" for c in _SGD_COLS for ch in _RGB]
    else:
        need = ["material"] + [f"{c}_{ch}" for c in ("kD", "A") for ch in _RGB] + ["B", "C", "ior"]
    if not rows or any(c not in rows[0] for c in need):
        found = sorted(rows[0]) if rows else "no rows"
        raise DataFormatError(path, f"a CSV table with the columns {need}", f"columns {found}")
    out = []
    try:
        for r in rows:
            if name == "sgd":
                per = [[float(r[f"{c}_{ch}"]) for c in _SGD_COLS] for ch in _RGB]
                # kap scales D exactly like rho_s: fold it in (10 parameters, see baselines.sgd)
                per = [[p[0], p[1] * p[6], *p[2:6], *p[7:]] for p in per]
            else:
                shared = [float(r["B"]), float(r["C"]), float(r["ior"])]
                per = [[float(r[f"kD_{ch}"]), float(r[f"A_{ch}"]), *shared] for ch in _RGB]
            out.append(per)
    except ValueError as e:
        raise DataFormatError(path, "numbers in every parameter column", f"unparsable value ({e})") from None
    params = np.asarray(out, dtype=np.float64)
    if not np.all(np.isfinite(params)):
        raise DataFormatError(path, "finite parameters", "NaN or inf")
    return tuple(r["material"].strip() for r in rows), params


def published(
    name: str, material: str | Sequence[str] = "all", root: str | os.PathLike | None = None
) -> np.ndarray:
    """The published parameters of ``"sgd"`` or ``"abc"`` for MERL materials, per R, G, B channel.

    Evaluate them with the model itself: ``baselines.get_model(name).evaluate(params[c], u, v)``, or all
    channels at once through :class:`baselines.BaselineFit`-style batching (``jax.vmap`` over the leading axes).

    Args:
        name: ``"sgd"`` (10 parameters per channel, ``kap`` folded into ``rho_s``) or ``"abc"`` (5 per
            channel; ``B``, ``C``, ``ior`` repeated in the three channels as published).
        material: a MERL name (``"gold-metallic-paint"``), a sequence of names, or ``"all"`` (the table's order).
        root: data root (default ``$POLYJAX_DATA``).

    Returns:
        ``(3, P)`` float64 for one name, ``(m, 3, P)`` for a sequence or ``"all"``.
    """
    key = str(name).strip().lower()
    if key not in _FILES:
        raise UnknownNameError(f"published model {name!r}: expected one of {sorted(_FILES)}")
    names, params = _table(key, None if root is None else str(root))
    index = {n: i for i, n in enumerate(names)}
    if isinstance(material, str):
        if material.strip().lower() == "all":
            return params.copy()
        mat = material.strip().lower().replace("_", "-").replace(" ", "-")
        if mat not in index:
            raise InputError(f"material {material!r}: not in the published {key} table (one of the 100 MERL names)")
        return params[index[mat]].copy()
    mats = [str(m).strip().lower().replace("_", "-").replace(" ", "-") for m in material]
    missing = [m for m in mats if m not in index]
    if missing or not mats:
        raise InputError(f"material: expected MERL names of the published {key} table, found {missing or 'none'}")
    return params[[index[m] for m in mats]]


def published_materials(name: str, root: str | os.PathLike | None = None) -> tuple[str, ...]:
    """The material names of a published table, in its order."""
    key = str(name).strip().lower()
    if key not in _FILES:
        raise UnknownNameError(f"published model {name!r}: expected one of {sorted(_FILES)}")
    return _table(key, None if root is None else str(root))[0]
