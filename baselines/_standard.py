"""A fitted standard material as its specification names it: :func:`standard_material`."""

from __future__ import annotations

import numpy as np

from polyjax import InputError

from ._registry import get_model


def standard_material(fit, index=()) -> dict:
    """The material of one fitted material lane of a standard model, named as its specification names it.

    Args:
        fit: a :class:`baselines.BaselineFit` of a standard model (:data:`baselines.STANDARD_MODELS`), params
            ``(..., 3, P)``.
        index: the material's index in the batch axes before the channel axis (``()`` for one material).

    Returns:
        ``{"model": <name>, <parameter>: float or [r, g, b], ...}``, e.g. for ``gltf-pbr``
        ``{"model": "gltf-pbr", "baseColorFactor": [r, g, b], "metallicFactor": m, "roughnessFactor": r}``;
        ready for :func:`polyjax.export.gltf` and :func:`polyjax.export.mitsuba_xml`.

    Raises:
        InputError: ``fit`` is not a fit of a standard model, or ``index`` does not select one material.
    """
    name = getattr(fit, "name", None)
    model = get_model(name) if isinstance(name, str) else None
    if model is None or model.to_material is None:
        raise InputError(f"fit: expected a baselines fit of a standard material model, found {name!r}")
    index = index if isinstance(index, tuple) else (index,)
    params = np.asarray(fit.params)
    try:
        p = params[index]
    except IndexError as err:
        raise InputError(f"index: {index} is not a material of the fit's batch shape {params.shape[:-2]}") from err
    if p.shape != (3, model.n_params):
        raise InputError(f"index: expected one material's (3, {model.n_params}) parameters, found shape {p.shape}; "
                         f"the fit's batch shape is {params.shape[:-1]}")
    return model.to_material(p)
