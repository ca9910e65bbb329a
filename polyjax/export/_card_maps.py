r"""glTF metallic-roughness maps of a capture fit (:func:`card_maps`): per texel, the glTF material closest to the
fit's BRDF ``rho_d / pi + sum_k m_k f_k``.

Each shared lobe ``f_k`` is first fitted by glTF's GGX lobe and a diffuse offset, ``a_k D V + b_k / pi``
(roughness ``r_k``, RGB amplitude ``a_k``, offset ``b_k``; :func:`polyjax.export.fit_ggx_lobes`), at the direction
pairs the capture saw (:func:`polyjax.export.capture_directions` of the fit's normals). Per texel:

- the diffuse albedo is ``rho_d + sum_k m_k b_k``, clipped at 0 (written ``rho_d`` below);
- the specular reflectance at normal incidence is ``s = sum_k m_k a_k`` (RGB), its grey value ``s_g`` the mean over
  channels;
- the roughness is the lobes' roughness weighted by their share of it, ``r = sum_k m_k a_{k,g} r_k / s_g`` (1 where
  the texel has no specular lobe);
- glTF's ``F0 = 0.04 (1 - M) + c M`` and diffuse colour ``(1 - M) c`` must give ``s_g`` and the diffuse albedo
  ``rho_g`` (grey): ``t = 1 - M`` solves ``0.04 t^2 - (s_g + rho_g) t + rho_g = 0`` (the root in ``[0, 1]``;
  ``M = 0`` when ``s_g <= 0.04``: core glTF has no weaker dielectric specular);
- a dielectric's specular weight ``k = min(1, s_g / 0.04)`` (``KHR_materials_specular``'s specular colour, glTF's
  ``F0 = 0.04 k``: a fitted specular weaker than core glTF's 0.04), 1 for metals;
- the base colour ``c`` (RGB) is the least-squares solution of ``(1 - M) c = rho_d`` and ``M c = s - 0.04 (1 - M)``
  (a metal's specular colour), clipped to ``[0, 1]``.

The radiometric scale: a capture's albedo is in camera units, which may exceed 1; ``rho_d`` and ``s`` are first
divided by ``scale = max(1, the 99.9th percentile over the mask's texels and channels of rho_d + s)`` (a percentile,
not the maximum: one badly conditioned texel must not darken the whole card; the brightest 0.1% clip), and a
renderer reproduces the photographs with lights ``scale`` times the capture's (recorded in the card).
"""

from __future__ import annotations

import equinox as eqx
import numpy as np
from jaxtyping import Array, Bool, Float

from .._errors import InputError
from ._ggx import GGXLobes, capture_directions, fit_ggx_lobes


class CardMaps(eqx.Module):
    """The glTF maps of a capture fit (module notes), camera image order (row 0 at the top).

    Attributes:
        base_color: ``(H, W, 3)`` linear base colour in ``[0, 1]``.
        metallic: ``(H, W)`` in ``[0, 1]``.
        roughness: ``(H, W)`` glTF roughness in ``[0, 1]``.
        specular: ``(H, W)`` the dielectric's specular weight ``k`` in ``[0, 1]`` (F0 ``0.04 k``).
        mask: ``(H, W)`` the fit's mask (the card's alpha).
        normals: ``(H, W, 3)`` the fit's camera-frame normals.
        scale: the radiometric scale the colours were divided by.
        lobes: the :class:`~polyjax.export.GGXLobes` fitted to the shared lobes.
    """

    base_color: Float[Array, "h w 3"]
    metallic: Float[Array, "h w"]
    roughness: Float[Array, "h w"]
    specular: Float[Array, "h w"]
    mask: Bool[Array, "h w"]
    normals: Float[Array, "h w 3"]
    scale: float
    lobes: GGXLobes


