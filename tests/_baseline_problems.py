"""Shared problem definitions for the baseline tests: a dense synthetic geometry, known parameters
for every model (scipy's least_squares reference is ``benchmarks.paper.references.scipy_best_l2``)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

#: Known constrained parameters per model (inside the transforms' ranges, away from the bounds).
TRUE_PARAMS = {
    "ashikhmin-shirley": [0.3, 0.4, 40.0, 0.3],
    "blinn-phong": [0.25, 0.3, 30.0],
    "cook-torrance": [0.3, 0.5, 0.25, 0.4],
    "lafortune": [0.35, -0.9, 0.85, 12.0],
    "oren-nayar": [0.6, 0.4],
    "ward": [0.3, 0.2, 0.15],
    "ward-duer": [0.3, 0.2, 0.2],
    "lafortune-anisotropic": [0.3, -1.0, -0.7, 0.9, 10.0],
    "ward-anisotropic": [0.3, 0.25, 0.12, 0.3],
}
#: one channel's parameters of the standard material models (fitted jointly over R, G, B)
STANDARD_PARAMS = {
    "gltf-pbr": [0.6, 0.3, 0.4],
    "gltf-pbr-specular": [0.6, 0.3, 0.4, 0.7, 1.6],
    "gltf-pbr-anisotropic": [0.6, 0.3, 0.4, 0.5, 0.7],
    "principled": [0.6, 0.4, 0.3, 0.6],
    "principled-anisotropic": [0.6, 0.4, 0.3, 0.6, 0.5],
}


def synthetic_geometry(n: int = 400, seed: int = 0, max_deg: float = 78.0):
    """``n`` random (u, v) pairs with polar angles up to ``max_deg`` and all azimuths, plus near-mirror pairs."""
    rng = np.random.default_rng(seed)

    def dirs(k):
        ct = rng.uniform(np.cos(np.deg2rad(max_deg)), 1.0, k)
        st = np.sqrt(1 - ct**2)
        ph = rng.uniform(-np.pi, np.pi, k)
        return np.stack([st * np.cos(ph), st * np.sin(ph), ct], -1)

    u = dirs(n)
    v = dirs(n)
    # a quarter of the views near the mirror direction so glossy lobes are sampled
    k = n // 4
    mirror = u[:k] * np.array([-1, -1, 1]) + 0.08 * rng.normal(size=(k, 3))
    mirror[:, 2] = np.abs(mirror[:, 2]) + 0.2
    v[:k] = mirror / np.linalg.norm(mirror, axis=-1, keepdims=True)
    return jnp.asarray(u), jnp.asarray(v)
