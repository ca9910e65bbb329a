r"""Mitsuba 3's ``roughplastic`` BSDF (``src/bsdfs/roughplastic.cpp``, GGX, ``nonlinear = false``, ``ext_ior = 1``,
``specular_reflectance = 1``) as a standard material model: ``roughplastic``.

Parameters of one channel: ``diffuse_reflectance`` (per channel), ``alpha`` and ``int_ior`` (shared by R, G, B).

Mitsuba's diffuse term is ``rho / (1 - R_i) / (pi eta^2) T(cos theta_u) T(cos theta_v)``, with the rough
interface's transmittance ``T`` tabulated at 64 cosines (``eval_transmittance``, Gauss-Legendre 32 x 32) and
linearly interpolated, and its internal diffuse reflectance ``R_i = 2 mean_mu(mu R(mu; 1 / eta))``
(``eval_reflectance``, 128 x 128 nodes) computed when the plugin loads. ``T`` is evaluated here as Mitsuba computes
it (:mod:`baselines._models.mi_microfacet`). ``R_i`` by the same rule at 32 x 32 nodes (a quarter of the cost: the fit
evaluates it at every step of every start), which differs from Mitsuba's 128 x 128 value by up to 2e-3 (0.4 %
of ``1 - R_i`` at ``eta = 1.5``, 1.4 % at 2.5); the material :func:`to_material` writes therefore carries
``diffuse_reflectance = rho (1 - R_i^{128}) / (1 - R_i^{32})``, with which Mitsuba's plugin evaluates to this model
(to float32 rounding). The model's ``rho`` is that of Mitsuba's plugin to that factor.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from .common import UNIT, BaselineModel, Geometry, LogBounded, grid, lobe, uniform_sampler
from .mi_microfacet import eval_reflectance, eval_transmittance, fresnel_dielectric, ndf, smith_g1

ALPHA = LogBounded(2e-3, 1.0)
IOR = LogBounded(1.05, 3.0)
#: Mitsuba's MI_ROUGH_TRANSMITTANCE_RES: the cosines ``max(1e-6, i / 63)`` of its transmittance table
RES = 64


def _mu(dtype=float):
    return jnp.maximum(jnp.linspace(0.0, 1.0, RES, dtype=dtype), 1e-6)


def transmittance_table(alpha, eta):
    """Mitsuba's ``m_external_transmittance``: ``T`` at the 64 table cosines, ``1 - (rough reflectance + loss)``."""
    return eval_transmittance(_mu(jnp.result_type(alpha, float)), alpha, eta, 32)


def internal_reflectance(alpha, eta, res: int = 32):
    """``m_internal_reflectance = 2 mean_mu(mu R(mu; 1 / eta))`` with ``res x res`` nodes (Mitsuba: 128)."""
    mu = _mu(jnp.result_type(alpha, float))
    return 2.0 * jnp.mean(eval_reflectance(mu, alpha, 1.0 / eta, res) * mu)


def _tables(alpha, eta):
    return transmittance_table(alpha, eta), internal_reflectance(alpha, eta)


@jax.custom_jvp
def tables(alpha, eta):
    """``(T (64,), R_i)`` of :func:`transmittance_table` and :func:`internal_reflectance` (32 x 32 nodes).

    Their derivative is the ``(65, 2)`` Jacobian w.r.t. ``(alpha, eta)`` times the tangent: computed once from the
    primal point, not once per tangent direction (a fit's Jacobian has a direction per parameter, and the colours'
    directions do not enter the tables)."""
    return _tables(alpha, eta)


@tables.defjvp
def _tables_jvp(primals, tangents):
    alpha, eta = primals
    primal, linear = jax.linearize(_tables, alpha, eta)
    one, zero = jnp.ones_like(alpha), jnp.zeros_like(alpha)
    ja, je = linear(one, zero), linear(zero, one)
    da, de = tangents
    return primal, jax.tree_util.tree_map(lambda x, y: x * da + y * de, ja, je)


