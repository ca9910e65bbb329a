r"""What the page shows: every fit or data set becomes one :class:`ViewItem` of one of three kinds.

- ``"program"``: a model the expression builder writes out (:func:`polyjax.export._expr.program`: a
  :class:`polyjax.PolynomialBRDF`, a ``polyjax.data.NeuralBRDF``). Its GLSL function is printed from the same
  :class:`~polyjax.export._expr.Program` as the GLSL export, so the page evaluates the very arithmetic of
  ``polyjax export --to glsl``.
- ``"table"``: a BRDF on the MERL grid (``(N_h, N_d, N_p)`` bins, theta_h index ``sqrt(theta_h / (pi/2)) N_h``,
  MERL's readBRDF convention, :mod:`polyjax.data._merl`), shown through a 3D texture with trilinear filtering
  between bin centres. Dense measured data (MERL ``.binary``, the neural MERL sets, any data set filling at least
  :data:`DENSE_FRACTION` of the bins) is binned into it (mean of the samples of each bin); any other evaluable
  model (a ``baselines.BaselineFit``, which the expression builder does not cover) is tabulated at the bin centres
  with :func:`polyjax.export.tabulate_merl`.
- ``"points"``: scattered measurements (CUReT's 205 pairs, Cornell's 1439): a texture would be mostly empty, so
  the page plots the samples themselves (value against ``theta_h``, and beside a fit the fit at the same
  directions).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .._compact.model import CompactBRDF
from .._errors import InputError
from .._measurements import Measurements
from .._model import PolynomialBRDF
from ..data._merl import directions_to_rusinkiewicz, merl_index
from ..data._nbrdf import NeuralBRDF
from ..export._expr import program
from ..export._merl import tabulate_both_orders

#: the MERL grid (theta_h, theta_d, phi_d bins), the default resolution of tables
MERL_RESOLUTION = (90, 90, 180)
#: a data set filling at least this fraction of the table's bins is shown as a table, else as points
DENSE_FRACTION = 0.2
#: at most this many items from one argument (materials of a batched model or data set)
MAX_LANES = 8


@dataclasses.dataclass
class ViewItem:
    """One thing the page shows.

    Attributes:
        name: its label.
        kind: ``"program"``, ``"table"`` or ``"points"`` (module docstring).
        info: the numbers shown beside the views (model, parameters, L2, source, notes): JSON values.
        program: the expression program (kind ``"program"``).
        table: float32 ``(N_h, N_d, N_p, 3)`` BRDF values in 1/sr (kind ``"table"``); ``(N_h, N_d, 2 N_p, 3)``,
            ``phi_d`` over the whole turn, for a BRDF that is not reciprocal (:func:`polyjax.export._merl.whole_turn`).
        u, v, values: float32 ``(n, 3)``, ``(n, 3)``, ``(n, 3)`` samples (kind ``"points"``).
        model: the Python model, kept for callers that compare with the page (not written into it).
        capture: the :class:`polyjax.Capture` whose photographs the page shows (a capture's ``"points"`` item,
            :mod:`polyjax.view._capture`).
        fit_seconds: a fit's time as saved with the model (:func:`fit_time`); None when not recorded.
        reciprocal: False for a table over the whole turn of ``phi_d`` (``table``).
    """

    name: str
    kind: str
    info: dict
    program: object = None
    table: np.ndarray | None = None
    u: np.ndarray | None = None
    v: np.ndarray | None = None
    values: np.ndarray | None = None
    model: object = None
    capture: object = None
    reciprocal: bool = True
    fit_seconds: float | None = None


def _lanes(obj, what: str) -> list[tuple[str, object]]:
    """``[(suffix, lane)]``: the object itself when its batch shape is ``()``, ``(1,)`` or ``(3,)`` (one BRDF),
    else one entry per index of its first axis (at most :data:`MAX_LANES`)."""
    bs = tuple(getattr(obj, "batch_shape", ()))
    if bs in ((), (1,), (3,)):
        return [("", obj)]
    if bs[0] > MAX_LANES:
        raise InputError(f"{what}: holds {bs[0]} BRDFs (batch shape {bs}); expected at most {MAX_LANES}: select "
                         "lanes with FILE#i")
    return [(f"[{i}]", obj[i]) for i in range(bs[0])]


def _array_list(a) -> list:
    """Numbers for the page's JSON: rounded to 8 decimals, non-finite ones (a failed lane's L2) as None."""
    a = np.round(np.asarray(a, np.float64), 8).ravel()
    return [float(x) if np.isfinite(x) else None for x in a]


def _polynomial_info(model: PolynomialBRDF) -> dict:
    info = {"model": "polynomial", "variables": model.variables, "basis": model.basis,
            "degree": _array_list(model.degree), "interactions": bool(model.interactions),
            "parameters": [int(n) for n in np.asarray(model.n_params).ravel()],
            "L2": _array_list(model.l2), "coefficients": _array_list(model.coefficients)}
    if model.link != "identity":
        bounded = "min(poly, log_top)" if model.log_top is not None else "poly"
        info["link"] = f"{model.link} (f = exp({bounded}) - {model.eps:g})"
    if model.clamp:
        info["outside the fitted samples"] = "clamped to the fitted box (constant extension)"
    return info


def _compact_info(model: CompactBRDF) -> dict:
    """The family, configuration, numbers per material and held-out errors of a compact model."""
    return {"model": "compact", "family": model.family, "config": repr(model.config),
            "numbers per material": model.n_numbers, "L2 (held out)": _array_list(model.l2),
            "log error (held out)": _array_list(model.log)}


def _fit_info(model) -> dict:
    """Name, parameter names and values (one row per lane) and L2 of a fitted model with ``params`` (a
    ``baselines.BaselineFit``); the name alone when its parameters are not one numeric array."""
    info = {"model": getattr(model, "name", type(model).__name__)}
    try:
        params = np.asarray(model.params, np.float64)
    except (TypeError, ValueError):
        return info
    names = list(getattr(model, "param_names", ())) or [f"p{i}" for i in range(params.shape[-1] if params.ndim else 1)]
    rows = params.reshape(-1, len(names))
    info.update(parameters=names, values=[dict(zip(names, _array_list(p))) for p in rows])
    if hasattr(model, "l2"):
        info["L2"] = _array_list(model.l2)
    return info


def fit_time(metadata: dict | None) -> tuple[str, float | None]:
    """``(text, seconds or None)`` of the fit time a model file keeps (:func:`polyjax.model_metadata`:
    ``fit_seconds``, written by ``polyjax fit --save`` and ``polyjax fit-photos --save``, compilation included);
    "not recorded" when it keeps none (older files, models saved from Python or never saved)."""
    seconds = (metadata or {}).get("fit_seconds")
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) or not np.isfinite(seconds) or seconds < 0:
        return "not recorded (the model was not saved with its fit time)", None
    command = (metadata or {}).get("fit_command", "fit")
    return f"{seconds:.3f} s (polyjax {command}, compilation included)", float(seconds)


def _with_fit_time(info: dict, text: str) -> dict:
    """``info`` with the row ``"fit time"`` after ``"L2"`` (at the end when there is none)."""
    out = {}
    for key, value in info.items():
        out[key] = value
        if key == "L2":
            out["fit time"] = text
    out.setdefault("fit time", text)
    return out


def model_items(model, name: str, resolution=MERL_RESOLUTION, metadata: dict | None = None) -> list[ViewItem]:
    """The items of a fitted model: programs for what the expression builder covers, tables otherwise; each with
    the fit time of ``metadata`` (the model file's, :func:`fit_time`)."""
    items = []
    lanes = _lanes(model, name)
    text, seconds = fit_time(metadata)
    text += " (all lanes of the file together)" if seconds is not None and len(lanes) > 1 else ""
    for suffix, lane in lanes:
        label = name + suffix
        if isinstance(lane, (PolynomialBRDF, NeuralBRDF)):
            info = _polynomial_info(lane) if isinstance(lane, PolynomialBRDF) else \
                {"model": "neural BRDF (Sztrajman et al. 2021)", "name": getattr(lane, "name", "")}
            try:
                item = ViewItem(label, "program", info, program=program(lane), model=lane)
            except InputError as e:  # variables the expression builder does not write (e.g. rusinkiewicz)
                item = _tabulated(lane, label, resolution, info, str(e).removeprefix("model: "))
        elif isinstance(lane, CompactBRDF):  # every family is a table here (no expression program for them yet)
            item = _tabulated(lane, label, resolution, _compact_info(lane), "compact models are shown as tables")
        elif callable(lane):
            item = _tabulated(lane, label, resolution)
        else:
            raise InputError(f"{name}: expected a fitted model (a callable f(u, v)), found {type(lane).__name__}")
        item.info, item.fit_seconds = _with_fit_time(item.info, text), seconds
        items.append(item)
    return items


def _shown_as(resolution, reciprocal: bool, what: str) -> str:
    turn = "" if reciprocal else (f"; not reciprocal: phi_d over the whole turn, {2 * resolution[2]} bins, "
                                  "f(u, v) and f(v, u) each in its own")
    return f"table: {what} at the centres of the {'x'.join(map(str, resolution))} MERL bins{turn}"


def _tabulated(model, name: str, resolution, info=None, why="no GLSL expression for this model") -> ViewItem:
    values, _, turn = tabulate_both_orders(model, resolution)
    table, reciprocal = np.moveaxis(values, 0, -1).astype(np.float32), not turn
    if info is None:
        info = _fit_info(model) if hasattr(model, "params") else {"model": type(model).__name__}
    info["shown as"] = _shown_as(resolution, reciprocal, "tabulated") + f" ({why})"
    return ViewItem(name, "table", info, table=table, model=model, reciprocal=reciprocal)


def _rgb(values: np.ndarray) -> np.ndarray:
    """``(C, n)`` or ``(n,)`` values -> ``(n, 3)`` (grey repeated)."""
    values = np.asarray(values, np.float64)
    values = values[None] if values.ndim == 1 else values
    if values.shape[0] not in (1, 3):
        raise InputError(f"data: expected 1 or 3 channels per material, found {values.shape[0]}")
    return np.repeat(values, 3, axis=0).T if values.shape[0] == 1 else values.T


def _binned(u, v, rgb, valid, resolution):
    """``(table (N_h, N_d, N_p, 3), filled fraction)``: the mean of the valid samples in each MERL bin."""
    th, td, pd = directions_to_rusinkiewicz(u, v)
    idx = merl_index(th, td, pd, resolution)[valid]
    n = int(np.prod(resolution))
    counts = np.bincount(idx, minlength=n)
    sums = np.stack([np.bincount(idx, weights=rgb[valid, c], minlength=n) for c in range(3)], -1)
    table = sums / np.maximum(counts, 1)[:, None]
    return table.astype(np.float32).reshape(*resolution, 3), float(np.mean(counts > 0))


def data_items(data: Measurements, name: str, resolution=MERL_RESOLUTION) -> list[ViewItem]:
    """The items of a data set: one per material; a table when dense on the MERL grid, else points."""
    if not isinstance(data, Measurements):
        raise InputError(f"{name}: expected polyjax.Measurements, found {type(data).__name__}")
    values = np.asarray(data.values, np.float64)
    lead = values.shape[:-2] if data.axes[-1:] == ("channel",) else values.shape[:-1]
    flat = values.reshape((-1,) + values.shape[len(lead):])
    mask = np.broadcast_to(np.asarray(data.mask), values.shape).reshape((-1,) + values.shape[len(lead):])
    if flat.shape[0] > MAX_LANES:
        raise InputError(f"{name}: holds {flat.shape[0]} materials; expected at most {MAX_LANES} (name fewer)")
    u, v = np.asarray(data.u, np.float64), np.asarray(data.v, np.float64)
    names = list(data.names) if len(data.names) == flat.shape[0] else [f"{name}[{i}]" for i in range(flat.shape[0])]
    items = []
    for label, vals, m in zip(names, flat, mask):
        valid = m if m.ndim == 1 else m.all(axis=0)
        rgb = _rgb(vals)
        info = {"model": "measured data", "source": data.source, "samples": int(valid.sum()),
                "channels": list(data.channels)}
        table, filled = _binned(u, v, rgb, valid, resolution)
        if filled >= DENSE_FRACTION:
            info["shown as"] = (f"table: samples binned into the {'x'.join(map(str, resolution))} MERL grid "
                                f"({100 * filled:.1f}% of the bins filled)")
            items.append(ViewItem(label, "table", info, table=table, model=data))
        else:
            info["shown as"] = "points: scattered samples (a table would be mostly empty)"
            items.append(ViewItem(label, "points", info, u=u[valid].astype(np.float32),
                                  v=v[valid].astype(np.float32), values=rgb[valid].astype(np.float32), model=data))
    return items
