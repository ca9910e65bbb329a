r"""A Mitsuba 3 BSDF plugin for polyjax models, written in Python with Dr.Jit (variants ``scalar_rgb`` and
``llvm_ad_rgb``; any RGB variant should work).

``bsdf = pj.export.mitsuba_bsdf(model)`` registers a plugin (default name ``"polyjax"``) and returns the
instance; ``mi.load_dict({"type": "polyjax"})`` then builds it inside scenes. Conventions: Mitsuba's local
``si.wi`` (towards the viewer) is polyjax's view ``v``, ``wo`` the light ``u``; ``eval`` returns
``f(u, v) cos theta_u`` (RGB), 0 unless both are above the surface (one-sided, glossy reflection).

- **Evaluation**: a polynomial model or a ``NeuralBRDF`` is the Dr.Jit print of the one program of
  :mod:`polyjax.export._expr` (the same arithmetic as the GLSL and numpy exports), so Mitsuba evaluates the model
  itself; any other model (baselines, ``TabulatedBRDF``, closures) is tabulated on the MERL grid
  (:func:`tabulate_merl`, 90 x 90 x 180 Rusinkiewicz bins) and looked up at the nearest bin centre, an
  approximation at MERL's resolution.
- **Sampling**: the tables of :class:`polyjax.render.ImportanceSampler` (same map, mixture and density as
  polyjax's own sampler, :mod:`polyjax.render._sampling`), so ``pdf`` is exactly the density ``sample`` draws
  from: ``sample1`` chooses the cosine component (probability ``alpha``), then is rescaled to choose the view
  node and the cell (a per-lane binary search over the cell CDF); ``sample2`` places the point in the cell.

Mitsuba is an optional dependency (``pip install mitsuba``); a variant must be set (``mi.set_variant``) before
calling. Not differentiable w.r.t. the model from Mitsuba (its parameters are baked in as constants).
"""

from __future__ import annotations

import numpy as np

from .._errors import InputError
from .._model import PolynomialBRDF
from ..render._brdf import rgb_brdf
from ..render._sampling import ImportanceSampler, importance_sampler
from ._expr import program


def _mitsuba():
    try:
        import drjit as dr
        import mitsuba as mi
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise InputError("mitsuba_bsdf: the optional package 'mitsuba' is not installed (pip install mitsuba)") from e
    if mi.variant() is None:
        raise InputError("mitsuba_bsdf: no Mitsuba variant is set; call mitsuba.set_variant('llvm_ad_rgb') "
                         "(or 'scalar_rgb') first")
    if "rgb" not in mi.variant():
        raise InputError(f"mitsuba_bsdf: expected an RGB variant such as 'llvm_ad_rgb', found {mi.variant()!r}")
    return mi, dr


class _Table:
    """A float table usable from scalar and JIT variants: ``table[index]`` for Dr.Jit or Python indices."""

    def __init__(self, mi, dr, values):
        self.scalar = mi.Float is float
        self.np = np.ascontiguousarray(np.asarray(values, np.float64).ravel())
        self.mi, self.dr = mi, dr
        self.dr_array = None if self.scalar else mi.Float(self.np.astype(np.float32))

    def __getitem__(self, index):
        if self.scalar:
            return float(self.np[int(index)])
        return self.dr.gather(self.mi.Float, self.dr_array, index)


def _tabulated_eval(mi, dr, brdf):
    """Nearest-bin lookup in the MERL tabulation of ``brdf`` (Rusinkiewicz angles in Dr.Jit)."""
    from ..data._merl import MERL_RESOLUTION
    from ._merl import tabulate_merl

    nh, nd, npd = MERL_RESOLUTION
    vals, _ = tabulate_merl(brdf)
    tables = [_Table(mi, dr, np.maximum(np.asarray(c), 0.0)) for c in vals]

    def f(ux, uy, uz, vx, vy, vz):
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
        pd = dr.select(pd < 0, pd + dr.pi, pd)
        i = dr.clip(dr.floor(dr.sqrt(dr.maximum(th, 0.0) / (dr.pi / 2)) * nh + 1e-6), 0, nh - 1)
        j = dr.clip(dr.floor(td / (dr.pi / 2) * nd + 1e-6), 0, nd - 1)
        k = dr.clip(dr.floor(pd / dr.pi * npd + 1e-6), 0, npd - 1)
        if mi.Float is float:
            idx = int(k) + npd * (int(j) + nd * int(i))
        else:
            idx = mi.UInt32(k) + npd * (mi.UInt32(j) + nd * mi.UInt32(i))
        ok = (uz > 0) & (vz > 0)
        return tuple(dr.select(ok, t[idx], 0.0) for t in tables)

    return f