def _lerp(table, mu):
    """Mitsuba's ``lerp_gather`` of the 64-entry table at ``mu`` in [0, 1]."""
    x = mu * (RES - 1)
    i = jnp.clip(jnp.floor(x).astype(jnp.int32), 0, RES - 2)
    return table[i] + (table[i + 1] - table[i]) * (x - i)


def _lobes(alpha, eta, u, v):
    """``(g, specular, diffuse per unit rho)`` of :func:`roughplastic_brdf` (neither masked to the horizon)."""
    g = Geometry(u, v)
    d = ndf(g.nh, alpha, False)
    gg = smith_g1(g.v, g.h, alpha, False) * smith_g1(g.u, g.h, alpha, False)
    spec = fresnel_dielectric(g.vh, eta)[0] * d * gg / (4.0 * g.cu * g.cv)
    table, r_i = tables(alpha, eta)
    t = _lerp(table, jnp.minimum(g.cu, 1.0)) * _lerp(table, jnp.minimum(g.cv, 1.0))
    return g, spec, t / ((1.0 - r_i) * jnp.pi * eta * eta)


def roughplastic_brdf(rho, alpha, eta, u, v):
    r"""The ``roughplastic`` BRDF of one channel (Mitsuba's ``eval`` divided by ``cos theta_u``):

    .. math:: f = \frac{F(v\cdot h, \eta)\, D(h)\, G_1(v, h) G_1(u, h)}{4 \cos\theta_u \cos\theta_v}
              + \frac{\rho}{(1 - R_i)\, \pi \eta^2}\, T(\cos\theta_u)\, T(\cos\theta_v)

    (see the module docs for ``T`` and ``R_i``); 0 where a direction is below the horizon.
    """
    g, spec, diffuse = _lobes(alpha, eta, u, v)
    return lobe(g, spec + rho * diffuse)


def roughplastic(params, u, v):
    """``roughplastic``: ``params = (diffuse_reflectance, alpha, int_ior)`` of one channel."""
    return roughplastic_brdf(params[0], params[1], params[2], u, v)


def roughplastic_rgb(params, u, v):
    """The three channels ``params (3, 3)`` (shared ``alpha``, ``int_ior``) at once: ``(3, ...)``, the lobes and
    tables computed once."""
    g, spec, diffuse = _lobes(params[0, 1], params[0, 2], u, v)
    rho = params[:, 0].reshape((3,) + (1,) * spec.ndim)
    return lobe(g, spec + rho * diffuse)


def to_material(params) -> dict:
    """Mitsuba's ``roughplastic`` dict of ``params (3, 3)``, its diffuse reflectance rescaled by
    ``(1 - R_i^{128}) / (1 - R_i^{32})`` (see the module docs; clipped to 1)."""
    p = np.asarray(params, float)
    alpha, eta = float(p[0, 1]), float(p[0, 2])
    scale = (1.0 - float(internal_reflectance(alpha, eta, 128))) / (1.0 - float(internal_reflectance(alpha, eta)))
    return {"model": "roughplastic", "distribution": "ggx", "alpha": alpha,
            "diffuse_reflectance": [min(float(x) * scale, 1.0) for x in p[:, 0]], "int_ior": eta, "ext_ior": 1.0}


MODEL = BaselineModel(
    name="roughplastic", param_names=("diffuse_reflectance", "alpha", "int_ior"), transforms=(UNIT, ALPHA, IOR),
    evaluate=roughplastic, n_linear=0, columns=None, guesses=grid([0.5], [0.03, 0.1, 0.3], [1.5]),
    sample=uniform_sampler([(0.05, 0.95, False), (0.005, 1.0, True), (1.1, 2.5, False)]),
    shared_across_channels=("alpha", "int_ior"), to_material=to_material, evaluate_rgb=roughplastic_rgb,
    reference="Mitsuba 3 roughplastic plugin (Walter et al. 2007; Weidlich and Wilkie 2007)",
)
