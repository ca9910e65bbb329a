"""The material dictionaries of the standard models: a fit's R, G, B parameters named as the model's specification
names them (``BaselineModel.to_material``, made by :func:`material_writer`), for the exporters of
:mod:`polyjax.export`; :func:`channel_parameters` is the one check of a material's ``(3, P)`` parameters (also of
:func:`baselines.standard_material`)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from polyjax import InputError


def channel_parameters(params: np.ndarray, n: int, expected: str, note: str = "") -> np.ndarray:
    """``params`` when it is ``(3, n)``: one row of ``n`` parameters per colour channel (R, G, B); else an
    :class:`polyjax.InputError` saying ``expected``, the shape found and ``note``."""
    if params.shape != (3, n):
        raise InputError(f"{expected}, found shape {params.shape}{note}")
    return params


def material_writer(name: str, fitted: tuple[str, ...], fixed: dict, defaults: dict, written: tuple[str, ...],
                    colors: tuple[str, ...]) -> Callable:
    """``to_material(params (3, P)) -> dict`` of the model ``name`` fitting ``fitted``.

    The dict holds ``"model": name``, every input of ``written`` (at its default), the inputs the model fixes
    (``fixed``) and the fitted ones: colours (``colors``) as ``[r, g, b]``, the others as one float, the mean over
    the channels (the channels agree on them when fitted jointly, ``shared_across_channels``).
    """

    def to_material(params) -> dict:
        params = channel_parameters(np.asarray(params, float), len(fitted), f"to_material: expected the "
                                    f"(3, {len(fitted)}) R, G, B parameters {list(fitted)} of {name}")
        if not np.all(np.isfinite(params)):
            raise InputError(f"to_material: expected finite parameters of {name}, found {params.tolist()}")
        out = {"model": name, **{k: defaults[k] for k in written}, **fixed}
        for i, k in enumerate(fitted):
            out[k] = [float(x) for x in params[:, i]] if k in colors else float(np.mean(params[:, i]))
        return {k: [float(x)] * 3 if k in colors and not isinstance(x, list) else x for k, x in out.items()}

    return to_material
