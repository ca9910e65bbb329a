r"""Which Mitsuba 3 plugin ``polyjax export --to mitsuba-xml`` writes: the simplest that fits as well as
``principled``.

The candidates, simplest first: ``roughconductor`` (one GGX specular lobe with a conductor's Fresnel, ``alpha`` and
``eta``, ``k`` per channel), ``roughplastic`` (a GGX dielectric lobe over a diffuse base, ``alpha``, ``int_ior`` and
``diffuse_reflectance`` per channel), ``principled`` (Disney's principled BRDF: ``base_color``, ``roughness``,
``metallic``, ``specular``). Each is fitted to the data (R, G, B jointly, equation (11) with the 80-degree cutoff);
with ``--plugin auto`` (the default) the first candidate whose L2, the mean over R, G, B, is at most
``(1 + tolerance)`` times ``principled``'s (``--tolerance``, 0.05 by default) is written, else ``principled``.
"""

from __future__ import annotations

import numpy as np

from .._errors import InputError
from .._io import fitter_for

#: the Mitsuba plugins ``--to mitsuba-xml`` chooses from, simplest first (each a model of that name)
PLUGINS = ("roughconductor", "roughplastic", "principled")
#: how much larger than ``principled``'s mean L2 a simpler plugin's may be and still be chosen
TOLERANCE = 0.05


def choose_plugin(errors: dict[str, float], tolerance: float = TOLERANCE) -> str:
    """The first of :data:`PLUGINS` in ``errors`` whose error is finite and at most ``(1 + tolerance)`` times
    ``errors["principled"]``; ``"principled"`` if none is (or if only it was fitted)."""
    ref = float(errors["principled"])
    for name in PLUGINS:
        e = float(errors.get(name, np.inf))
        if np.isfinite(e) and e <= (1.0 + tolerance) * ref:
            return name
    return "principled"


def fit_plugin(data, plugin: str, tolerance: float):
    """``(model name, fit)``: the fit of ``plugin`` to ``data``, or with ``"auto"`` of every candidate and the one
    :func:`choose_plugin` picks (each candidate's mean L2 printed)."""
    if plugin != "auto" and plugin not in PLUGINS:
        raise InputError(f"--plugin: expected 'auto' or one of {list(PLUGINS)}, found {plugin!r}")
    if not (isinstance(tolerance, (int, float)) and np.isfinite(tolerance) and tolerance >= 0):
        raise InputError(f"--tolerance: expected a finite number >= 0, found {tolerance!r}")
    fits, errors = {}, {}
    for name in PLUGINS if plugin == "auto" else (plugin,):
        kind, model_name = fitter_for(name)
        fits[name] = kind.fit(model_name, data)
        errors[name] = float(np.mean(np.asarray(fits[name].l2)))
    if plugin != "auto":
        return plugin, fits[plugin]
    chosen = choose_plugin(errors, tolerance)
    print("Mitsuba plugins, mean L2 (eq. 11) over R, G, B: " + ", ".join(f"{k} {e:.4g}" for k, e in errors.items())
          + f"; chosen: {chosen} (the simplest within {tolerance:g} of principled's)")
    return chosen, fits[chosen]
