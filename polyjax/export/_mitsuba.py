r"""A Mitsuba 3 BSDF plugin for polyjax models, written in Python with Dr.Jit (variants ``scalar_rgb`` and
``llvm_ad_rgb``; any RGB variant should work).

``bsdf = pj.export.mitsuba_bsdf(model)`` registers a plugin (default name ``"polyjax"``) and returns the
instance; ``mi.load_dict({"type": "polyjax"})`` then builds it inside scenes. Conventions: Mitsuba's local
``si.wi`` (towards the viewer) is polyjax's view ``v``, ``wo`` the light ``u``; ``eval`` returns
``max(f(u, v), 0) cos theta_u`` (RGB), 0 unless both are above the surface (one-sided, glossy reflection).

- **Evaluation**: a polynomial model or a ``NeuralBRDF`` is the Dr.Jit print of the one program of
  :mod:`polyjax.export._expr` (the same arithmetic as the GLSL and numpy exports), so Mitsuba evaluates the model
  itself; any other model (baselines, ``TabulatedBRDF``, closures) is tabulated at the nodes of the MERL grid
  (:func:`tabulate_merl`, 90 x 90 x 180 Rusinkiewicz bins; 360 bins of ``phi_d`` over the whole turn for a model
  that is not reciprocal, :func:`polyjax.export._merl.whole_turn`) and interpolated trilinearly in the bin
  coordinates (``sqrt`` of ``theta_h``, ``theta_d``, ``phi_d`` periodic), nodes with a direction below the horizon
  left out of the weights: continuous, an approximation at MERL's resolution.
- **Sampling**: the tables of :class:`polyjax.render.ImportanceSampler` (same map, mixture and density as
  polyjax's own sampler, :mod:`polyjax.render._sampling`), so ``pdf`` is exactly the density ``sample`` draws
  from, up to float32: ``sample1`` chooses the cosine component (probability ``alpha``), then is rescaled to
  choose the view node; ``sample2`` draws the point of the square by the same inversion (``y`` from the
  marginal, ``x`` from the conditional, a per-lane binary search and a quadratic solve each).

Mitsuba is an optional dependency (``pip install mitsuba``); a variant must be set (``mi.set_variant``) before
calling. Not differentiable w.r.t. the model from Mitsuba (its parameters are baked in as constants).
"""

from __future__ import annotations

import numpy as np

from .._errors import InputError
from .._model import PolynomialBRDF
from ..data._merl import MERL_RESOLUTION
from ..data._nbrdf import NeuralBRDF
from ..render._brdf import rgb_brdf
from ..render._sampling import ImportanceSampler, importance_sampler
from ._expr import program
from ._merl import tabulate_both_orders
from ._mitsuba_name import check_plugin_name


def _mitsuba():
    try:
        import drjit as dr  # optional (the "mitsuba" extra): imported where used
        import mitsuba as mi  # optional (the "mitsuba" extra)
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise InputError("mitsuba_bsdf: the optional package 'mitsuba' is not installed (pip install mitsuba)") from e
    if mi.variant() is None:
        raise InputError("mitsuba_bsdf: no Mitsuba variant is set; call mitsuba.set_variant('llvm_ad_rgb') "
                         "(or 'scalar_rgb') first")
    if "rgb" not in mi.variant():
        raise InputError(f"mitsuba_bsdf: expected an RGB variant such as 'llvm_ad_rgb', found {mi.variant()!r}")
    return mi, dr


class _Table:
    """A float table usable from scalar and JIT variants: ``table[index]`` for Dr.Jit or Python indices, or for
    floats holding whole numbers (converted to ``UInt32``)."""

    def __init__(self, mi, dr, values):
        self.scalar = mi.Float is float
        self.np = np.ascontiguousarray(np.asarray(values, np.float64).ravel())
        self.mi, self.dr = mi, dr
        self.dr_array = None if self.scalar else mi.Float(self.np.astype(np.float32))

    def __getitem__(self, index):
        if self.scalar:
            return float(self.np[int(index)])
        if not isinstance(index, self.mi.UInt32):
            index = self.mi.UInt32(index)
        return self.dr.gather(self.mi.Float, self.dr_array, index)


# --------------------------------------------------------------------------- evaluation of tabulated models


