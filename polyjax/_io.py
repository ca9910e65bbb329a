"""Saving and loading fitted models (``.npz`` or ``.json``), bit-exact.

File format (version 2): a JSON header ``{"format": "polyjax.model", "version": 2, "kind": <kind>,
"static": {...}}`` and named arrays. In ``.npz`` the header is the string array ``__meta__`` and every
array is stored under its name; in ``.json`` the header's keys are at the top level and
``"arrays": {name: {"dtype", "shape", "data"}}`` holds the arrays (floats in exact ``repr``; inf and NaN as the
strings ``"Infinity"``, ``"-Infinity"``, ``"NaN"``, so the file is strict JSON; older files with bare ``Infinity``
still load). ``kind`` names a :class:`polyjax.ModelKind` (``"polyjax.PolynomialBRDF"``, or one that
another package provides, e.g. ``"baselines.BaselineFit"``), ``static`` its non-array fields.
Version 1 files (``"format": "polyjax.PolynomialBRDF"``, static fields at the top level) still load.
"""

from __future__ import annotations

import json
import os
import zipfile
from pathlib import Path

import numpy as np

from ._errors import DataFormatError, DataNotFoundError, InputError, UnknownNameError
from ._kinds import kind_named, kind_of, module_kind, register_model_kind
from ._model import FitStatus, PolynomialBRDF

FORMAT = "polyjax.model"
VERSION = 2
#: version 1: polynomial models only
FORMAT_V1 = "polyjax.PolynomialBRDF"
_STATIC_V1 = ("variables", "basis", "interactions", "max_degree")

POLYNOMIAL_KIND = register_model_kind(module_kind(
    PolynomialBRDF, "polyjax.PolynomialBRDF", status_names=tuple(s.name for s in FitStatus),
))


def save_model(path: str | os.PathLike, model, *, metadata: dict | None = None) -> Path:
    """Write a fitted model to ``path``: ``.json`` (text, exact float repr) or anything else as ``.npz``.

    Args:
        path: the file, ending in ``.json`` or ``.npz`` (the format is chosen by the suffix; any other suffix is
            refused, never renamed). The file is written whole or not at all (a temporary file renamed).
        model: a :class:`polyjax.PolynomialBRDF` or any model whose class has a :class:`polyjax.ModelKind`
            (e.g. a ``baselines.BaselineFit``).
        metadata: optional facts about the fit kept in the header's ``"metadata"`` (JSON values, e.g.
            ``{"fit_seconds": 1.2}`` written by ``polyjax fit --save``); :func:`model_metadata` reads them back.
            Readers that do not know the key ignore it.

    Returns:
        The path written. A polynomial model's variable set is stored by name: a user-registered set must be
        registered again before loading.

    Raises:
        InputError: a suffix other than ``.npz`` / ``.json``, metadata that is not a dict of JSON values.
    """
    path = Path(path)
    if path.suffix not in (".npz", ".json"):
        raise InputError(f"path {str(path)!r}: expected a model file name ending in .npz or .json, found suffix "
                         f"{path.suffix or '(none)'!r}")
    kind = kind_of(model)
    static, arrays = kind.to_arrays(model)
    meta = {"format": FORMAT, "version": VERSION, "kind": kind.kind, "static": static}
    if metadata is not None:
        meta["metadata"] = _checked_metadata(metadata)
    if path.suffix == ".json":
        doc = dict(meta)
        doc["arrays"] = {
            k: {"dtype": str(a.dtype), "shape": list(a.shape),
                "data": [_json_float(x) if a.dtype.kind == "f" else int(x) for x in a.ravel()]}
            for k, a in arrays.items()
        }
        _write_whole(path, lambda f: f.write(json.dumps(doc, allow_nan=False).encode()))
    else:
        _write_whole(path, lambda f: np.savez(f, __meta__=np.asarray(json.dumps(meta)), **arrays))
    return path


