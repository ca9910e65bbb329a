r"""OpenPBR Surface's opaque base, specular and coat lobes, as MaterialX 1.39 defines them (the node graph
``NG_open_pbr_surface_surfaceshader`` of ``libraries/bxdf/open_pbr_surface.mtlx``, OpenPBR 1.1, evaluated by its
GLSL closures, :mod:`baselines._models.mx_microfacet`).

The BRDF of one colour channel, ``u`` the light ``L`` and ``v`` the view ``V`` (normal ``+z``, tangent ``+x``):

.. math::
    f = f_c + T_c\, A\, B\, \big[(1 - m)\,(f_s + T_s f_d) + m\, f_m\big]

- ``f_d``: the diffuse base, ``base_weight`` times the energy-compensated Oren-Nayar (EON) of ``base_color`` and
  ``base_diffuse_roughness`` over pi (``oren_nayar_diffuse_bsdf``, ``energy_compensation = true``);
- ``f_s``: the dielectric specular (``dielectric_bsdf``, ``scatter_mode R``): GGX ``D`` with the roughness pair of
  ``open_pbr_anisotropy`` (:math:`a_x = r^2 \sqrt{2 / (1 + (1 - \mathrm{aniso})^2)}`, :math:`a_y = (1 - \mathrm{aniso})
  a_x`), the height-correlated Smith ``G2`` at :math:`\sqrt{a_x a_y}`, the dielectric Fresnel at ``v . h`` of the IOR
  that ``specular_weight`` modulates (the spec's ``specular_weight`` scales F0: :math:`\eta' = (1 + \epsilon) /
  (1 - \epsilon)`, :math:`\epsilon = \mathrm{sign}(\eta - 1) \sqrt{\mathrm{clamp}(w F_0(\eta), 0, 0.99999)}`), Turquin's
  energy compensation, tinted by ``specular_color``; ``T_s = 1 - E(n . v) comp`` is its albedo-scaling throughput
  (``layer``: base times top's throughput);
- ``f_m``: the metal, ``specular_weight`` times the same microfacet lobe with Hoffman's F82-tint Fresnel
  (``generalized_schlick_bsdf``: ``color0 = base_weight base_color``, ``color82 = specular_color``, ``color90 = 1``);
- with a coat: ``f_c`` the coat's dielectric lobe (weight ``coat_weight``, ``coat_ior``, ``coat_roughness``), ``T_c``
  its throughput, ``A = mix(1, coat_color, coat_weight)``, ``B`` the coat darkening
  ``mix(1, (1 - K) / (1 - E_base K), coat_weight coat_darkening)`` with :math:`K = 1 - (1 - F_0(\eta_c)) / \eta_c^2`,
  and the coat's effect on the layers below: the specular roughness
  ``mix(r, min(1, 2 r_c^4 + r^4)^{1/4}, coat_weight)`` and the IOR ratio ``mix(ior, ratio, coat_weight)`` (ratio
  ``ior / coat_ior``, inverted when below 1).

Not reciprocal: MaterialX takes Turquin's energy compensation at the *view* direction only and scales the layers
below a lobe by ``1 -`` the lobe's directional albedo at the view direction, so ``f(u, v) != f(v, u)`` (by up to a
few percent). Not exactly energy conserving either: white materials reach a directional albedo of 1.075 at oblique
views (the GLSL clamps ``l . v`` to ``>= 0`` in the EON lobe; the layering uses analytic albedo fits).
Transmission, subsurface, fuzz, thin film and emission are not modelled (their weights are 0 in the fitted
materials).

References: OpenPBR Surface specification 1.1 (Academy Software Foundation, 2024), sections "Base", "Specular",
"Coat"; MaterialX 1.39 ``open_pbr_surface`` and its GLSL implementation.
"""

from __future__ import annotations

import dataclasses

import jax.numpy as jnp
import numpy as np

from polyjax import half_vector

from . import mx_microfacet as mx
from .common import UNIT, BaselineModel, LogBounded, grid, lobe, uniform_sampler
from .materials import material_writer

#: The inputs this model evaluates and their defaults in ``ND_open_pbr_surface_surfaceshader``.
DEFAULTS = {
    "base_weight": 1.0, "base_color": 0.8, "base_diffuse_roughness": 0.0, "base_metalness": 0.0,
    "specular_weight": 1.0, "specular_color": 1.0, "specular_roughness": 0.3, "specular_ior": 1.5,
    "specular_roughness_anisotropy": 0.0, "coat_weight": 0.0, "coat_color": 1.0, "coat_roughness": 0.0,
    "coat_roughness_anisotropy": 0.0, "coat_ior": 1.6, "coat_darkening": 1.0,
}
#: The colour inputs (one value per channel); the others are scalars shared by the channels.
COLORS = ("base_color", "specular_color", "coat_color")


