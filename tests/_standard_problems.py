"""Shared problems of the standard-material tests: known parameters of the OpenPBR and UsdPreviewSurface models, and
independent numpy implementations of their BRDFs written from the reference shader code (MaterialX 1.39's GLSL
closures ``mx_dielectric_bsdf``, ``mx_generalized_schlick_bsdf``, ``mx_oren_nayar_diffuse_bsdf`` and the
``open_pbr_surface`` node graph; Hydra Storm's ``previewSurface.glslfx`` ``evaluateLight``), vector by vector as the
GLSL computes them."""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

import baselines as bl

from _baseline_problems import synthetic_geometry

#: Known constrained parameters (inside the ranges, away from the limits), one colour channel.
STANDARD_PARAMS = {
    "openpbr": [0.5, 0.8, 0.3, 0.4, 1.6, 0.5],
    "openpbr-anisotropic": [0.5, 0.8, 0.3, 0.4, 1.6, 0.5, 0.4],
    "openpbr-coat": [0.5, 0.8, 0.3, 0.4, 1.6, 0.5, 0.2, 1.5],
    "usd-preview": [0.5, 0.3, 0.4, 1.6],
    "usd-preview-specular": [0.5, 0.2, 0.4],
    "usd-preview-clearcoat": [0.5, 0.3, 0.4, 1.6, 0.4, 0.15],
}
STANDARD_MODELS = tuple(STANDARD_PARAMS)


@functools.cache
def grey_fit(name: str):
    """``(u, v, values (3, n), fit)``: the fit of noise-free R, G, B data of the grey material
    ``STANDARD_PARAMS[name]`` (the same colour in the three channels), made once per process and model; every test
    file asks with the same shapes and options, so the fit's program is compiled once."""
    u, v = synthetic_geometry(300, seed=0)
    m = bl.get_model(name)
    y = m.evaluate(jnp.asarray(STANDARD_PARAMS[name]), u, v)
    values = jnp.stack([y, y, y])
    return u, v, values, bl.fit(name, u, v, values, n_starts=6, rtol=1e-10, atol=1e-12)

EPS = 1e-8
N = np.array([0.0, 0.0, 1.0])
X = np.array([1.0, 0.0, 0.0])


def _dot(a, b):
    return np.sum(a * b, -1)


def _normalize(a):
    return a / np.linalg.norm(a, axis=-1, keepdims=True)


def _ndf(ht, alpha):
    he = ht[..., :2] / alpha
    denom = _dot(he, he) + ht[..., 2] ** 2
    return 1.0 / (np.pi * alpha[0] * alpha[1] * denom**2)


def _g2(nl, nv, alpha):
    a2 = alpha**2
    ll = np.sqrt(a2 + (1 - a2) * nl**2)
    lv = np.sqrt(a2 + (1 - a2) * nv**2)
    return 2 * nl * nv / (ll * nv + lv * nl)


def _albedo(nv, alpha, f0, f90):
    x, y = nv, alpha
    r = [np.array(c) for c in ([0.1003, 0.9345, 1.0, 1.0], [-0.6303, -2.323, -1.765, 0.2281],
                               [9.748, 2.229, 8.263, 15.94], [-2.038, -3.748, 11.53, -55.83],
                               [29.34, 1.424, 28.96, 13.08], [-8.245, -0.7684, -7.507, 41.26],
                               [-26.44, 1.436, -36.11, 54.9], [19.99, 0.2913, 15.86, 300.2],
                               [-5.448, 0.6286, 33.37, -285.1])]
    x, y = x[..., None], np.asarray(y)[..., None]
    rr = (r[0] + r[1] * x + r[2] * y + r[3] * x * y + r[4] * x * x + r[5] * y * y + r[6] * x * x * y
          + r[7] * x * y * y + r[8] * x * x * y * y)
    ab = np.clip(rr[..., :2] / rr[..., 2:], 0, 1)
    return f0 * ab[..., 0] + f90 * ab[..., 1]


def _comp(nv, alpha, f):
    ess = _albedo(nv, alpha, 1.0, 1.0)
    return 1 + f * (1 - ess) / ess