def _rusinkiewicz(dr, ux, uy, uz, vx, vy, vz, period):
    """``(theta_h, theta_d, phi_d)`` of light ``u`` and view ``v`` in Dr.Jit, ``phi_d`` in ``[0, period)``:
    ``pi`` folds it by reciprocity (the MERL convention: ``f`` is symmetric under ``phi_d -> phi_d + pi``),
    ``2 pi`` keeps the whole turn (a table of a model that is not reciprocal)."""
    hx, hy, hz = ux + vx, uy + vy, uz + vz
    inv = dr.rsqrt(dr.maximum(hx * hx + hy * hy + hz * hz, 1e-30))
    hx, hy, hz = hx * inv, hy * inv, hz * inv
    th = dr.acos(dr.clip(hz, -1.0, 1.0))
    rh = dr.sqrt(dr.maximum(hx * hx + hy * hy, 0.0))
    safe = dr.select(rh > 1e-12, rh, 1.0)
    cp, sp = dr.select(rh > 1e-12, hx / safe, 1.0), dr.select(rh > 1e-12, hy / safe, 0.0)
    x, y = cp * ux + sp * uy, -sp * ux + cp * uy
    ct, st = dr.cos(th), dr.sin(th)
    dx, dz = x * ct - uz * st, x * st + uz * ct
    td = dr.atan2(dr.sqrt(dx * dx + y * y), dz)
    pd = dr.atan2(y, dx)
    pd = dr.select(pd < 0, pd + period, pd)
    return th, td, pd


def _tabulated_eval(mi, dr, brdf):
    """Trilinear interpolation of the MERL tabulation of ``brdf`` (module docstring), in Dr.Jit.

    Node ``(i, j, k)`` sits at ``theta_h = (i / N_h)^2 pi / 2``, ``theta_d = j / N_d pi / 2``, ``phi_d = k / N_p
    pi`` (the bin angles of :func:`polyjax.data.merl_grid`), so the coordinates are ``sqrt(theta_h / (pi / 2))
    N_h``, ``theta_d / (pi / 2) N_d`` (both clamped to the grid) and ``phi_d / pi N_p`` (periodic; ``phi_d / (2 pi)
    2 N_p`` for a table over the whole turn, :func:`polyjax.export._merl.whole_turn`). The value is
    ``sum_c w_c m_c f_c / sum_c w_c m_c`` over the 8 corners, ``w`` the trilinear weights and ``m`` 1 where both
    directions of the node are above the horizon (``f`` is then ``max(f, 0)`` there) and 0 elsewhere.
    """
    vals, above, turn = tabulate_both_orders(brdf, MERL_RESOLUTION)
    nh, nd, npd = above.shape
    period = 2.0 * np.pi if turn else np.pi
    vals = np.where(above[None], vals, 0.0).reshape(3, -1)
    tables = [_Table(mi, dr, c) for c in vals] + [_Table(mi, dr, above.reshape(-1).astype(np.float64))]

    def axis(c, n, periodic):
        c0 = dr.floor(c)
        w = c - c0
        if periodic:
            c0 = dr.select(c0 >= n, c0 - n, c0)
            return (c0, dr.select(c0 + 1 >= n, c0 + 1 - n, c0 + 1)), w
        c0 = dr.clip(c0, 0, n - 2)
        return (c0, c0 + 1), dr.clip(c - c0, 0.0, 1.0)

    def f(ux, uy, uz, vx, vy, vz):
        th, td, pd = _rusinkiewicz(dr, ux, uy, uz, vx, vy, vz, period)
        (i0, i1), wi = axis(dr.sqrt(dr.maximum(th, 0.0) / (dr.pi / 2)) * nh, nh, False)
        (j0, j1), wj = axis(dr.clip(td, 0.0, dr.pi / 2) / (dr.pi / 2) * nd, nd, False)
        (k0, k1), wk = axis(dr.clip(pd, 0.0, period) / period * npd, npd, True)
        acc = [0.0 * wi for _ in tables]
        for i, a in ((i0, 1.0 - wi), (i1, wi)):
            for j, b in ((j0, 1.0 - wj), (j1, wj)):
                for k, c in ((k0, 1.0 - wk), (k1, wk)):
                    idx = k + npd * (j + nd * i)
                    w = a * b * c
                    acc = [s + w * t[idx] for s, t in zip(acc, tables)]
        norm = acc[3]
        ok = (uz > 0) & (vz > 0) & (norm > 0)
        return tuple(dr.select(ok, s / dr.select(norm > 0, norm, 1.0), 0.0) for s in acc[:3])

    return f


# --------------------------------------------------------------------------- the sampler in Dr.Jit


