r"""The image a capture's ``.glb`` card shows under one directional light, by the glTF 2.0 BRDF itself
(specification appendix B): what a renderer that follows the specification draws, to compare a renderer's image
and the photographs with (:func:`render_card`).

Per pixel, with the card's normal ``n`` (its normal map), view ``v = (0, 0, 1)``, light direction ``l``,
``h = (l + v) / |l + v|``, ``x = (1 - v.h)^5``, base colour ``c``, metallic ``M``, ``D V`` glTF's GGX lobe
(:func:`polyjax.export.ggx_specular`):

.. math::
    f = (1 - M)\,\big[(1 - F_d)\,c/\pi + F_d\,D V\big] + M\,F_m\,D V, \qquad F_d = 0.04 k + (1 - 0.04 k)\,x,
    \quad F_m = c + (1 - c)\,x,

``k`` the card's specular weight (``KHR_materials_specular``: dielectric ``F0 = 0.04 k``, ``F90 = 1``),

and the pixel is ``scale E max(0, n . l) f`` (``E`` the capture's irradiance, ``scale`` the card's light scale), 0
off the mask: in the capture's camera units.
"""

from __future__ import annotations

import numpy as np
from jaxtyping import ArrayLike

from .._errors import InputError
from ._card_maps import CardMaps


def _ggx(nl, nv, nh, roughness):
    a2 = np.maximum(roughness, 1e-2) ** 4
    d = a2 / (np.pi * (nh * nh * (a2 - 1.0) + 1.0) ** 2)
    den = nl * np.sqrt(nv * nv * (1.0 - a2) + a2) + nv * np.sqrt(nl * nl * (1.0 - a2) + a2)
    return d * 0.5 / np.maximum(den, 1e-12)


def render_card(maps: CardMaps, direction: ArrayLike, irradiance: ArrayLike = 1.0) -> np.ndarray:
    """The card's image ``(H, W, 3)`` under a directional light (module notes).

    Args:
        maps: the card's :class:`~polyjax.export.CardMaps` (:func:`~polyjax.export.card_maps`).
        direction: ``(3,)`` direction towards the light, camera frame (normalised here).
        irradiance: the light's irradiance ``E``, a number or ``(3,)`` RGB, in the capture's units.

    Raises:
        InputError: a direction that is not three finite numbers of non-zero length.
    """
    d = np.asarray(direction, np.float64).reshape(-1)
    if d.shape != (3,) or not np.isfinite(d).all() or np.linalg.norm(d) == 0:
        raise InputError(f"direction: expected three finite numbers, not all 0, found {np.asarray(direction)!r}")
    light = d / np.linalg.norm(d)
    n = np.asarray(maps.normals, np.float64)
    view = np.array([0.0, 0.0, 1.0])
    half = (light + view) / max(np.linalg.norm(light + view), 1e-12)
    nl, nv = np.maximum(n @ light, 0.0), np.maximum(n @ view, 0.0)
    nh, x = np.maximum(n @ half, 0.0), (1.0 - max(float(view @ half), 0.0)) ** 5
    dv = _ggx(nl, nv, nh, np.asarray(maps.roughness, np.float64))[..., None]
    c, metal = np.asarray(maps.base_color, np.float64), np.asarray(maps.metallic, np.float64)[..., None]
    f0 = 0.04 * np.asarray(maps.specular, np.float64)[..., None]
    fd = f0 + (1.0 - f0) * x
    f = (1.0 - metal) * ((1.0 - fd) * c / np.pi + fd * dv) + metal * (c + (1.0 - c) * x) * dv
    e = np.broadcast_to(np.asarray(irradiance, np.float64), (3,))
    image = maps.scale * e * nl[..., None] * f
    return np.where(np.asarray(maps.mask)[..., None] & (nl[..., None] > 0), image, 0.0)