def _checked_metadata(metadata) -> dict:
    """``metadata`` as strict JSON (a dict with string keys, finite numbers), else an InputError."""
    if not isinstance(metadata, dict) or not all(isinstance(k, str) for k in metadata):
        raise InputError(f"metadata: expected a dict with string keys, found {type(metadata).__name__}")
    try:
        return json.loads(json.dumps(metadata, allow_nan=False))
    except (TypeError, ValueError) as e:
        raise InputError(f"metadata: expected JSON values (finite numbers, strings, lists, dicts): {e}") from None


def model_metadata(path: str | os.PathLike) -> dict:
    """The ``metadata`` dict a model file was saved with (:func:`save_model`); ``{}`` when it has none (older
    files, models saved without it). Reads the header only.

    Raises:
        DataNotFoundError: no such file. DataFormatError: not a saved model.
    """
    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"{str(path)!r}: no such model file")
    try:
        if path.suffix == ".json":
            meta = json.loads(path.read_text())
        else:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["__meta__"]))
    except (ValueError, KeyError, TypeError, OSError, EOFError, zipfile.BadZipFile) as e:
        raise DataFormatError(path, f"a {FORMAT} file written by save_model", f"unreadable content ({e})") from None
    if not isinstance(meta, dict) or meta.get("format") not in (FORMAT, FORMAT_V1):
        raise DataFormatError(path, f"format {FORMAT!r} (or {FORMAT_V1!r})", repr(meta.get("format") if
                                                                                  isinstance(meta, dict) else meta))
    found = meta.get("metadata", {})
    return dict(found) if isinstance(found, dict) else {}


def _json_float(x):
    """A float for strict JSON: finite ones as numbers (exact ``repr``), ``inf``/``-inf``/``nan`` as the strings
    ``"Infinity"``/``"-Infinity"``/``"NaN"`` (numpy reads both back bit-exactly)."""
    x = float(x)
    if x == x and abs(x) != float("inf"):
        return x
    return "NaN" if x != x else ("Infinity" if x > 0 else "-Infinity")


def _write_whole(path: Path, write) -> None:
    """``write(file)`` into a temporary file beside ``path``, then renamed onto it: never a half-written model."""
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            write(f)
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)


def load_model(path: str | os.PathLike):
    """Read a model written by :func:`save_model` (any version); it evaluates identically.

    Raises:
        DataNotFoundError: no such file. DataFormatError: not a saved model, a newer version, or missing
        arrays. UnknownNameError: its kind is provided by a package that is not installed.
    """
    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"{str(path)!r}: no such model file")
    try:
        if path.suffix == ".json":
            meta = json.loads(path.read_text())
            arrays = {}
            if isinstance(meta, dict) and isinstance(meta.get("arrays"), dict):
                arrays = {
                    k: np.asarray(v["data"], dtype=v["dtype"]).reshape(v["shape"]) for k, v in meta["arrays"].items()
                }
        else:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["__meta__"]))
                arrays = {k: z[k] for k in z.files if k != "__meta__"}
    except (ValueError, KeyError, TypeError, OSError, EOFError, zipfile.BadZipFile) as e:
        raise DataFormatError(path, f"a {FORMAT} file written by save_model", f"unreadable content ({e})") from None
    fmt = meta.get("format") if isinstance(meta, dict) else meta
    if fmt == FORMAT_V1:
        kind_name, static = POLYNOMIAL_KIND.kind, {k: meta.get(k) for k in _STATIC_V1}
    elif fmt == FORMAT:
        version = meta.get("version")
        if not isinstance(version, int) or version > VERSION:
            raise DataFormatError(path, f"a saved model of version <= {VERSION}", f"version {version!r} "
                                  "(written by a newer polyjax)")
        kind_name, static = meta.get("kind"), meta.get("static", {})
    else:
        raise DataFormatError(path, f"format {FORMAT!r} (or {FORMAT_V1!r})", repr(fmt))
    try:
        kind = kind_named(kind_name)
    except UnknownNameError as e:
        raise UnknownNameError(f"{str(path)!r}: {e}") from None
    try:
        return kind.from_arrays(static, arrays)
    except (KeyError, TypeError, ValueError) as e:
        raise DataFormatError(path, f"the fields of a {kind_name} model", f"{e}") from None