@dataclasses.dataclass
class _Dirs:
    nv: jnp.ndarray
    nl: jnp.ndarray
    vh: jnp.ndarray
    lv: jnp.ndarray
    h: jnp.ndarray
    above: jnp.ndarray


def _dirs(u, v) -> _Dirs:
    u, v = jnp.asarray(u), jnp.asarray(v)
    h = half_vector(u, v)
    return _Dirs(nv=mx.clamp_cos(v[..., 2]), nl=mx.clamp_cos(u[..., 2]), vh=mx.clamp_cos(jnp.sum(v * h, -1)),
                 lv=mx.clamp_cos(jnp.sum(u * v, -1)), h=h, above=(u[..., 2] > 0) & (v[..., 2] > 0))


def roughness_pair(roughness, anisotropy):
    """``NG_open_pbr_anisotropy`` then the closures' clamp to ``[eps, 1]``: ``(a_x, a_y)``."""
    inv = 1.0 - anisotropy
    ax = roughness * roughness * jnp.sqrt(2.0 / (1.0 + inv * inv))
    return jnp.clip(ax, mx.EPS, 1.0), jnp.clip(inv * ax, mx.EPS, 1.0)


def _microfacet(d: _Dirs, ax, ay, fresnel):
    """``D F G comp / (4 n.l n.v)`` and ``comp`` of a GGX lobe with Fresnel ``fresnel`` (at ``v . h``)."""
    alpha = jnp.sqrt(ax * ay)
    comp = mx.energy_compensation(d.nv, alpha, fresnel)
    return mx.ggx_ndf(d.h, ax, ay) * fresnel * mx.smith_g2_over_4(d.nl, d.nv, alpha) * comp, comp, alpha


def dielectric_lobe(d: _Dirs, ior, ax, ay, weight=1.0):
    """``mx_dielectric_bsdf`` in reflection: ``(f, throughput)``, untinted."""
    f, comp, alpha = _microfacet(d, ax, ay, mx.fresnel_dielectric(d.vh, ior))
    albedo = mx.ggx_dir_albedo(d.nv, alpha, mx.ior_to_f0(ior), 1.0) * comp
    return weight * f, 1.0 - albedo * weight


def _modulated_eta(eta, specular_weight):
    """OpenPBR's ``specular_weight`` as a modulation of the IOR (the graph's ``modulated_eta_s``)."""
    f0 = jnp.clip(specular_weight * mx.ior_to_f0(eta), 0.0, 0.99999)
    eps = jnp.sign(eta - 1.0) * jnp.sqrt(jnp.maximum(f0, 1e-30))
    return (1.0 + eps) / (1.0 - eps)


def _with_coat(p: dict):
    """The specular roughness and IOR the coat leaves to the layers below it (``effective_specular_roughness``,
    ``eta_s``)."""
    cw, r, ior = p["coat_weight"], p["specular_roughness"], p["specular_ior"]
    if _no_coat(cw):
        return r, ior
    covered = jnp.minimum(1.0, 2.0 * p["coat_roughness"] ** 4 + r**4) ** 0.25
    ratio = ior / p["coat_ior"]
    ratio = jnp.where(ratio > 1.0, ratio, 1.0 / ratio)
    return r + (covered - r) * cw, ior + (ratio - ior) * cw


def _no_coat(cw) -> bool:
    """A coat weight known to be 0 when traced (a Python number): the coat's closures are left out, as MaterialX's
    ``dielectric_bsdf`` returns at once for a weight below ``M_FLOAT_EPS``."""
    return isinstance(cw, (int, float)) and cw < mx.EPS


def _base_substrate(p: dict, d: _Dirs):
    """``base_substrate``: the metal / dielectric mix of the specular lobes over the diffuse base."""
    roughness, eta = _with_coat(p)
    ax, ay = roughness_pair(roughness, p["specular_roughness_anisotropy"])
    spec, through = dielectric_lobe(d, _modulated_eta(eta, p["specular_weight"]), ax, ay)
    diffuse = p["base_weight"] * mx.eon_diffuse(d.nv, d.nl, d.lv, p["base_diffuse_roughness"], p["base_color"]) / np.pi
    dielectric = p["specular_color"] * spec + through * diffuse
    f82 = mx.fresnel_f82(d.vh, p["base_weight"] * p["base_color"], p["specular_color"])
    metal = p["specular_weight"] * _microfacet(d, ax, ay, f82)[0]
    m = p["base_metalness"]
    return (1.0 - m) * dielectric + m * metal


