"""Saved models: the kinds of fitted model polyjax knows, and saving and loading them (``.npz`` or ``.json``).

**Kinds.** Kinds of fitted model that :func:`polyjax.save_model`, :func:`polyjax.load_model` and ``polyjax fit --model``
know, found without polyjax importing the packages that define them.

A kind is a :class:`ModelKind` record: the name stored in saved files, the model's class, functions to and
from plain arrays, and optionally the model families it can fit (``polyjax fit --model <name>``). polyjax
registers its own :class:`polyjax.PolynomialBRDF`; another package provides kinds through the entry point
group ``polyjax.models`` of its metadata (``pyproject.toml``)::

    [project.entry-points."polyjax.models"]
    "mypackage.MyFit" = "mypackage._saving:KIND"

or calls :func:`register_model_kind` on import. Entry points are loaded only when a kind is asked for that is
not registered yet.

**Files.** Saving and loading fitted models (``.npz`` or ``.json``), bit-exact.

File format (version 2, or 3 for a file holding a log-link polynomial's bound ``log_top``, which older readers
would ignore: they refuse version 3): a JSON header ``{"format": "polyjax.model", "version": 2, "kind": <kind>,
"static": {...}}`` and named arrays. In ``.npz`` the header is the string array ``__meta__`` and every
array is stored under its name; in ``.json`` the header's keys are at the top level and
``"arrays": {name: {"dtype", "shape", "data"}}`` holds the arrays (floats in exact ``repr``; inf and NaN as the
strings ``"Infinity"``, ``"-Infinity"``, ``"NaN"``, so the file is strict JSON; older files with bare ``Infinity``
still load). ``kind`` names a :class:`polyjax.ModelKind` (``"polyjax.PolynomialBRDF"``, or one that
another package provides, e.g. ``"baselines.BaselineFit"``), ``static`` its non-array fields.
Version 1 files (``"format": "polyjax.PolynomialBRDF"``, static fields at the top level) still load.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import json
import os
import warnings
from collections.abc import Callable
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

from ._arrays import device_array
from ._errors import DataFormatError, DataNotFoundError, InputError, PolyjaxError, UnknownNameError
from ._files import check_output_path, write_atomically
from ._model import RESULTS, PolynomialBRDF
from ._reading.bounded import NUMERIC_KINDS, load_json, read_npz
from ._reading.model import check_polynomial_fields

ENTRY_POINT_GROUP = "polyjax.models"


@dataclasses.dataclass(frozen=True)
class ModelKind:
    """How to store (and optionally fit) one class of fitted model.

    Attributes:
        kind: the name written into saved files (``"<package>.<class>"`` by convention); never change it.
        type: the class of the fitted models.
        to_arrays: ``model -> (static, arrays)``: a JSON-serialisable dict and a dict of numpy arrays.
        from_arrays: ``(static, arrays) -> model``, the inverse (bit-exact).
        models: names of the model families ``fit`` accepts (``polyjax fit --model <name>``).
        fit: ``(name, measurements, **options) -> model``; options the command line passes:
            ``cutoff_deg``.
        status_names: names of the integer codes in the model's ``status`` field, for reports.
    """

    kind: str
    type: type
    to_arrays: Callable[[Any], tuple[dict, dict]]
    from_arrays: Callable[[dict, dict], Any]
    models: tuple[str, ...] = ()
    fit: Callable[..., Any] | None = None
    status_names: tuple[str, ...] = ()


def module_kind(cls, kind: str, *, models: tuple[str, ...] = (), fit=None, status_names=()) -> ModelKind:
    """A :class:`ModelKind` for an ``equinox.Module`` class: its array fields are stored as arrays, its
    static fields (which must be JSON values: str, int, float, bool) in ``static``, all by field name."""
    fields = dataclasses.fields(cls)
    static = tuple(f.name for f in fields if f.metadata.get("static", False))
    arrays = tuple(f.name for f in fields if not f.metadata.get("static", False))

    def to_arrays(model):  # an array field of None (an optional one, e.g. PolynomialBRDF.log_top) is not stored
        return ({k: getattr(model, k) for k in static},
                {k: np.asarray(getattr(model, k)) for k in arrays if getattr(model, k) is not None})

    # fields with a default (added after files were written, e.g. PolynomialBRDF.link and .log_top) may be absent
    defaults = {f.name: f.default for f in fields if f.default is not dataclasses.MISSING}

    def from_arrays(meta, arrs):
        missing = ([k for k in arrays if k not in arrs and k not in defaults]
                   + [k for k in static if k not in meta and k not in defaults])
        if missing:
            raise KeyError(f"missing fields {missing}")
        return cls(**{k: device_array(arrs[k]) if k in arrs else defaults[k] for k in arrays},
                   **{k: meta.get(k, defaults.get(k)) for k in static})

    return ModelKind(kind=kind, type=cls, to_arrays=to_arrays, from_arrays=from_arrays, models=tuple(models), fit=fit,
                     status_names=tuple(status_names))


_REGISTRY: dict[str, ModelKind] = {}
_LOADED_ENTRY_POINTS: set[str] = set()
#: why an entry point (by name, e.g. "baselines.BaselineFit") failed to load, for the errors that need its kind
_LOAD_FAILURES: dict[str, str] = {}


def register_model_kind(kind: ModelKind) -> ModelKind:
    """Register ``kind`` (replacing a kind of the same name); returns it."""
    if not isinstance(kind, ModelKind):
        raise TypeError(f"kind: expected a polyjax.ModelKind, found {type(kind).__name__}")
    _REGISTRY[kind.kind] = kind
    return kind


def _load_entry_points(until=None) -> None:
    """Load every entry point of the group not loaded yet (each registers the kind it names), in the group's order;
    with ``until`` (a test of the registry), stop as soon as it holds: the others stay unloaded until needed (each
    imports its provider: ``polyjax.CaptureFit``'s imports ``polyjax.inverse`` and the renderer, which a baseline's
    fit never uses)."""
    for ep in metadata.entry_points(group=ENTRY_POINT_GROUP):
        if until is not None and until():
            return
        key = f"{ep.name}={ep.value}"
        if key in _LOADED_ENTRY_POINTS:
            continue
        _LOADED_ENTRY_POINTS.add(key)
        # checked before loading: an editable install's import hook would find the provider's module below a
        # foreign package of the same name, and load it as if it belonged there
        shadow = _shadowing_package(ep.value)
        try:
            if shadow:
                raise ImportError(shadow)
            obj = ep.load()
        except Exception as e:  # noqa: BLE001  (a broken provider must not break the others)
            _LOAD_FAILURES[ep.name] = shadow or f"its entry point {ep.value!r} failed to load: {e}"
            warnings.warn(f"entry point {ep.name!r} = {ep.value!r} of group {ENTRY_POINT_GROUP!r} failed to load: "
                          f"{shadow or e}", stacklevel=3)
            continue
        if isinstance(obj, ModelKind):
            _REGISTRY.setdefault(obj.kind, obj)


def _shadowing_package(value: str) -> str | None:
    """When the top-level package of entry point ``value`` (e.g. ``baselines`` of ``baselines._saving:KIND``) is
    importable but is not the one that declares it (another package of that name, e.g. an unrelated ``baselines``
    from the package index, found first on ``sys.path``): a message saying so, naming where it was found."""
    module = value.split(":")[0]
    top = module.split(".")[0]
    if module == top:  # the entry point names a top-level module itself: nothing can stand in front of a part of it
        return None
    try:
        spec = importlib.util.find_spec(top)
        own = importlib.util.find_spec(module) if spec is not None else None
    except (ImportError, ValueError):
        return None
    inside = own is not None and any(str(own.origin or "").startswith(str(loc))
                                     for loc in (spec.submodule_search_locations or []))
    if spec is None or inside:
        return None
    where = spec.origin or ", ".join(spec.submodule_search_locations or [])
    return (f"the package {top!r} found at {where} is not polyjax's {top!r} (it has no {module!r}): another package "
            f"of that name shadows it; uninstall it (pip uninstall {top}) or put polyjax's first on sys.path")


def model_kinds() -> dict[str, ModelKind]:
    """Every known kind (registered, and those of installed entry points), by name."""
    _load_entry_points()
    return dict(_REGISTRY)


def kind_named(name: str) -> ModelKind:
    """The kind stored in a file under ``name``; UnknownNameError when no installed package provides it."""
    if name not in _REGISTRY:
        _load_entry_points()
    if name not in _REGISTRY and name in _LOAD_FAILURES:
        raise UnknownNameError(f"model kind {name!r}: {_LOAD_FAILURES[name]}")
    if name not in _REGISTRY:
        raise UnknownNameError(
            f"model kind {name!r}: not provided by any installed package (known: {sorted(_REGISTRY)}); install the "
            f"package that defines it (it declares the entry point group {ENTRY_POINT_GROUP!r})"
        )
    return _REGISTRY[name]


def kind_of(model) -> ModelKind:
    """The kind of a fitted model object (by its class, most specific first)."""
    for attempt in range(2):
        for cls in type(model).__mro__:
            for k in _REGISTRY.values():
                if k.type is cls:
                    return k
        if attempt == 0:
            _load_entry_points()
    raise UnknownNameError(
        f"model: no saved-model kind for {type(model).__module__}.{type(model).__name__} (known: "
        f"{sorted(k.type.__name__ for k in _REGISTRY.values())}); register one with polyjax.register_model_kind"
    )


def fitter_for(name: str) -> tuple[ModelKind, str]:
    """The kind whose ``models`` include ``name`` (case, ``_`` and space insensitive), and the name as it spells it."""
    key = str(name).strip().lower().replace("_", "-").replace(" ", "-")

    def found():
        for k in list(_REGISTRY.values()):
            for m in k.models:
                if m.lower() == key and k.fit is not None:
                    return k, m
        return None

    # the kinds registered so far first, then the entry points one at a time until one provides the name (the first
    # in registration order, as when every one is loaded first)
    _load_entry_points(until=found)
    hit = found()
    if hit is not None:
        return hit
    kinds = model_kinds()
    known = sorted(m for k in kinds.values() if k.fit is not None for m in k.models)
    failed = "".join(f"; {kind} unavailable: {why}" for kind, why in _LOAD_FAILURES.items())
    raise UnknownNameError(f"--model {name!r}: expected 'polynomial' or one of {known}{failed}")


FORMAT = "polyjax.model"
#: the newest version this polyjax reads and writes
VERSION = 3
#: arrays that a reader of an older version would not evaluate the same (it ignores arrays it does not know), and
#: the least version that knows them: a file holding one is written with that version, which older readers refuse
#: ("written by a newer polyjax") instead of evaluating differently; every other file is version 2
_VERSION_OF_ARRAY = {"log_top": 3}
#: version 1: polynomial models only
FORMAT_V1 = "polyjax.PolynomialBRDF"
_STATIC_V1 = ("variables", "basis", "interactions", "max_degree")

POLYNOMIAL_KIND = register_model_kind(module_kind(
    PolynomialBRDF, "polyjax.PolynomialBRDF", status_names=tuple(s.name for s in RESULTS),
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
        InputError: a suffix other than ``.npz`` / ``.json``, a path that is a folder or in a missing or read-only
            folder, metadata that is not a dict of JSON values.
    """
    path = check_output_path(path, "save_model: path")
    if path.suffix not in (".npz", ".json"):
        raise InputError(f"path {str(path)!r}: expected a model file name ending in .npz or .json, found suffix "
                         f"{path.suffix or '(none)'!r}")
    kind = kind_of(model)
    static, arrays = kind.to_arrays(model)
    version = max([2] + [_VERSION_OF_ARRAY.get(k, 2) for k in arrays])
    meta = {"format": FORMAT, "version": version, "kind": kind.kind, "static": static}
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
    meta, _ = _read_file(path, arrays=False)
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
    """``write(file)`` into the open temporary file of :func:`polyjax._files.write_atomically`: never a
    half-written model."""

    def to_file(tmp: Path) -> None:
        with open(tmp, "wb") as f:
            write(f)

    write_atomically(path, to_file)


