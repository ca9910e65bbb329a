"""Which items a command-line argument or a Python object makes: saved model files, capture folders, data set specs
(:mod:`polyjax.view._items`, :mod:`polyjax.view._capture`, :mod:`polyjax.view._rgl`)."""

from __future__ import annotations

from pathlib import Path

import polyjax as pj

from .._errors import DataNotFoundError, InputError
from .._io import load_model
from .._measurements import Measurements
from ..inverse._capture import Capture
from ._capture import capture_items
from ._items import MERL_RESOLUTION, ViewItem, data_items, model_items
from ._rgl import rgl_items


def items_from_argument(arg: str, root=None, resolution=MERL_RESOLUTION, lights=None) -> list[ViewItem]:
    """The items of one command-line argument: a saved model file (``.npz``/``.json``, ``FILE#i`` for lane ``i``),
    a photometric capture's folder in DiLiGenT's layout (:func:`polyjax.data.load_photometric` of its ``lights``,
    None: all; :mod:`polyjax.view._capture`) or a data set spec of :func:`polyjax.data.load` (``curet:25``,
    ``merl-nbrdf:green-latex``, ``cornell:cayman``, ``merl:<file>``, ``rgl:<file>``: :mod:`polyjax.view._rgl`)."""
    if Path(arg).is_dir():
        return capture_items(pj.data.load_photometric(arg, lights), Path(arg).name, source=f"capture {arg}")
    arg = pj.data.dataset_spec(arg)  # a bare .bsdf / .binary path: the rule of every command
    if arg.strip().lower().startswith("rgl:"):
        return rgl_items(arg, root, resolution)
    path, sep, index = arg.rpartition("#")
    path = path if sep else arg
    if Path(path).suffix.lower() in (".npz", ".json"):
        if not Path(path).is_file():
            raise DataNotFoundError(f"{path!r}: no such model file")
        model = load_model(path)
        if sep:
            try:
                model = model[int(index)]
            except (ValueError, IndexError, TypeError) as e:
                raise InputError(f"{arg!r}: expected FILE#i with i a lane of the model's batch shape "
                                 f"{getattr(model, 'batch_shape', ())}") from e
        return model_items(model, Path(path).stem + (f"[{index}]" if sep else ""), resolution,
                           pj.model_metadata(path))
    if ":" not in arg:
        raise InputError(f"{arg!r}: expected a saved model (.npz or .json), a capture's folder or a data set spec "
                         "such as curet:25, merl-nbrdf:green-latex, cornell:cayman, merl:<file.binary>, "
                         "rgl:<file.bsdf> (or a .bsdf or .binary file by its path alone)")
    return data_items(pj.data.load(arg, root=root), arg, resolution)


def as_items(objects, resolution=MERL_RESOLUTION, root=None, lights=None) -> list[ViewItem]:
    """Items from a mix of :class:`ViewItem`, models, :class:`polyjax.Measurements`, :class:`polyjax.Capture`,
    ``(name, object)`` pairs and command-line strings (``lights``: of the capture folders among them)."""
    items = []
    for i, obj in enumerate(objects):
        name, obj = obj if isinstance(obj, tuple) and len(obj) == 2 and isinstance(obj[0], str) else (None, obj)
        if isinstance(obj, ViewItem):
            items.append(obj)
        elif isinstance(obj, (str, Path)):
            items.extend(items_from_argument(str(obj), root, resolution, lights))
        elif isinstance(obj, Capture):
            items.extend(capture_items(obj, name or f"capture {i}"))
        elif isinstance(obj, Measurements):
            items.extend(data_items(obj, name or (obj.names[0] if len(obj.names) == 1 else f"data {i}"), resolution))
        else:
            items.extend(model_items(obj, name or f"{type(obj).__name__} {i}", resolution))
    if not items:
        raise InputError("items: expected at least one fit or data set to show")
    return items