def _fresnel_dielectric(c, ior):
    g2 = ior * ior + c * c - 1
    g = np.sqrt(np.maximum(g2, 0))
    f = 0.5 * ((g - c) / (g + c)) ** 2 * (1 + (((g + c) * c - 1) / ((g - c) * c + 1)) ** 2)
    return np.where(g2 < 0, 1.0, f)


def hoffman_fresnel(c, f0, f82, f90, e):
    """mx_fresnel_hoffman_schlick: Hoffman's generalised Schlick with the F82 tint."""
    cmax = 1 / 7
    factor = 1 / (cmax * (1 - cmax) ** 6)
    x = np.clip(c, 0, 1)
    a = (f0 * (1 - (1 - cmax) ** e) + f90 * (1 - cmax) ** e) * (1 - f82) * factor
    return f0 * (1 - (1 - x) ** e) + f90 * (1 - x) ** e - a * x * (1 - x) ** 6


def _frame(L, V):
    nv = np.clip(_dot(N, V), EPS, 1)
    nl = np.clip(_dot(N, L), EPS, 1)
    H = _normalize(L + V)
    vh = np.clip(_dot(V, H), EPS, 1)
    Y = np.cross(N, X)
    ht = np.stack([_dot(H, X), _dot(H, Y), _dot(H, N)], -1)
    return nv, nl, vh, ht


def _microfacet_closure(L, V, alpha, fresnel_at, f0, f90, weight):
    """The REFLECTION branch shared by mx_dielectric_bsdf and mx_generalized_schlick_bsdf: (response, dirAlbedo)."""
    nv, nl, vh, ht = _frame(L, V)
    alpha = np.clip(alpha, EPS, 1)
    avg = np.sqrt(alpha[0] * alpha[1])
    F = fresnel_at(vh)
    D = _ndf(ht, alpha)
    G = _g2(nl, nv, avg)
    comp = _comp(nv, avg, F)
    return D * F * G * comp * weight / (4 * nv), _albedo(nv, avg, f0, f90) * comp


def dielectric_bsdf(L, V, weight, tint, ior, alpha):
    """mx_dielectric_bsdf, scatter_mode R: (response, throughput)."""
    if weight < EPS:
        return 0.0, 1.0
    resp, alb = _microfacet_closure(L, V, alpha, lambda c: _fresnel_dielectric(c, ior), ((ior - 1) / (ior + 1)) ** 2,
                                    1.0, weight)
    return resp * max(tint, 0), 1 - alb * weight


def schlick_bsdf(L, V, weight, c0, c82, alpha):
    """mx_generalized_schlick_bsdf (color90 = 1, exponent 5): response (its throughput is not used by OpenPBR)."""
    if weight < EPS:
        return 0.0
    return _microfacet_closure(L, V, alpha, lambda c: hoffman_fresnel(c, max(c0, 0), max(c82, 0), 1.0, 5.0), c0, 1.0,
                               weight)[0]


def _fujii(c, r):
    a = 1 / (1 + (0.5 - 2 / (3 * np.pi)) * r)
    si = np.sqrt(np.maximum(0, 1 - c * c))
    g = si * (np.arccos(np.clip(c, -1, 1)) - si * c) + 2 * ((si / c) * (1 - si**3) - si) / 3
    return a + r * a * g / np.pi


def oren_nayar_bsdf(L, V, weight, color, r):
    """mx_oren_nayar_diffuse_bsdf with energy_compensation: response."""
    nv = np.clip(_dot(N, V), EPS, 1)
    nl = np.clip(_dot(N, L), EPS, 1)
    lv = np.clip(_dot(L, V), EPS, 1)
    s = lv - nl * nv
    stinv = np.where(s > 0, s / np.maximum(nl, nv), s)
    a = 1 / (1 + (0.5 - 2 / (3 * np.pi)) * r)
    single = color * a * (1 + r * stinv)
    avg = a * (1 + (2 / 3 - 28 / (15 * np.pi)) * r)
    cms = color**2 * avg / (1 - color * max(0, 1 - avg))
    multi = cms * np.maximum(EPS, 1 - _fujii(nv, r)) * np.maximum(EPS, 1 - _fujii(nl, r)) / max(EPS, 1 - avg)
    return (single + multi) * weight * nl / np.pi


def _aniso(r, aniso):
    inv = 1 - aniso
    ax = r * r * np.sqrt(2 / (1 + inv * inv))
    return np.array([ax, inv * ax])