def _read_file(path: Path, arrays: bool) -> tuple:
    """``(header, arrays)`` of a model file written by :func:`save_model` (``arrays`` empty unless asked for; an
    ``.npz``'s header alone is read without its arrays). Sizes are checked before anything is read: the file against
    the input cap, each ``.npz`` member's ``.npy`` header against the member's size (``polyjax._reading.bounded``).

    Raises:
        DataNotFoundError: no such file. DataFormatError: unreadable content.
    """
    if not path.is_file():
        raise DataNotFoundError(f"{str(path)!r}: no such model file")
    what = f"a {FORMAT} file written by save_model"
    if path.suffix == ".json":
        meta = load_json(path, what)
        out = _json_arrays(path, meta) if arrays else {}
        return meta, out
    stored = read_npz(path, what, kinds=NUMERIC_KINDS + "U")
    try:
        meta = json.loads(str(stored.pop("__meta__")[()].item()) if "__meta__" in stored else "")
    except (ValueError, TypeError, IndexError, RecursionError) as e:
        raise DataFormatError(path, what, f"unreadable header __meta__ ({type(e).__name__}: {e})") from None
    return meta, (stored if arrays else {})


def _json_arrays(path: Path, meta) -> dict:
    """The arrays of a ``.json`` model (``{"dtype", "shape", "data"}`` each), numeric dtypes only, as numpy."""
    found = meta.get("arrays") if isinstance(meta, dict) else None
    if not isinstance(found, dict):
        return {}
    out = {}
    for k, v in found.items():
        try:
            dtype = np.dtype(v["dtype"])
            if dtype.kind not in NUMERIC_KINDS:
                raise TypeError(f"dtype {dtype}: expected a numeric dtype")
            out[k] = np.asarray(v["data"], dtype=dtype).reshape(v["shape"])
        except (ValueError, KeyError, TypeError, OverflowError, IndexError) as e:
            raise DataFormatError(path, f"array {k!r} as {{'dtype', 'shape', 'data'}} of numbers",
                                  f"{type(e).__name__}: {e}") from None
    return out


