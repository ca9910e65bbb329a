r"""glTF 2.0 metallic-roughness material (specification Appendix B), with ``KHR_materials_specular``,
``KHR_materials_ior`` and ``KHR_materials_anisotropy`` as registry variants.

Three records, one BRDF function:

- ``gltf-pbr``: ``baseColorFactor``, ``metallicFactor``, ``roughnessFactor`` (the core material);
- ``gltf-pbr-specular``: also ``specularFactor`` (``KHR_materials_specular``, ``specularColorFactor`` white) and
  ``ior`` (``KHR_materials_ior``);
- ``gltf-pbr-anisotropic``: also ``anisotropyStrength`` and ``anisotropyRotation`` (``KHR_materials_anisotropy``).

``specularColorFactor`` is held white: the extension's ``fresnel_mix`` weights the diffuse base by
``1 - specular max_value(fr)``, the maximum over the R, G, B channels, which a per-channel BRDF cannot evaluate
when the colour differs between channels; with a white colour ``fr`` is the same in every channel.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .common import UNIT, BaselineModel, Geometry, LogBounded, Transform, grid, lobe, uniform_sampler

#: roughness range: alpha = roughness^2 >= 1e-4 (the specification's note: never alpha = 0)
ROUGHNESS = LogBounded(1e-2, 1.0)
#: KHR_materials_ior: ior >= 1 (3 at most: the densest common dielectrics)
IOR = LogBounded(1.0, 3.0)
#: KHR_materials_anisotropy's rotation: radians, any real (periodic with period pi)
ROTATION = Transform("real")


def _microfacet(alpha, strength, rotation, g: Geometry):
    r"""``Vis * D`` of ``specular_brdf(alpha)``: Appendix B.3.2 ("Specular BRDF") for ``strength = 0``, the
    anisotropic GGX of ``KHR_materials_anisotropy`` ("Implementation") otherwise, with ``alpha_t = mix(alpha, 1,
    strength^2)`` along the tangent ``t = (cos rotation, sin rotation, 0)``, ``alpha_b = alpha``:

    .. math::
        D = \frac{a^2 w^4}{\pi},\; a^2 = \alpha_t \alpha_b,\; w^2 = \frac{a^2}{|(\alpha_b\, t\cdot h,\, \alpha_t\, b
        \cdot h,\, a^2\, n\cdot h)|^2},\quad
        V = \frac{1/2}{n\cdot u\, |(\alpha_t\, t\cdot v, \alpha_b\, b\cdot v, n\cdot v)|
            + n\cdot v\, |(\alpha_t\, t\cdot u, \alpha_b\, b\cdot u, n\cdot u)|}

    (for ``alpha_t = alpha_b`` the height-correlated Smith visibility and GGX ``D`` of Appendix B.3.2).
    """
    at = alpha + (1.0 - alpha) * strength * strength
    ab = alpha
    c, s = jnp.cos(rotation), jnp.sin(rotation)

    def tb(w):
        return c * w[..., 0] + s * w[..., 1], -s * w[..., 0] + c * w[..., 1]

    th, bh = tb(g.h)
    a2 = at * ab
    w2 = a2 / ((ab * th) ** 2 + (at * bh) ** 2 + (a2 * g.nh) ** 2)
    d = a2 * w2 * w2 / jnp.pi
    tu, bu = tb(g.u)
    tv, bv = tb(g.v)
    ggxv = g.cu * jnp.sqrt((at * tv) ** 2 + (ab * bv) ** 2 + g.cv**2)
    ggxl = g.cv * jnp.sqrt((at * tu) ** 2 + (ab * bu) ** 2 + g.cu**2)
    return 0.5 / (ggxv + ggxl) * d


def gltf_brdf(base_color, metallic, roughness, u, v, specular=1.0, ior=1.5, strength=0.0, rotation=0.0):
    r"""The glTF 2.0 metallic-roughness BRDF of one colour channel (Appendix B.3.5, "Metal BRDF and Dielectric
    BRDF"), with ``KHR_materials_specular``'s ``fresnel_mix`` (white ``specularColorFactor``) and
    ``KHR_materials_ior``'s ``f0``:

    .. math::
        f = (1 - m)\,\big[(1 - s\,F_d)\,\tfrac{c}{\pi} + s\,F_d\,V D\big] + m\, F_m\, V D,\quad
        F_d = f_0 + (1 - f_0) w,\; f_0 = \big(\tfrac{1 - \eta}{1 + \eta}\big)^2,\;
        F_m = c + (1 - c) w,\; w = (1 - |v\cdot h|)^5,

    ``V D`` the microfacet term at ``alpha = roughness^2`` (:func:`_microfacet`).

    Args:
        base_color: ``baseColorFactor`` of this channel, in [0, 1].
        metallic, roughness: ``metallicFactor``, ``roughnessFactor`` in [0, 1].
        u, v: ``(..., 3)`` light and view directions (local frame, normal ``+z``).
        specular: ``specularFactor`` (1 without the extension); ior: ``ior`` (1.5 without the extension).
        strength, rotation: ``anisotropyStrength`` in [0, 1] and ``anisotropyRotation`` (radians).

    Returns:
        ``f`` with the shape of ``u[..., 0]``; 0 where a direction is below the horizon.
    """
    g = Geometry(u, v)
    w = (1.0 - g.vh) ** 5
    f0 = ((1.0 - ior) / (1.0 + ior)) ** 2
    f_d = f0 + (1.0 - f0) * w
    spec = _microfacet(roughness * roughness, strength, rotation, g)
    dielectric = (1.0 - specular * f_d) * base_color / jnp.pi + specular * f_d * spec
    metal = (base_color + (1.0 - base_color) * w) * spec
    return lobe(g, (1.0 - metallic) * dielectric + metallic * metal)


def gltf_pbr(params, u, v):
    """``gltf-pbr``: ``params = (baseColorFactor, metallicFactor, roughnessFactor)`` of one channel
    (:func:`gltf_brdf`)."""
    return gltf_brdf(params[0], params[1], params[2], u, v)


def gltf_pbr_specular(params, u, v):
    """``gltf-pbr-specular``: ``(baseColorFactor, metallicFactor, roughnessFactor, specularFactor, ior)``."""
    return gltf_brdf(params[0], params[1], params[2], u, v, specular=params[3], ior=params[4])


def gltf_pbr_anisotropic(params, u, v):
    """``gltf-pbr-anisotropic``: ``(baseColorFactor, metallicFactor, roughnessFactor, anisotropyStrength,
    anisotropyRotation)``."""
    return gltf_brdf(params[0], params[1], params[2], u, v, strength=params[3], rotation=params[4])


def _material(name: str, names: tuple[str, ...], extra: dict):
    """``to_material(params (3, P))``: the glTF names of the constrained parameters (colour per channel)."""

    def to_material(params) -> dict:
        p = np.asarray(params, float)
        out = {"model": name, "baseColorFactor": [float(x) for x in p[:, 0]]}
        for i, n in enumerate(names[1:], start=1):
            out[n] = float(np.mod(p[0, i], np.pi)) if n == "anisotropyRotation" else float(p[0, i])
        return dict(out, **extra)

    return to_material


_CORE = ("baseColorFactor", "metallicFactor", "roughnessFactor")
_GUESSES = grid([0.5], [0.0, 1.0], [0.1, 0.3, 0.6])


def _record(name, names, transforms, evaluate, guesses, bounds, extra=None):
    return BaselineModel(
        name=name, param_names=names, transforms=transforms, evaluate=evaluate, n_linear=0, columns=None,
        guesses=guesses, sample=uniform_sampler(bounds), shared_across_channels=names[1:],
        to_material=_material(name, names, extra or {}),
        reference="glTF 2.0 specification, Appendix B; KHR_materials_specular, _ior, _anisotropy",
        anisotropic="anisotropyRotation" in names,
    )


_BOUNDS = [(0.05, 0.95, False), (0.0, 1.0, False), (0.03, 1.0, True)]
MODEL = _record("gltf-pbr", _CORE, (UNIT, UNIT, ROUGHNESS), gltf_pbr, _GUESSES, _BOUNDS)
SPECULAR = _record(
    "gltf-pbr-specular", _CORE + ("specularFactor", "ior"), (UNIT, UNIT, ROUGHNESS, UNIT, IOR), gltf_pbr_specular,
    np.concatenate([_GUESSES, np.tile([[1.0, 1.5]], (len(_GUESSES), 1))], 1),
    _BOUNDS + [(0.1, 1.0, False), (1.1, 2.5, False)], {"specularColorFactor": [1.0, 1.0, 1.0]},
)
_ANISO_GUESSES = np.asarray(
    [[0.5, m, r, 0.3, 0.0] for m in (0.0, 1.0) for r in (0.1, 0.3)]
    + [[0.5, m, 0.2, 0.5, 0.5 * np.pi] for m in (0.0, 1.0)]
)
ANISOTROPIC = _record(
    "gltf-pbr-anisotropic", _CORE + ("anisotropyStrength", "anisotropyRotation"),
    (UNIT, UNIT, ROUGHNESS, UNIT, ROTATION), gltf_pbr_anisotropic, _ANISO_GUESSES,
    _BOUNDS + [(0.05, 0.9, False), (0.0, np.pi, False)],
)