def _make_class(mi, dr, evaluate, sampler: ImportanceSampler):
    nv, n = sampler.n_views, sampler.resolution
    n2 = n * n
    pmf = _Table(mi, dr, sampler.pmf)
    cdf = _Table(mi, dr, sampler.cdf)
    alpha, theta_max = float(sampler.alpha), float(sampler.theta_max)
    steps = int(np.ceil(np.log2(n2))) + 1
    scalar = mi.Float is float
    to_uint = (lambda x: int(x)) if scalar else mi.UInt32

    def node(wi):
        theta = dr.acos(dr.clip(wi.z, -1.0, 1.0))
        s = dr.clip(theta / theta_max, 0.0, 1.0) * (nv - 1)
        j = dr.clip(dr.floor(s), 0, max(nv - 2, 0))
        t = dr.clip(s - j, 0.0, 1.0) if nv > 1 else 0.0 * s
        return j, t

    def azimuth(wi):
        r2 = wi.x * wi.x + wi.y * wi.y
        ok = r2 > 1e-20
        r = dr.sqrt(dr.select(ok, r2, 1.0))
        return dr.select(ok, wi.x / r, 1.0), dr.select(ok, wi.y / r, 0.0)

    def density(wi, wo):
        c, s = azimuth(wi)
        lx, ly = c * wo.x + s * wo.y, -s * wo.x + c * wo.y
        sq = mi.warp.uniform_hemisphere_to_square(mi.Vector3f(lx, ly, dr.maximum(wo.z, 0.0)))
        ix = dr.clip(dr.floor(sq.x * n), 0, n - 1)
        iy = dr.clip(dr.floor(sq.y * n), 0, n - 1)
        j, t = node(wi)
        j1 = dr.minimum(j + 1, nv - 1)
        cell = iy * n + ix
        p = (1.0 - t) * pmf[to_uint(j * n2 + cell)] + t * pmf[to_uint(j1 * n2 + cell)]
        tab = p * (n2 / (2.0 * dr.pi))
        pdf = alpha * dr.maximum(wo.z, 0.0) / dr.pi + (1.0 - alpha) * tab
        return dr.select((wo.z > 0) & (wi.z > 0), pdf, 0.0)

    def value(wi, wo):
        r, g, b = evaluate(wo.x, wo.y, wo.z, wi.x, wi.y, wi.z)
        cos = dr.maximum(wo.z, 0.0)
        ok = (wo.z > 0) & (wi.z > 0)
        return mi.Color3f(dr.select(ok, r * cos, 0.0), dr.select(ok, g * cos, 0.0), dr.select(ok, b * cos, 0.0))

    def search(base, x):
        """Per lane: the first cell of row ``base`` (offset ``base * n2``) whose CDF exceeds ``x``."""
        first = to_uint(base * n2)
        count = to_uint(0 * base + n2)
        for _ in range(steps):
            step = count // 2
            it = first + step
            go = (cdf[dr.minimum(it, to_uint(nv * n2 - 1))] <= x) & (count > 0)
            first = dr.select(go, it + 1, first)
            count = dr.select(go, count - step - 1, step)
        return dr.minimum(first - to_uint(base * n2), n2 - 1)

    class PolyjaxBSDF(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            flags = mi.BSDFFlags.GlossyReflection | mi.BSDFFlags.FrontSide
            self.m_components = [flags]
            self.m_flags = flags

        def sample(self, ctx, si, sample1, sample2, active=True):
            wi = si.wi
            use_cos = sample1 < alpha
            x = (sample1 - alpha) / (1.0 - alpha) if alpha < 1.0 else sample1
            j, t = node(wi)
            up = x < t
            x = dr.select(up, x / dr.maximum(t, 1e-12), (x - t) / dr.maximum(1.0 - t, 1e-12))
            jj = dr.select(up, dr.minimum(j + 1, nv - 1), j)
            cell = search(jj, dr.clip(x, 0.0, 1.0))
            cx, cy = cell % n, cell // n
            sq = mi.Point2f((cx + sample2.x) / n, (cy + sample2.y) / n)
            loc = mi.warp.square_to_uniform_hemisphere(sq)
            c, s = azimuth(wi)
            w_tab = mi.Vector3f(c * loc.x - s * loc.y, s * loc.x + c * loc.y, loc.z)
            w_cos = mi.warp.square_to_cosine_hemisphere(sample2)
            wo = dr.select(use_cos, w_cos, w_tab)
            pdf = density(wi, wo)
            bs = mi.BSDFSample3f()
            bs.wo = wo
            bs.pdf = pdf
            bs.eta = 1.0
            bs.sampled_component = mi.UInt32(0)
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            ok = (pdf > 0) & (wi.z > 0)
            weight = value(wi, wo) / dr.select(ok, pdf, 1.0)
            return bs, dr.select(ok, weight, mi.Color3f(0.0))

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
        name: the plugin name used in ``mi.load_dict({"type": name})`` and scene files.
        sampler_options: passed to :func:`polyjax.render.importance_sampler` (``resolution``, ``n_views``,
            ``alpha``, ...).
    """
    mi, dr = _mitsuba()
    from ..data._nbrdf import NeuralBRDF

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
    mi, _ = _mitsuba()
    register_mitsuba_bsdf(model, name, **sampler_options)
    return mi.load_dict({"type": str(name)})


__all__ = ["mitsuba_bsdf", "register_mitsuba_bsdf"]