def load_model(path: str | os.PathLike):
    """Read a model written by :func:`save_model` (any version); it evaluates identically.

    Raises:
        DataNotFoundError: no such file. DataFormatError: not a saved model, a newer version, missing arrays,
        arrays whose shapes disagree, sizes over the input cap (``POLYJAX_MAX_INPUT_MB``). UnknownNameError: its
        kind is provided by a package that is not installed.
    """
    path = Path(path)
    meta, arrays = _read_file(path, arrays=True)
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
        raise DataFormatError(path, f"format {FORMAT!r} (or {FORMAT_V1!r})", repr(fmt)[:80])
    if not isinstance(kind_name, str) or not isinstance(static, dict):
        raise DataFormatError(path, "a kind's name and its static fields as a JSON object",
                              f"{type(kind_name).__name__} and {type(static).__name__}")
    try:
        kind = kind_named(kind_name)
    except UnknownNameError as e:
        raise UnknownNameError(f"{str(path)!r}: {e}") from None
    if kind is POLYNOMIAL_KIND:
        check_polynomial_fields(path, static, arrays)
    try:
        return kind.from_arrays(static, arrays)
    except PolyjaxError:
        raise
    except (KeyError, TypeError, ValueError) as e:
        raise DataFormatError(path, f"the fields of a {kind_name} model", f"{e}") from None
