"""Saving and loading fitted polynomial models (``.npz`` or ``.json``), bit-exact."""

from __future__ import annotations

import json
import os
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from ._errors import DataFormatError, DataNotFoundError
from ._model import PolynomialBRDF

FORMAT = "polyjax.PolynomialBRDF"
VERSION = 1
_ARRAYS = ("coefficients", "degree", "mean", "rotation", "centre", "halfwidth", "l2", "rank", "condition", "n_used", "status")
_STATIC = ("variables", "basis", "interactions", "max_degree")
_OPTIONAL = {"link": "identity", "eps": 0.0}  # log-space models (polyjax._logfit); absent in older files


def save_model(path: str | os.PathLike, model: PolynomialBRDF) -> Path:
    """Write ``model`` to ``path``: ``.json`` (text, exact float repr) or anything else as ``.npz``.

    The variable set is stored by name: a user-registered set must be registered again before loading.
    """
    path = Path(path)
    meta = {"format": FORMAT, "version": VERSION, **{k: getattr(model, k) for k in _STATIC + tuple(_OPTIONAL)}}
    arrays = {k: np.asarray(getattr(model, k)) for k in _ARRAYS}
    if path.suffix == ".json":
        doc = dict(meta)
        doc["arrays"] = {
            k: {"dtype": str(a.dtype), "shape": list(a.shape), "data": [float(x) if a.dtype.kind == "f" else int(x) for x in a.ravel()]}
            for k, a in arrays.items()
        }
        path.write_text(json.dumps(doc))
    else:
        if path.suffix != ".npz":
            path = path.with_suffix(path.suffix + ".npz") if path.suffix else path.with_suffix(".npz")
        np.savez(path, __meta__=np.asarray(json.dumps(meta)), **arrays)
    return path


def load_model(path: str | os.PathLike) -> PolynomialBRDF:
    """Read a model written by :func:`save_model`; it evaluates identically."""
    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"{str(path)!r}: no such model file")
    try:
        if path.suffix == ".json":
            doc = json.loads(path.read_text())
            meta = doc
            if isinstance(doc, dict) and doc.get("format") == FORMAT:
                arrays = {
                    k: np.asarray(v["data"], dtype=v["dtype"]).reshape(v["shape"]) for k, v in doc["arrays"].items()
                }
            else:
                arrays = {}
        else:
            with np.load(path, allow_pickle=False) as z:
                meta = json.loads(str(z["__meta__"]))
                arrays = {k: z[k] for k in z.files if k != "__meta__"}
    except (ValueError, KeyError, OSError) as e:
        raise DataFormatError(path, f"a {FORMAT} file written by save_model", f"unreadable content ({e})") from None
    if not isinstance(meta, dict) or meta.get("format") != FORMAT:
        raise DataFormatError(path, f"format {FORMAT!r}", repr(meta.get("format") if isinstance(meta, dict) else meta))
    missing = [k for k in _ARRAYS if k not in arrays]
    if missing:
        raise DataFormatError(path, f"arrays {list(_ARRAYS)}", f"missing {missing}")
    return PolynomialBRDF(
        **{k: jnp.asarray(arrays[k]) for k in _ARRAYS}, **{k: meta[k] for k in _STATIC},
        **{k: type(d)(meta.get(k, d)) for k, d in _OPTIONAL.items()},
    )