def _fields(fit):
    """The contract's arrays of a capture fit, checked: normals, mask, diffuse ``(H, W, ...)``, mix ``(H, W, K)``."""
    for name in ("normals", "mask", "diffuse", "mix", "lobes"):
        if not hasattr(fit, name):
            raise InputError(f"fit: expected a capture fit (polyjax.CaptureFit) with .{name}, found "
                             f"{type(fit).__name__}")
    n, m = np.asarray(fit.normals, np.float64), np.asarray(fit.mask, bool)
    d, mix = np.asarray(fit.diffuse, np.float64), np.asarray(fit.mix, np.float64)
    hw = m.shape
    if m.ndim != 2 or n.shape != hw + (3,) or d.shape != hw + (3,) or mix.ndim != 3 or mix.shape[:2] != hw:
        raise InputError(f"fit: expected mask (H, W), normals and diffuse (H, W, 3), mix (H, W, K), found "
                         f"{m.shape}, {n.shape}, {d.shape}, {mix.shape}")
    d = np.where(m[..., None], np.nan_to_num(np.maximum(d, 0.0)), 0.0)
    mix = np.where(m[..., None], np.nan_to_num(np.maximum(mix, 0.0)), 0.0)
    return n, m, d, mix


def _metallic(s_g, rho_g):
    """``M`` of the module notes: the root ``t = 1 - M`` in ``[0, 1]`` of ``0.04 t^2 - (s + rho) t + rho = 0``."""
    b = s_g + rho_g
    t = (b - np.sqrt(np.maximum(b * b - 0.16 * rho_g, 0.0))) / 0.08
    t = np.where(b > 1e-12, t, 0.0)  # neither diffuse nor specular: a black metal
    return np.where(s_g <= 0.04, 0.0, np.clip(1.0 - t, 0.0, 1.0))


def card_maps(fit, *, lobes: GGXLobes | None = None) -> CardMaps:
    """The glTF metallic-roughness maps of a capture fit (module notes).

    Args:
        fit: a :class:`polyjax.CaptureFit` (or any object with its ``normals``, ``mask``, ``diffuse``, ``mix`` and
            ``lobes(u, v) -> (K, n, 3)``).
        lobes: the GGX fits of its lobes, if already made (default: :func:`~polyjax.export.fit_ggx_lobes`).

    Returns:
        A :class:`CardMaps`.

    Raises:
        InputError: ``fit`` lacks a field or its arrays disagree in shape; ``lobes`` has another number of lobes.
    """
    n, m, rho, mix = _fields(fit)
    g = fit_ggx_lobes(fit.lobes, directions=capture_directions(n, m, 8192)) if lobes is None else lobes
    a, r = np.asarray(g.amplitude, np.float64), np.asarray(g.roughness, np.float64)
    if a.shape != (mix.shape[-1], 3):
        raise InputError(f"lobes: expected {mix.shape[-1]} lobes (the fit's mix), found {a.shape[0]}")
    s = np.einsum("hwk,kc->hwc", mix, a)
    rho = np.where(m[..., None], np.maximum(rho + np.einsum("hwk,kc->hwc", mix, np.asarray(g.offset)), 0.0), 0.0)
    scale = float(max(1.0, np.percentile((rho + s)[m], 99.9))) if m.any() else 1.0
    rho, s = rho / scale, s / scale
    share = mix * a.mean(-1)
    rough = np.where(share.sum(-1) > 1e-12, (share @ r) / np.maximum(share.sum(-1), 1e-300), 1.0)
    metal = _metallic(s.mean(-1), rho.mean(-1))
    t = 1.0 - metal
    colour = (t[..., None] * rho + metal[..., None] * (s - 0.04 * t[..., None])) / np.maximum(
        t * t + metal * metal, 1e-12)[..., None]
    k = np.where(metal > 0, 1.0, np.clip(s.mean(-1) / 0.04, 0.0, 1.0))
    return CardMaps(np.clip(colour, 0.0, 1.0), metal, np.clip(rough, 0.0, 1.0), k, m, n, scale, g)
