r"""Which Mitsuba 3 plugin ``polyjax export --to mitsuba-xml`` writes: the simplest that fits as well as
``principled``.

The candidates, simplest first: ``roughconductor`` (one GGX specular lobe with a conductor's Fresnel, ``alpha`` and
``eta``, ``k`` per channel), ``roughplastic`` (a GGX dielectric lobe over a diffuse base, ``alpha``, ``int_ior`` and
``diffuse_reflectance`` per channel), ``principled`` (Disney's principled BRDF: ``base_color``, ``roughness``,
``metallic``, ``specular``). Each is fitted to the data (R, G, B jointly, equation (11) with the 80-degree cutoff);
with ``--plugin auto`` (the default) the first candidate whose L2, the mean over R, G, B, is at most
``(1 + tolerance)`` times ``principled``'s (``--tolerance``, 0.05 by default) is written, else ``principled``.

A candidate of another material class than the one ``principled`` fitted (``roughconductor`` is a metal,
``roughplastic`` a dielectric; ``principled`` is a metal when its fitted ``metallic`` is at least 0.5) must also win
on the log-space error (:func:`polyjax.log_error`, the root mean square over R, G, B, 80-degree cutoff): at most
``principled``'s. The L2 of equation (11) weighs the bright specular peak; a metal's lobe can match that peak of a
dielectric (a satin film) within the tolerance while its diffuse part, dark to the L2 but not to the eye, is wrong.
"""

from __future__ import annotations

import numpy as np

from .._errors import InputError
from .._io import fitter_for
from .._metrics import log_error
from .._run.interrupt import check_interrupt

#: the Mitsuba plugins ``--to mitsuba-xml`` chooses from, simplest first (each a model of that name)
PLUGINS = ("roughconductor", "roughplastic", "principled")
#: how much larger than ``principled``'s mean L2 a simpler plugin's may be and still be chosen
TOLERANCE = 0.05
#: the material class of each simpler plugin (``principled``'s is that of its fitted ``metallic``)
PLUGIN_CLASS = {"roughconductor": "metal", "roughplastic": "dielectric"}


def choose_plugin(errors: dict[str, float], tolerance: float = TOLERANCE, *, log_errors: dict | None = None,
                  principled_class: str | None = None) -> str:
    """The first of :data:`PLUGINS` in ``errors`` whose error is finite and at most ``(1 + tolerance)`` times
    ``errors["principled"]``, and, when it is of another class (:data:`PLUGIN_CLASS`) than ``principled_class``
    (``"metal"`` or ``"dielectric"``), whose ``log_errors`` entry is at most ``principled``'s; ``"principled"`` if
    none is (or if only it was fitted). Without ``log_errors`` and ``principled_class`` the L2 alone decides."""
    ref = float(errors["principled"])
    for name in PLUGINS:
        e = float(errors.get(name, np.inf))
        if not (np.isfinite(e) and e <= (1.0 + tolerance) * ref):
            continue
        if name in PLUGIN_CLASS and principled_class is not None and PLUGIN_CLASS[name] != principled_class:
            lg = float((log_errors or {}).get(name, np.inf))
            if not (np.isfinite(lg) and lg <= float((log_errors or {}).get("principled", np.inf))):
                continue
        return name
    return "principled"


def _log_error(fit, data) -> float:
    """The log-space error of ``fit`` on ``data``: the root mean square over its R, G, B lanes."""
    u, v = np.asarray(data.u), np.asarray(data.v)
    per = log_error(data.values, fit(u, v), u, v, data.weights, cutoff_deg=80.0, mask=data.mask)
    return float(np.sqrt(np.mean(np.square(np.asarray(per)))))


def material_class(fit) -> str:
    """``"metal"`` or ``"dielectric"``: a ``principled`` fit's class by its fitted ``metallic`` (at least 0.5: a
    metal)."""
    return "metal" if float(fit.material()["metallic"]) >= 0.5 else "dielectric"


def fit_plugin(data, plugin: str, tolerance: float):
    """``(model name, fit)``: the fit of ``plugin`` to ``data``, or with ``"auto"`` of every candidate and the one
    :func:`choose_plugin` picks (each candidate's mean L2 and log-space error printed)."""
    if plugin != "auto" and plugin not in PLUGINS:
        raise InputError(f"--plugin: expected 'auto' or one of {list(PLUGINS)}, found {plugin!r}")
    if not (isinstance(tolerance, (int, float)) and np.isfinite(tolerance) and tolerance >= 0):
        raise InputError(f"--tolerance: expected a finite number >= 0, found {tolerance!r}")
    fits, errors, logs = {}, {}, {}
    for name in PLUGINS if plugin == "auto" else (plugin,):
        check_interrupt()  # Ctrl-C between the plugins' fits
        kind, model_name = fitter_for(name)
        fits[name] = kind.fit(model_name, data)
        errors[name] = float(np.mean(np.asarray(fits[name].l2)))
    if plugin != "auto":
        return plugin, fits[plugin]
    logs = {name: _log_error(f, data) for name, f in fits.items()}
    cls = material_class(fits["principled"])
    chosen = choose_plugin(errors, tolerance, log_errors=logs, principled_class=cls)
    print("Mitsuba plugins, mean L2 (eq. 11) over R, G, B / log-space error: "
          + ", ".join(f"{k} {e:.4g} / {logs[k]:.4g}" for k, e in errors.items())
          + f"; chosen: {chosen} (the simplest within {tolerance:g} of principled's L2; principled fitted a {cls}, "
          "a plugin of the other class must also match its log-space error)")
    return chosen, fits[chosen]