def _coat(p: dict, d: _Dirs, base):
    """``coat_layer``: the coat lobe over the attenuated, darkened base (``coat_weight = 0``: ``base``)."""
    cw = p["coat_weight"]
    if _no_coat(cw):
        return base
    k = 1.0 - (1.0 - mx.ior_to_f0(p["coat_ior"])) / p["coat_ior"] ** 2
    e_base = p["base_color"] + (p["base_color"] * p["specular_weight"] - p["base_color"]) * p["base_metalness"]
    darkening = 1.0 + ((1.0 - k) / (1.0 - e_base * k) - 1.0) * cw * p["coat_darkening"]
    attenuation = 1.0 + (p["coat_color"] - 1.0) * cw
    ax, ay = roughness_pair(p["coat_roughness"], p["coat_roughness_anisotropy"])
    coat, through = dielectric_lobe(d, p["coat_ior"], ax, ay, cw)
    return jnp.where(cw > 0.0, coat, 0.0) + jnp.where(cw > 0.0, through, 1.0) * attenuation * darkening * base


def open_pbr_surface(inputs: dict, u, v):
    """The OpenPBR Surface BRDF (module docs) of one colour channel.

    Args:
        inputs: OpenPBR input names (:data:`DEFAULTS`) to values; colours as this channel's component; missing
            inputs take their defaults.
        u, v: ``(..., 3)`` light and view directions.

    Returns:
        ``f`` with the shape of ``u[..., 0]``; 0 unless both directions are above the horizon.
    """
    p = {**DEFAULTS, **inputs}
    d = _dirs(u, v)
    return lobe(d, _coat(p, d, _base_substrate(p, d)))


def _make(name: str, fitted: tuple[str, ...], fixed: dict, transforms, guesses, sample, anisotropic=False):
    """The :class:`BaselineModel` fitting ``fitted`` (the other inputs at ``fixed`` or their defaults)."""

    def evaluate(params, u, v):
        return open_pbr_surface({**fixed, **{k: params[i] for i, k in enumerate(fitted)}}, u, v)

    return BaselineModel(
        name=name, param_names=fitted, transforms=transforms, evaluate=evaluate, n_linear=0, columns=_no_columns,
        guesses=guesses, sample=sample, reference="OpenPBR Surface 1.1; MaterialX 1.39 open_pbr_surface",
        anisotropic=anisotropic, shared_across_channels=tuple(k for k in fitted if k not in COLORS),
        to_material=material_writer(name, fitted, fixed, DEFAULTS, _WRITTEN, COLORS),
    )


def _no_columns(nl, u, v):
    """No parameter enters linearly (the metal's F82 Fresnel and the EON lobe are nonlinear in the colours)."""
    return jnp.zeros(jnp.shape(u)[:-1] + (0,), jnp.result_type(u, nl))


#: What every exported material states (:func:`polyjax.export.materialx` needs them all).
_WRITTEN = ("base_weight", "base_color", "base_metalness", "base_diffuse_roughness", "specular_weight",
            "specular_color", "specular_roughness", "specular_ior", "specular_roughness_anisotropy")
_ROUGH = LogBounded(1e-2, 1.0)
_IOR = LogBounded(1.001, 4.0)
_BASE = ("base_color", "specular_color", "base_metalness", "specular_roughness", "specular_ior",
         "base_diffuse_roughness")
_BASE_T = (UNIT, UNIT, UNIT, _ROUGH, _IOR, UNIT)
_BASE_GUESS = grid([0.5], [0.9], [0.05, 0.5, 0.95], [0.15, 0.4], [1.5], [0.3])
_BASE_SAMPLE = [(0.05, 0.95, False), (0.3, 0.99, False), (0.02, 0.98, False), (0.05, 0.9, True),
                (1.2, 2.5, False), (0.0, 1.0, False)]

MODEL = _make("openpbr", _BASE, {}, _BASE_T, _BASE_GUESS, uniform_sampler(_BASE_SAMPLE))
ANISOTROPIC = _make(
    "openpbr-anisotropic", _BASE + ("specular_roughness_anisotropy",), {}, _BASE_T + (UNIT,),
    np.concatenate([np.repeat(_BASE_GUESS, 2, 0), np.tile([[0.0], [0.5]], (len(_BASE_GUESS), 1))], 1),
    uniform_sampler(_BASE_SAMPLE + [(0.0, 0.9, False)]), anisotropic=True,
)
COAT = _make(
    "openpbr-coat", _BASE + ("coat_roughness", "coat_ior"), {"coat_weight": 1.0, "coat_color": 1.0}, _BASE_T
    + (_ROUGH, _IOR), np.concatenate([np.repeat(_BASE_GUESS, 2, 0), np.tile([[0.05, 1.5], [0.3, 1.5]],
                                                                           (len(_BASE_GUESS), 1))], 1),
    uniform_sampler(_BASE_SAMPLE + [(0.02, 0.6, True), (1.2, 2.2, False)]),
)
