r"""Mitsuba 3's ``roughconductor`` BSDF (``src/bsdfs/roughconductor.cpp``), isotropic, without
``specular_reflectance``, as a standard material model: ``roughconductor`` (GGX) and ``roughconductor-beckmann``.

Parameters of one channel: ``eta``, ``k`` (the conductor's complex index of refraction ``eta + i k`` in that channel)
and ``alpha`` (the distribution's roughness, shared by R, G, B).
"""

from __future__ import annotations

import functools

import numpy as np

from .common import BaselineModel, Geometry, LogBounded, grid, lobe, uniform_sampler
from .mi_microfacet import fresnel_conductor, ndf, smith_g1

#: alpha range (Mitsuba clamps alpha at 1e-4)
ALPHA = LogBounded(2e-3, 1.0)
ETA = LogBounded(0.02, 6.0)
K = LogBounded(0.01, 12.0)


def roughconductor_brdf(eta, k, alpha, u, v, beckmann: bool = False):
    r"""Mitsuba 3's ``roughconductor`` BRDF of one channel (its ``eval`` divided by ``cos theta_u``):

    .. math:: f = \frac{F_c(v\cdot h;\ \eta + i k)\, D(h)\, G_1(v, h)\, G_1(u, h)}{4 \cos\theta_u \cos\theta_v},

    ``F_c`` the unpolarised conductor Fresnel reflectance, ``D`` and ``G_1`` GGX (or Beckmann) of roughness
    ``alpha`` (:mod:`baselines._models.mi_microfacet`); 0 where a direction is below the horizon.
    """
    g = Geometry(u, v)
    d = ndf(g.nh, alpha, beckmann)
    gg = smith_g1(g.v, g.h, alpha, beckmann) * smith_g1(g.u, g.h, alpha, beckmann)
    return lobe(g, fresnel_conductor(g.vh, eta, k) * d * gg / (4.0 * g.cu * g.cv))


def _evaluate(params, u, v, beckmann: bool):
    return roughconductor_brdf(params[0], params[1], params[2], u, v, beckmann)


def _material(distribution: str):
    def to_material(params) -> dict:
        p = np.asarray(params, float)
        return {"model": "roughconductor", "distribution": distribution, "alpha": float(p[0, 2]),
                "eta": [float(x) for x in p[:, 0]], "k": [float(x) for x in p[:, 1]]}

    return to_material


def _record(name: str, beckmann: bool) -> BaselineModel:
    return BaselineModel(
        name=name, param_names=("eta", "k", "alpha"), transforms=(ETA, K, ALPHA),
        evaluate=functools.partial(_evaluate, beckmann=beckmann), n_linear=0, columns=None,
        guesses=grid([0.3, 1.5], [3.0], [0.05, 0.2, 0.5]),
        sample=uniform_sampler([(0.05, 4.0, True), (0.1, 8.0, True), (0.005, 1.0, True)]),
        shared_across_channels=("alpha",), to_material=_material("beckmann" if beckmann else "ggx"),
        reference="Mitsuba 3 roughconductor plugin (Walter et al. 2007)",
    )


MODEL = _record("roughconductor", False)
BECKMANN = _record("roughconductor-beckmann", True)
