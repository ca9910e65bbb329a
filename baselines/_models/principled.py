r"""The Disney principled BRDF as Mitsuba 3's ``principled`` plugin evaluates it (``src/bsdfs/principled.cpp``,
``principledhelpers.h``): its reflection lobes with ``spec_trans``, ``clearcoat``, ``sheen``, ``flatness`` and
``spec_tint`` at 0.

Two records: ``principled`` (``base_color``, ``roughness``, ``metallic``, ``specular``) and
``principled-anisotropic`` (also ``anisotropic``). ``spec_tint`` is held at 0: Mitsuba tints by ``base_color``
divided by its luminance, a mix of the R, G, B channels that a per-channel BRDF cannot evaluate.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .common import UNIT, BaselineModel, Geometry, LogBounded, grid, lobe, uniform_sampler

#: roughness range: Mitsuba clamps alpha = roughness^2 to at least 0.001, reached at roughness 0.0316
ROUGHNESS = LogBounded(0.032, 1.0)


def _fresnel_dielectric(cos_i, eta):
    """Unpolarised Fresnel reflectance of a dielectric of relative index ``eta >= 1`` seen from outside."""
    cos_t = jnp.sqrt(jnp.maximum(1.0 - (1.0 - cos_i * cos_i) / (eta * eta), 0.0))
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp)


def _ggx(roughness, anisotropic, g: Geometry):
    r"""Mitsuba's GGX ``D(h)`` and separable Smith ``G = G_1(u) G_1(v)`` with ``calc_dist_params``:
    ``alpha_x = max(0.001, r^2 / a)``, ``alpha_y = max(0.001, r^2 a)``, ``a = sqrt(1 - 0.9 anisotropic)``."""
    aspect = jnp.sqrt(1.0 - 0.9 * anisotropic)
    r2 = roughness * roughness
    ax, ay = jnp.maximum(0.001, r2 / aspect), jnp.maximum(0.001, r2 * aspect)
    h = g.h
    d = 1.0 / (jnp.pi * ax * ay * ((h[..., 0] / ax) ** 2 + (h[..., 1] / ay) ** 2 + g.nh**2) ** 2)

    def g1(w, c):
        return 2.0 / (1.0 + jnp.sqrt(1.0 + ((ax * w[..., 0]) ** 2 + (ay * w[..., 1]) ** 2) / (c * c)))

    return d, g1(g.u, g.cu) * g1(g.v, g.cv)


def principled_brdf(base_color, roughness, metallic, specular, u, v, anisotropic=0.0):
    r"""Mitsuba 3's ``principled`` BRDF of one colour channel (its ``eval`` divided by ``cos theta_u``):

    .. math::
        f = \frac{F\, D\, G}{4 \cos\theta_u \cos\theta_v}
          + (1 - m) \frac{c}{\pi} \Big[(1 - \tfrac{F_u}{2})(1 - \tfrac{F_v}{2})
          + R_r (F_u + F_v + F_u F_v (R_r - 1))\Big],

    ``F = m\, \mathrm{Schlick}(c, v\cdot h) + (1 - m) F_\mathrm{diel}(v\cdot h, \eta)`` (``principled_fresnel``),
    ``eta = 2 / (1 - sqrt(0.08 specular)) - 1``, ``F_x = (1 - \cos\theta_x)^5`` (``schlick_weight``),
    ``R_r = 2 r \cos^2\theta_d``; the specular lobe is 0 where ``F_diel = 0`` (``specular = 0``), as in Mitsuba.

    Args:
        base_color: ``base_color`` of this channel in [0, 1]; roughness, metallic, specular, anisotropic: the
            plugin's parameters of those names, in [0, 1].
        u, v: ``(..., 3)`` light and view directions (local frame, normal ``+z``, tangent ``+x``).

    Returns:
        ``f`` with the shape of ``u[..., 0]``; 0 where a direction is below the horizon.
    """
    g = Geometry(u, v)
    eta = 2.0 / (1.0 - jnp.sqrt(jnp.maximum(0.08 * specular, 1e-30))) - 1.0
    f_diel = _fresnel_dielectric(g.vh, eta)
    fresnel = metallic * (base_color + (1.0 - base_color) * (1.0 - g.vh) ** 5) + (1.0 - metallic) * f_diel
    d, gg = _ggx(roughness, anisotropic, g)
    spec = jnp.where(f_diel > 0, fresnel * d * gg / (4.0 * g.cu * g.cv), 0.0)
    fo, fi = (1.0 - g.cu) ** 5, (1.0 - g.cv) ** 5
    rr = 2.0 * roughness * g.vh**2
    diffuse = (1.0 - metallic) * base_color / jnp.pi * ((1.0 - 0.5 * fi) * (1.0 - 0.5 * fo)
                                                       + rr * (fo + fi + fo * fi * (rr - 1.0)))
    return lobe(g, spec + diffuse)


def principled(params, u, v):
    """``principled``: ``params = (base_color, roughness, metallic, specular)`` of one channel."""
    return principled_brdf(params[0], params[1], params[2], params[3], u, v)


def principled_anisotropic(params, u, v):
    """``principled-anisotropic``: ``(base_color, roughness, metallic, specular, anisotropic)``."""
    return principled_brdf(params[0], params[1], params[2], params[3], u, v, anisotropic=params[4])


def _material(name: str, names: tuple[str, ...]):
    def to_material(params) -> dict:
        p = np.asarray(params, float)
        out = {"model": "principled", "base_color": [float(x) for x in p[:, 0]]}
        out.update({n: float(p[0, i]) for i, n in enumerate(names[1:], start=1)})
        out.setdefault("anisotropic", 0.0)
        return dict(out, spec_tint=0.0)

    return to_material


def _record(name, names, transforms, evaluate, guesses, bounds):
    return BaselineModel(
        name=name, param_names=names, transforms=transforms, evaluate=evaluate, n_linear=0, columns=None,
        guesses=guesses, sample=uniform_sampler(bounds), shared_across_channels=names[1:],
        to_material=_material(name, names), reference="Burley 2012; Mitsuba 3 principled plugin",
        anisotropic="anisotropic" in names,
    )


_NAMES = ("base_color", "roughness", "metallic", "specular")
_BOUNDS = [(0.05, 0.95, False), (0.05, 1.0, True), (0.0, 1.0, False), (0.1, 1.0, False)]
MODEL = _record("principled", _NAMES, (UNIT, ROUGHNESS, UNIT, UNIT), principled,
                grid([0.5], [0.1, 0.3, 0.6], [0.0, 1.0], [0.5]), _BOUNDS)
ANISOTROPIC = _record(
    "principled-anisotropic", _NAMES + ("anisotropic",), (UNIT, ROUGHNESS, UNIT, UNIT, UNIT),
    principled_anisotropic, grid([0.5], [0.1, 0.3], [0.0, 1.0], [0.5], [0.0, 0.5]), _BOUNDS + [(0.0, 1.0, False)],
)