def openpbr_reference(p: dict, L, V):
    """The open_pbr_surface graph (opaque, no fuzz, thin film, transmission or subsurface): the BRDF response / n.l."""
    cw = p.get("coat_weight", 0.0)
    cr, cior = p.get("coat_roughness", 0.0), p.get("coat_ior", 1.6)
    r, ior, sw = p["specular_roughness"], p["specular_ior"], p.get("specular_weight", 1.0)
    bw, bc, sc, m = p.get("base_weight", 1.0), p["base_color"], p["specular_color"], p["base_metalness"]
    r_eff = (1 - cw) * r + cw * min(1.0, 2 * cr**4 + r**4) ** 0.25
    alpha = _aniso(r_eff, p.get("specular_roughness_anisotropy", 0.0))
    ratio = ior / cior
    eta = (1 - cw) * ior + cw * (ratio if ratio > 1 else 1 / ratio)
    sf0 = np.clip(sw * ((eta - 1) / (eta + 1)) ** 2, 0, 0.99999)
    e = np.sign(eta - 1) * np.sqrt(sf0)
    spec, through = dielectric_bsdf(L, V, 1.0, sc, (1 + e) / (1 - e), alpha)
    dielectric_base = spec + oren_nayar_bsdf(L, V, bw, bc, p["base_diffuse_roughness"]) * through
    metal = schlick_bsdf(L, V, sw, bc * bw, sc, alpha)
    substrate = (1 - m) * dielectric_base + m * metal
    f0c = ((cior - 1) / (cior + 1)) ** 2
    k = 1 - (1 - f0c) / cior**2
    ebase = (1 - m) * bc + m * bc * sw
    darkening = (1 - cw * p.get("coat_darkening", 1.0)) + cw * p.get("coat_darkening", 1.0) * (1 - k) / (1 - ebase * k)
    attenuated = substrate * darkening * ((1 - cw) + cw * p.get("coat_color", 1.0))
    coat, coat_through = dielectric_bsdf(L, V, cw, 1.0, cior, _aniso(cr, p.get("coat_roughness_anisotropy", 0.0)))
    return (coat + attenuated * coat_through) / np.clip(_dot(N, L), EPS, 1)


def usd_preview_reference(p: dict, L, V, pi=np.pi, epsilon=0.0):
    """Storm's evaluateLight (specularAmount 1, occlusion 1, clearcoatColor 1): (d + s1 + s2) per unit n.l; ``pi``
    and ``epsilon`` are the shader's PI and EPSILON (3.1415 and 0.001 there)."""
    h = _normalize(L + V)
    nl, ne = np.maximum(0, _dot(N, L)), np.maximum(0, _dot(N, V))
    nh, eh = np.maximum(0, _dot(N, h)), np.maximum(0, _dot(V, h))

    def direct_specular(f0, f90, rough, fresnel):
        alpha = rough * rough
        a2 = alpha * alpha
        D = (a2 + epsilon) / (pi * ((nh * nh * (a2 - 1)) + 1) ** 2)
        k = alpha * 0.5
        G = ne / (ne * (1 - k) + k) * nl / (nl * (1 - k) + k)
        return (f0 + (f90 - f0) * fresnel) * G * D / (4 * nl * ne + epsilon)

    rough, ccr = max(0.001, p["roughness"]), max(0.001, p.get("clearcoatRoughness", 0.01))
    fresnel = np.maximum(0, 1 - eh) ** 5
    dc, ior, met = p["diffuseColor"], p.get("ior", 1.5), p.get("metallic", 0.0)
    d = dc * (1 / pi)
    R = (1 - ior) / (1 + ior)
    f0, f90 = p.get("specularColor", 0.0), 1.0
    if not p.get("useSpecularWorkflow", 0):
        spec_color = 1 + (dc - 1) * met
        f0, f90 = R * R * spec_color * (1 - met) + spec_color * met, spec_color
        d = d * (1 - met)
    s1 = direct_specular(f0, f90, rough, fresnel)
    d = d * (1 - (f0 + (f90 - f0) * fresnel))
    s2 = p.get("clearcoat", 0.0) * direct_specular(R * R, 1.0, ccr, fresnel) if p.get("clearcoat", 0.0) > 0 else 0
    return d + s1 + s2
