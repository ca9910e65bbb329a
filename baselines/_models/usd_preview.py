r"""UsdPreviewSurface, the USD specification's preview material (UsdPreviewSurface Specification, openusd.org,
"Preview Surface" inputs ``diffuseColor``, ``useSpecularWorkflow``, ``specularColor``, ``metallic``, ``roughness``,
``clearcoat``, ``clearcoatRoughness``, ``ior``), with the lobes of its reference implementation (Hydra Storm's
``usdImaging/plugin/usdShaders/shaders/previewSurface.glslfx``, ``evaluateLight``).

The BRDF of one colour channel, ``u`` the light, ``v`` the view (the GLSL's ``E``), ``h`` their half vector:

.. math::
    f = (1 - m)\,\frac{c_d}{\pi}\,\big(1 - F\big) + F\, D(r)\, V(r) + c\, F_c\, D(r_c)\, V(r_c),
    \qquad F = \mathrm{mix}(F_0, F_{90}, (1 - v\cdot h)^5),

- ``D``: GGX with ``alpha = r^2`` (the specification: roughness "is squared before use with a GGX lobe"),
  :math:`D = \alpha^2 / (\pi ((n\cdot h)^2 (\alpha^2 - 1) + 1)^2)`, ``r = max(roughness, 0.001)``;
- ``V``: the separable Schlick-Smith visibility of the reference, :math:`G / (4 (n\cdot l)(n\cdot v))` with
  :math:`G = \frac{n\cdot v}{(n\cdot v)(1 - k) + k}\frac{n\cdot l}{(n\cdot l)(1 - k) + k}`, ``k = alpha / 2``;
- specular workflow (``useSpecularWorkflow = 1``): ``F0 = specularColor``, ``F90 = 1``, ``m = 0`` (the
  specification: "the color at 0 incidence; edge color is assumed white");
- metallic workflow (0): with ``s = mix(1, diffuseColor, metallic)``, ``F0 = mix(R s, s, metallic)``,
  ``F90 = s``, :math:`R = ((1 - \mathrm{ior}) / (1 + \mathrm{ior}))^2` (the specification: at ``metallic = 1`` both
  F0 and F90 are the albedo, at 0 F0 comes from the IOR and F90 is white, interpolated between);
- clearcoat: amount ``c = clearcoat``, white, ``F_c = mix(R, 1, (1 - v.h)^5)``, roughness ``clearcoatRoughness``.

Two constants of the reference shader are a real-time renderer's shortcuts and are not taken: its ``PI = 3.1415``
(here pi) and its ``EPSILON = 0.001`` added to the GGX numerator and the ``4 n.l n.v`` denominator (here 0).
Reciprocal: ``D``, ``V`` are symmetric in ``u``, ``v`` and the Fresnel weights depend on ``v . h = u . h`` only.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .common import UNIT, BaselineModel, Geometry, LogBounded, grid, lobe, uniform_sampler
from .materials import material_writer

#: The inputs this model evaluates and their defaults in the specification.
DEFAULTS = {"diffuseColor": 0.18, "useSpecularWorkflow": 0, "specularColor": 0.0, "metallic": 0.0,
            "roughness": 0.5, "ior": 1.5, "clearcoat": 0.0, "clearcoatRoughness": 0.01}
COLORS = ("diffuseColor", "specularColor")


def _specular(g: Geometry, roughness):
    """``D(r) G / (4 n.l n.v)`` of the reference (``NormalDistribution``, ``Geometric``, ``evaluateDirectSpecular``)."""
    alpha = jnp.maximum(roughness, 0.001) ** 2
    a2 = alpha * alpha
    d = a2 / (np.pi * (g.nh * g.nh * (a2 - 1.0) + 1.0) ** 2)
    k = 0.5 * alpha
    return d / (4.0 * (g.cv * (1.0 - k) + k) * (g.cu * (1.0 - k) + k))


def usd_preview_surface(inputs: dict, u, v):
    """The UsdPreviewSurface BRDF (module docs) of one colour channel.

    Args:
        inputs: UsdPreviewSurface input names (:data:`DEFAULTS`) to values, colours as this channel's component;
            ``useSpecularWorkflow`` a Python 0 or 1; missing inputs take their defaults.
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; 0 unless both directions are above the horizon.
    """
    p = {**DEFAULTS, **inputs}
    g = Geometry(u, v)
    schlick = (1.0 - jnp.clip(g.vh, 0.0, 1.0)) ** 5
    r0 = ((1.0 - p["ior"]) / (1.0 + p["ior"])) ** 2
    diffuse = p["diffuseColor"] / np.pi
    if int(p["useSpecularWorkflow"]) == 1:
        f0, f90 = p["specularColor"], 1.0
    else:
        m = p["metallic"]
        s = 1.0 + (p["diffuseColor"] - 1.0) * m
        f0, f90, diffuse = r0 * s + (s - r0 * s) * m, s, diffuse * (1.0 - m)
    fresnel = f0 + (f90 - f0) * schlick
    f = diffuse * (1.0 - fresnel) + fresnel * _specular(g, p["roughness"])
    f = f + p["clearcoat"] * (r0 + (1.0 - r0) * schlick) * _specular(g, p["clearcoatRoughness"])
    return lobe(g, f)


def _make(name: str, fitted: tuple[str, ...], fixed: dict, transforms, guesses, sample):
    """The :class:`BaselineModel` fitting ``fitted`` (the other inputs at ``fixed`` or their defaults)."""

    def evaluate(params, u, v):
        return usd_preview_surface({**fixed, **{k: params[i] for i, k in enumerate(fitted)}}, u, v)

    return BaselineModel(
        name=name, param_names=fitted, transforms=transforms, evaluate=evaluate, n_linear=0, columns=_no_columns,
        guesses=guesses, sample=sample, reference="UsdPreviewSurface Specification; Hydra Storm previewSurface.glslfx",
        shared_across_channels=tuple(k for k in fitted if k not in COLORS),
        to_material=material_writer(name, fitted, fixed, DEFAULTS, _WRITTEN, COLORS),
    )


def _no_columns(nl, u, v):
    """No parameter enters linearly (the diffuse is scaled by ``1 - F`` of the specular colours)."""
    return jnp.zeros(jnp.shape(u)[:-1] + (0,), jnp.result_type(u, nl))


_WRITTEN = ("diffuseColor", "useSpecularWorkflow", "specularColor", "metallic", "roughness", "ior")
_ROUGH = LogBounded(1e-2, 1.0)
_IOR = LogBounded(1.001, 4.0)
_METAL_GUESS = grid([0.5], [0.05, 0.5, 0.95], [0.15, 0.4], [1.5])
_METAL_SAMPLE = [(0.05, 0.95, False), (0.02, 0.98, False), (0.05, 0.9, True), (1.2, 2.5, False)]

MODEL = _make("usd-preview", ("diffuseColor", "metallic", "roughness", "ior"), {"useSpecularWorkflow": 0},
              (UNIT, UNIT, _ROUGH, _IOR), _METAL_GUESS, uniform_sampler(_METAL_SAMPLE))
SPECULAR = _make(
    "usd-preview-specular", ("diffuseColor", "specularColor", "roughness"), {"useSpecularWorkflow": 1},
    (UNIT, UNIT, _ROUGH), grid([0.5], [0.04, 0.5], [0.15, 0.4]),
    uniform_sampler([(0.05, 0.95, False), (0.01, 0.95, False), (0.05, 0.9, True)]),
)
CLEARCOAT = _make(
    "usd-preview-clearcoat", ("diffuseColor", "metallic", "roughness", "ior", "clearcoat", "clearcoatRoughness"),
    {"useSpecularWorkflow": 0}, (UNIT, UNIT, _ROUGH, _IOR, UNIT, _ROUGH),
    np.concatenate([np.repeat(_METAL_GUESS, 2, 0), np.tile([[0.5, 0.05], [0.5, 0.2]], (len(_METAL_GUESS), 1))], 1),
    uniform_sampler(_METAL_SAMPLE + [(0.05, 0.95, False), (0.02, 0.5, True)]),
)
