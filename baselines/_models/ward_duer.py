"""Ward-Duer (Ward's lobe with Duer's normalisation, Lambertian diffuse): the Ward model (:mod:`baselines._models.ward`)
with another normalisation, its parameters, ranges and starts unchanged."""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp

from .common import Geometry, diffuse_specular_columns
from .ward import MODEL as WARD
from .ward import ward_lobe


def _specular(alpha, g):
    return ward_lobe(alpha, g, lambda s, g: s * g.cu * g.cv)


def ward_duer(params, u, v):
    r"""Ward-Duer BRDF (Ward's Gaussian lobe, ``1 / sqrt(cos cos)`` replaced by ``1 / (cos cos)``):

    .. math::
        f = \frac{\rho_d}{\pi} + \rho_s \frac{\exp(-\tan^2\delta / \alpha^2)}{4\pi\alpha^2\,(n\cdot u)(n\cdot v)} .

    Reference: A. Duer, "An improved normalization for the Ward reflectance model", Journal of
    Graphics Tools 11(1), 2006; as fitted by Ngan, Durand, Matusik 2005.

    Args, returns: as :func:`baselines.ward` (``params = (rho_d, rho_s, alpha)``, alpha in (1e-3, 3)).
    """
    return params[0] / jnp.pi + params[1] * _specular(params[2], Geometry(u, v))


MODEL = dataclasses.replace(
    WARD, name="ward-duer", evaluate=ward_duer, columns=diffuse_specular_columns(_specular),
    reference="Duer, J. Graphics Tools 11(1) 2006",
)
