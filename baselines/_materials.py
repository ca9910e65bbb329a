"""The material dictionaries of the standard models (``BaselineModel.to_material``): a fit's R, G, B parameters
named as the model's specification names them, for the exporters of :mod:`polyjax.export`."""

from __future__ import annotations

from typing import Callable

import numpy as np

from polyjax import InputError


def material_writer(name: str, fitted: tuple[str, ...], fixed: dict, defaults: dict, written: tuple[str, ...],
                    colors: tuple[str, ...]) -> Callable:
    """``to_material(params (3, P)) -> dict`` of the model ``name`` fitting ``fitted``.

    The dict holds ``"model": name``, every input of ``written`` (at its default), the inputs the model fixes
    (``fixed``) and the fitted ones: colours (``colors``) as ``[r, g, b]``, the others as one float, the mean over
    the channels (the channels agree on them when fitted jointly, ``shared_across_channels``).
    """

    def to_material(params) -> dict:
        params = np.asarray(params, float)
        if params.shape != (3, len(fitted)):
            raise InputError(f"to_material: expected the (3, {len(fitted)}) R, G, B parameters {list(fitted)} of "
                             f"{name}, found shape {params.shape}")
        if not np.all(np.isfinite(params)):
            raise InputError(f"to_material: expected finite parameters of {name}, found {params.tolist()}")
        out = {"model": name, **{k: defaults[k] for k in written}, **fixed}
        for i, k in enumerate(fitted):
            out[k] = [float(x) for x in params[:, i]] if k in colors else float(np.mean(params[:, i]))
        return {k: [float(x)] * 3 if k in colors and not isinstance(x, list) else x for k, x in out.items()}

    return to_material