def _last_at_most(dr, value_at, n: int, x):
    """Dr.Jit twin of ``polyjax.render._sampling._last_at_most`` (indices as whole-number floats)."""
    lo, hi = 0.0 * x, 0.0 * x + n
    for _ in range(int(np.ceil(np.log2(max(n, 1))))):
        mid = dr.floor((lo + hi) * 0.5)
        go = value_at(mid) <= x
        lo, hi = dr.select(go, mid, lo), dr.select(go, hi, mid)
    return lo


def _invert_linear(dr, d0, d1, t):
    """Dr.Jit twin of ``polyjax.render._sampling._invert_linear``."""
    den = d0 + dr.sqrt(dr.maximum(d0 * d0 + 2.0 * (d1 - d0) * t, 0.0))
    return dr.clip(dr.select(den > 0, 2.0 * t / dr.select(den > 0, den, 1.0), 0.0), 0.0, 1.0)


def _sampler_functions(mi, dr, sampler: ImportanceSampler):
    """``(node, density, draw)``: the view node and weight of ``wi``, the density of ``wo`` for ``wi``, and
    ``draw(jj, xi_y, xi_x)`` a point of the square from the table of node ``jj``; the methods of
    :class:`ImportanceSampler` on its tables, in Dr.Jit."""
    nv, n = sampler.n_views, sampler.resolution
    n1 = n + 1
    q, prefix, row_cdf = (_Table(mi, dr, a) for a in (sampler.density, sampler.prefix, sampler.row_cdf))
    alpha, theta_max = float(sampler.alpha), float(sampler.theta_max)

    def node(wi):
        s = dr.clip(dr.acos(dr.clip(wi.z, -1.0, 1.0)) / theta_max, 0.0, 1.0) * (nv - 1)
        j = dr.clip(dr.floor(s), 0, max(nv - 2, 0))
        return j, (dr.clip(s - j, 0.0, 1.0) if nv > 1 else 0.0 * s)

    def square_density(j, x, y):
        ix, iy = dr.clip(dr.floor(x * n), 0, n - 1), dr.clip(dr.floor(y * n), 0, n - 1)
        sx, sy = dr.clip(x * n - ix, 0.0, 1.0), dr.clip(y * n - iy, 0.0, 1.0)
        base = (j * n1 + iy) * n1 + ix
        lower = (1.0 - sx) * q[base] + sx * q[base + 1]
        upper = (1.0 - sx) * q[base + n1] + sx * q[base + n1 + 1]
        return (1.0 - sy) * lower + sy * upper

    def density(wi, wo):
        c, s = _azimuth(dr, wi)
        lx, ly = c * wo.x + s * wo.y, -s * wo.x + c * wo.y
        sq = mi.warp.uniform_hemisphere_to_square(mi.Vector3f(lx, ly, dr.maximum(wo.z, 0.0)))
        j, t = node(wi)
        j1 = dr.minimum(j + 1, nv - 1)
        tab = (1.0 - t) * square_density(j, sq.x, sq.y) + t * square_density(j1, sq.x, sq.y)
        pdf = alpha * dr.maximum(wo.z, 0.0) / dr.pi + (1.0 - alpha) / (2.0 * dr.pi) * tab
        return dr.select((wo.z > 0) & (wi.z > 0), pdf, 0.0)

    def draw(jj, xi_y, xi_x):
        target = xi_y * row_cdf[jj * n1 + n]
        a = _last_at_most(dr, lambda i: row_cdf[jj * n1 + i], n, target)
        row0, row1 = (jj * n1 + a) * n1, (jj * n1 + a + 1) * n1
        r0, r1 = prefix[row0 + n], prefix[row1 + n]
        sy = _invert_linear(dr, r0, r1, (target - row_cdf[jj * n1 + a]) * n)

        def blend(table, b):
            return (1.0 - sy) * table[row0 + b] + sy * table[row1 + b]

        target = xi_x * ((1.0 - sy) * r0 + sy * r1)
        b = _last_at_most(dr, lambda i: blend(prefix, i), n, target)
        sx = _invert_linear(dr, blend(q, b), blend(q, b + 1), (target - blend(prefix, b)) * n)
        return mi.Point2f((b + sx) / n, (a + sy) / n)

    return node, density, draw


def _azimuth(dr, wi):
    """``(cos phi, sin phi)`` of the view ``wi`` (``(1, 0)`` at the normal)."""
    r2 = wi.x * wi.x + wi.y * wi.y
    ok = r2 > 1e-20
    r = dr.sqrt(dr.select(ok, r2, 1.0))
    return dr.select(ok, wi.x / r, 1.0), dr.select(ok, wi.y / r, 0.0)


