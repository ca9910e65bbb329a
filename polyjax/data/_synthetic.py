"""A small built-in dataset for machines without the measured data.

It is **synthetic**, not measured: directions drawn from a fixed seed and values of an
analytic Lambertian-plus-Lafortune-lobe BRDF with a little multiplicative noise.
"""

from __future__ import annotations

import numpy as np

from .._measurements import Measurements, make_measurements

SYNTHETIC_DESCRIPTION = (
    "built-in SYNTHETIC example (not measured data): 400 random direction pairs, "
    "values of an analytic Lambertian + Lafortune lobe BRDF with 2% noise"
)

#: (name, albedo, lobe scale C, exponent n)
_MATERIALS = (
    ("synthetic-matte", 0.6, 0.3, 3.0), ("synthetic-satin", 0.35, 1.0, 8.0), ("synthetic-glossy", 0.2, 3.0, 20.0),
)


def synthetic_default(n: int = 400, seed: int = 0) -> Measurements:
    """The built-in synthetic dataset (three materials) used when no data root is configured."""
    rng = np.random.default_rng(seed)

    def hemi(k):
        ct = rng.uniform(0.05, 1.0, k)
        ph = rng.uniform(-np.pi, np.pi, k)
        st = np.sqrt(1 - ct**2)
        return np.stack([st * np.cos(ph), st * np.sin(ph), ct], -1)

    u, v = hemi(n), hemi(n)
    lob = -u[:, 0] * v[:, 0] - u[:, 1] * v[:, 1] + u[:, 2] * v[:, 2]
    vals = []
    for _, albedo, c, e in _MATERIALS:
        f = albedo / np.pi + c * np.maximum(lob, 0.0) ** e
        vals.append(f * (1 + 0.02 * rng.standard_normal(n)))
    return make_measurements(
        u, v, np.stack(vals), names=[m[0] for m in _MATERIALS], channels=("avg",), axes=("material",),
        source=SYNTHETIC_DESCRIPTION,
    )