def _sample_direction(mi, dr, sampler: ImportanceSampler):
    """``wo = sample(wi, sample1, sample2)``: :meth:`ImportanceSampler.warp` with Mitsuba's uniforms (``sample1``
    picks the component, then, rescaled, the view node; ``sample2`` the point)."""
    node, _, draw = _sampler_functions(mi, dr, sampler)
    alpha, nv = float(sampler.alpha), sampler.n_views

    def sample(wi, sample1, sample2):
        x = (sample1 - alpha) / (1.0 - alpha) if alpha < 1.0 else sample1
        j, t = node(wi)
        up = x < t
        jj = dr.select(up, dr.minimum(j + 1, nv - 1), j)
        loc = mi.warp.square_to_uniform_hemisphere(draw(jj, sample2.y, sample2.x))
        c, s = _azimuth(dr, wi)
        w_tab = mi.Vector3f(c * loc.x - s * loc.y, s * loc.x + c * loc.y, loc.z)
        return dr.select(sample1 < alpha, mi.warp.square_to_cosine_hemisphere(sample2), w_tab)

    return sample


def _make_class(mi, dr, evaluate, sampler: ImportanceSampler):
    """The ``mi.BSDF`` subclass evaluating ``evaluate`` (six Dr.Jit coordinates to RGB) and sampling ``sampler``."""
    _, density, _ = _sampler_functions(mi, dr, sampler)
    draw = _sample_direction(mi, dr, sampler)

    def value(wi, wo):
        ok = (wo.z > 0) & (wi.z > 0)
        cos = dr.maximum(wo.z, 0.0)
        return mi.Color3f(*(dr.select(ok, c * cos, 0.0) for c in evaluate(wo.x, wo.y, wo.z, wi.x, wi.y, wi.z)))

    class PolyjaxBSDF(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            self.m_components = [flags]
            self.m_flags = flags

        def sample(self, ctx, si, sample1, sample2, active=True):
            wo = draw(si.wi, sample1, sample2)
            bs = mi.BSDFSample3f()
            bs.wo, bs.pdf, bs.eta = wo, density(si.wi, wo), 1.0
            bs.sampled_component = mi.UInt32(0)
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            ok = (bs.pdf > 0) & (si.wi.z > 0)
            return bs, dr.select(ok, value(si.wi, wo) / dr.select(ok, bs.pdf, 1.0), mi.Color3f(0.0))

        def eval(self, ctx, si, wo, active=True):
            return value(si.wi, wo)

        def pdf(self, ctx, si, wo, active=True):
            return density(si.wi, wo)

        def eval_pdf(self, ctx, si, wo, active=True):
            return value(si.wi, wo), density(si.wi, wo)

        def to_string(self):
            return "PolyjaxBSDF[]"

    return PolyjaxBSDF


def register_mitsuba_bsdf(model, name: str = "polyjax", **sampler_options) -> str:
    """Register ``model`` as the Mitsuba BSDF plugin ``name`` for the current variant; returns ``name``.

    Args:
        model: a :class:`polyjax.PolynomialBRDF` (batch ``()``, ``(1,)`` or ``(3,)``), or any BRDF callable
            polyjax evaluates (tabulated on the MERL grid, see the module docstring).
        name: the plugin name used in ``mi.load_dict({"type": name})`` and scene files: a Python identifier
            (else :class:`polyjax.InputError`).
        sampler_options: passed to :func:`polyjax.render.importance_sampler` (``resolution``, ``n_views``,
            ``alpha``, ...).
    """
    check_plugin_name(name)
    mi, dr = _mitsuba()

    if isinstance(model, (PolynomialBRDF, NeuralBRDF)):
        evaluate = program(model).python_function("drjit")
    else:
        evaluate = _tabulated_eval(mi, dr, rgb_brdf(model))
    sampler = importance_sampler(model, **sampler_options)
    cls = _make_class(mi, dr, evaluate, sampler)
    mi.register_bsdf(str(name), lambda props: cls(props))
    return str(name)


def mitsuba_bsdf(model, name: str = "polyjax", **sampler_options):
    """A Mitsuba 3 BSDF evaluating and sampling ``model`` (registered as plugin ``name``, see
    :func:`register_mitsuba_bsdf`): ``mi.load_dict({"type": "sphere", "bsdf": pj.export.mitsuba_bsdf(fit)})``."""
    check_plugin_name(name)
    mi, _ = _mitsuba()
    register_mitsuba_bsdf(model, name, **sampler_options)
    return mi.load_dict({"type": str(name)})


__all__ = ["mitsuba_bsdf", "register_mitsuba_bsdf"]
