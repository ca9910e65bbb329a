r"""The renderer: plan the effects a scene needs, then trace only those.

Radiance leaving a visible surface point ``p`` towards the camera (direction ``v``) is

.. math::
    L(p, v) = \sum_{\text{lights}} f(u, v)\, E(u) \cos\theta_u\, V(p, u)
            + \int_{S^2} f(u, v)\, L_{env}(u) \cos^+\theta_u\, V(p, u)\, du + L_{indirect},

with ``f`` evaluated in the local shading frame of the object hit (:mod:`polyjax.render._scene`),
``E`` the irradiance of a directional light or ``I / r^2`` of a point light, ``V`` the visibility.
Each term is computed only if :func:`polyjax.render.plan_effects` says it exists:

- **direct_point** is closed form per pixel: one BRDF evaluation per light, no sampling.
- **shadows**: ``V`` is a shadow ray against every object; otherwise ``V = 1`` exactly (a lone
  convex sphere or a plane cannot occlude itself; ``cos^+`` does its self-shadowing).
- **environment**: Monte Carlo with ``spp`` samples per pixel, importance-sampled from the map
  (:class:`polyjax.render.EnvironmentLight`): a pool of samples is drawn once per render
  (:func:`polyjax.render.sample_pool`) and each pixel uses a hashed subset of it. With shadows,
  ``sum_s c_s V_s`` is computed as ``sum_s c_s - sum_s c_s (1 - V_s)`` (same samples).
- **indirect**: ``spp`` paths per pixel of ``max_bounces`` cosine-sampled bounces; at each
  secondary hit the direct terms above are added (the environment with one sample). Rays that
  leave the scene add nothing here (that light is the environment term).

Each effect is its own compiled stage (primary rays, point lights, environment, occlusion,
indirect, compositing), called only when the effect is on.

**Derivatives.** Every term is differentiable (``jax.grad``, ``jax.jvp``, ``vmap`` of them, under
``jit``) with respect to the BRDFs' parameters (polynomial coefficients, any BRDF module's arrays,
neural weights, tabulated values), light intensities, irradiances, positions and directions, and
environment-map texels; scenes can be built inside the differentiated function. Visibility
(``V``) is piecewise constant: a moving shadow edge has no derivative. Environment samples and
their densities are held fixed (drawn from the map's sampling tables): the derivative with respect
to a texel is that of the estimator, an unbiased estimate of the integral's derivative.

``force_all_effects=True`` computes every term whatever the scene (a black environment map when
there is none, shadow rays, one indirect bounce at least); on a scene where the extra terms
contribute nothing the pixels are identical: the shared terms come from the same compiled code
(stages, and optimisation barriers around each BRDF term), and the extra terms add exact zeros
or multiply by exact ones.
"""

from __future__ import annotations

import copy

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._arrays import cast_concrete
from .._errors import InputError
from ._brdf import evaluate_rgb
from ._envmap import EnvironmentLight, pool_indices
from ._sampling import cosine_pdf, cosine_sample, importance_sampler
from ._scene import DirectionalLight, Effects, NormalMap, Scene, Sphere, plan_effects

_ENV_KEY, _INDIRECT_KEY = 0x2545F491, 0x9E3779B9


def cast_floats(tree, dtype):
    """Cast every floating-point array leaf of a pytree (scene, BRDF) to ``dtype``."""
    return jax.tree.map(lambda x: cast_concrete(x, dtype) if eqx.is_inexact_array(x) else x, tree)


class RenderResult(eqx.Module):
    """What :func:`render` returns.

    Attributes:
        image: ``(H, W, 3)`` linear RGB radiance.
        hit: ``(H, W)`` True where a primary ray hit an object.
        effects: the :class:`Effects` that were computed.
        spp: samples per pixel used by the sampled effects (0 when nothing was sampled).
    """

    image: Float[Array, "h w 3"]
    hit: Bool[Array, "h w"]
    effects: Effects = eqx.field(static=True)
    spp: int = eqx.field(static=True)


# --------------------------------------------------------------------------- geometry


def _dot(a, b):
    """``a . b`` over the last axis of size 3, as explicit products and sums (a fixed evaluation
    order, whatever XLA fuses it with)."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def _eps(dtype) -> float:
    return 1e-4 if jnp.finfo(dtype).bits <= 32 else 1e-7


def _intersect(objects, o, d, tmin):
    """Nearest hit along rays: ``(t, index, hit)``; ``t = inf`` where nothing is hit beyond ``tmin``."""
    ts = []
    for obj in objects:
        if isinstance(obj, Sphere):
            oc = o - obj.center
            b = _dot(oc, d)
            c = _dot(oc, oc) - obj.radius**2
            disc = b * b - c
            sq = jnp.sqrt(jnp.maximum(disc, 0.0))
            t0, t1 = -b - sq, -b + sq
            t = jnp.where(t0 > tmin, t0, jnp.where(t1 > tmin, t1, jnp.inf))
            ts.append(jnp.where(disc >= 0, t, jnp.inf))
        elif isinstance(obj, NormalMap):  # no depth: only primary rays see it (_primary_rays)
            ts.append(jnp.full(o.shape[:-1], jnp.inf, o.dtype))
        else:
            denom = _dot(d, obj.normal)
            safe = jnp.where(denom != 0, denom, 1.0)
            t = (obj.offset - _dot(o, obj.normal)) / safe
            ts.append(jnp.where((denom != 0) & (t > tmin), t, jnp.inf))
    if len(ts) == 1:
        t = ts[0]
        idx = jnp.zeros(t.shape, jnp.int32)
    else:
        allt = jnp.stack(ts)
        idx = jnp.argmin(allt, axis=0).astype(jnp.int32)
        t = jnp.min(allt, axis=0)
    return t, idx, jnp.isfinite(t)


def _select(idx, values):
    out = values[0]
    for k in range(1, len(values)):
        out = jnp.where((idx == k)[..., None], values[k], out)
    return out


def _frame(objects, p, idx):
    """Shading frame ``(t, b, n)`` at points ``p`` of objects ``idx``."""
    ns, tans = [], []
    for obj in objects:
        if isinstance(obj, Sphere):
            n = (p - obj.center) / obj.radius
            tx = jnp.stack([n[..., 2], jnp.zeros_like(n[..., 0]), -n[..., 0]], -1)  # (0, 1, 0) x n
            tl = jnp.sqrt(jnp.sum(tx * tx, -1, keepdims=True))
            fallback = jnp.zeros_like(n).at[..., 0].set(1.0)
            ok = tl > 1e-6
            tx = jnp.where(ok, tx / jnp.where(ok, tl, 1.0), fallback)
            ns.append(n)
            tans.append(tx)
        elif isinstance(obj, NormalMap):  # per pixel: ``p`` holds the camera's pixels, row-major
            n = obj.normals.reshape(-1, 3).astype(p.dtype)
            tx = jnp.stack([n[..., 2], jnp.zeros_like(n[..., 0]), -n[..., 0]], -1)
            tl = jnp.sqrt(jnp.sum(tx * tx, -1, keepdims=True))
            ok = tl > 1e-6
            tx = jnp.where(ok, tx / jnp.where(ok, tl, 1.0), jnp.zeros_like(n).at[..., 0].set(1.0))
            ns.append(n)
            tans.append(tx)
        else:
            ns.append(jnp.broadcast_to(obj.normal, p.shape))
            tans.append(jnp.broadcast_to(obj.tangent, p.shape))
    n = _select(idx, ns)
    t = _select(idx, tans)
    return t, jnp.cross(n, t), n


def _to_local(frame, w):
    t, b, n = frame
    return jnp.stack([_dot(w, t), _dot(w, b), _dot(w, n)], -1)


def _object_brdf(objects, idx):
    """``f(u, v) -> (..., 3)`` of the object hit at each point (every object's BRDF, selected)."""

    def f(u, v):
        return _select(idx, [evaluate_rgb(obj.brdf, u, v) for obj in objects])

    return f


# --------------------------------------------------------------------------- lighting


def _visible(objects, p, n, l, dist):
    eps = _eps(p.dtype)
    t, _, _ = _intersect(objects, p + eps * n, l, eps)
    return (t >= dist - 2 * eps).astype(p.dtype)


_fence = jax.lax.optimization_barrier


def _hash(x):
    """A 32-bit integer mix (the "lowbias32" finaliser of C. Wellons): uint32 -> uint32."""
    x = jnp.asarray(x, jnp.uint32)
    x = x ^ (x >> 16)
    x = x * jnp.uint32(0x7FEB352D)
    x = x ^ (x >> 15)
    x = x * jnp.uint32(0x846CA68B)
    return x ^ (x >> 16)


def _unit(h, dtype):
    """A uint32 hash to a uniform number in ``[0, 1)`` (24 bits)."""
    return (h >> 8).astype(dtype) * (1.0 / (1 << 24))


def _pool_size(spp: int) -> int:
    return max(1 << 14, 1 << int(np.ceil(np.log2(16 * spp))))


def _pool_stride(n_pool: int) -> int:
    return int(0.6180339887 * n_pool) | 1


def _term(brdf, ul, vl, weight):
    """``brdf(ul, vl) * weight``, fenced by optimisation barriers (see :func:`_direct`)."""
    return _fence(brdf(ul, vl) * weight)


def _light_at(light, p, n):
    """A point or directional light seen from points ``p (N, 3)`` with normals ``n``: the world direction ``l`` to
    it, its distance (``inf`` for a directional light), ``cos+ theta_l`` and the RGB weight ``E cos+ theta_l``
    (``I cos+ theta_l / d^2`` for a point light) of its term ``f(u, v) * weight``."""
    if isinstance(light, DirectionalLight):
        l = jnp.broadcast_to(light.direction, p.shape)
        dist = jnp.full(p.shape[:-1], jnp.inf, p.dtype)
        cos = jnp.maximum(_dot(n, l), 0.0)
        return l, dist, cos, light.irradiance * cos[..., None]
    delta = light.position - p
    d2 = _dot(delta, delta)
    dist = jnp.sqrt(d2)
    l = delta / dist[..., None]
    cos = jnp.maximum(_dot(n, l), 0.0)
    return l, dist, cos, light.intensity * (cos / d2)[..., None]


def _pool_entry(pool, offset, s):
    """Environment sample ``s`` of the pixels whose pool offset is ``offset``: the pool entry
    ``(offset + s * stride) mod P`` (direction, ``L / pdf``)."""
    dirs, lps = pool
    n_pool = dirs.shape[0]
    k = ((offset + jnp.uint32(s) * jnp.uint32(_pool_stride(n_pool))) & jnp.uint32(n_pool - 1)).astype(jnp.int32)
    return dirs[k], lps[k]


def _direct(brdf, p, frame, vl, point_lights, pool, salt, pix, n_env, shadow_objects):
    """Direct lighting ``(N, 3)`` at points ``p`` (frame, local view ``vl``).

    ``shadow_objects`` is None when no shadow ray is needed; ``pool`` None when the environment
    effect is off, else ``(directions, L / pdf)`` of :func:`sample_pool`; ``n_env`` the
    environment samples per point: point ``i`` uses the pool entries
    ``(hash(pix_i, salt) + s * stride) mod P`` for ``s < n_env`` (distinct since the stride is odd
    and ``P`` a power of two).

    Every light's term ``f(u, v) * weight`` is computed between optimisation barriers, from
    inputs that also pass a barrier: XLA then cannot fuse or rewrite it differently depending on
    what else the program computes (visibility, other effects). The term is the same code in
    every program, and a render forced to compute every effect multiplies it by an exact 1 and
    adds exact 0s where those effects contribute nothing, so its pixels are bit-identical.
    """
    p, frame, vl = _fence((p, frame, vl))
    n = frame[2]
    acc = jnp.zeros(p.shape, p.dtype)
    for light in point_lights:
        l, dist, _, weight = _light_at(light, p, n)
        ul, l, weight, dist = _fence((_to_local(frame, l), l, weight, dist))
        c = _term(brdf, ul, vl, weight)
        if shadow_objects is not None:
            c = c * _visible(shadow_objects, p, n, l, dist)[..., None]
        acc = acc + c
    if pool is not None:
        acc = acc + _env_sum(brdf, p, frame, vl, pool, salt, pix, n_env, shadow_objects) / n_env
    return acc


def _env_sum(brdf, p, frame, vl, pool, salt, pix, n_env, shadow_objects, occluded_only=False):
    """Sum over ``n_env`` pooled environment samples of ``f(u, v) L cos / pdf`` (times ``V`` when
    ``shadow_objects`` is given; times ``1 - V`` when ``occluded_only``)."""
    n = frame[2]
    inf = jnp.full(p.shape[:-1], jnp.inf, p.dtype)
    offset = _hash(pix ^ _hash(jnp.asarray(salt, jnp.uint32)))

    def one(s, a):
        l, lp = _pool_entry(pool, offset, s)
        cos = jnp.maximum(_dot(n, l), 0.0)
        ul, l, weight = _fence((_to_local(frame, l), l, lp * cos[..., None]))
        c = _term(brdf, ul, vl, weight)
        if shadow_objects is not None:
            vis = _visible(shadow_objects, p, n, l, inf)
            c = c * (1.0 - vis if occluded_only else vis)[..., None]
        return a + c

    zero = jnp.zeros(p.shape, p.dtype)
    return jax.lax.fori_loop(0, n_env, one, zero) if n_env > 1 else one(0, zero)


def _indirect(objects, p, frame, vl, idx, pix, point_lights, pool, salt, spp, bounces, effects):
    """Mean over ``spp`` cosine-sampled paths of light arriving after ``1..bounces`` reflections."""
    return _paths(objects, p, frame, vl, idx, pix, point_lights, pool, salt, spp, bounces, effects,
                  lambda h, fr, v_loc, ix: _cosine_bounce(h, fr, p.dtype))


def _cosine_bounce(h, fr, dtype):
    """A cosine-weighted direction from hash ``h`` in the frame ``fr``: ``(local, world, f cos / pdf factor = pi,
    None)`` (every direction is valid)."""
    x0, x1 = _unit(h, dtype), _unit(_hash(h), dtype)
    r = jnp.sqrt(x0)
    ph = 2 * jnp.pi * x1
    loc = jnp.stack([r * jnp.cos(ph), r * jnp.sin(ph), jnp.sqrt(jnp.maximum(1 - x0, 0.0))], -1)
    return loc, _from_local(fr, loc), jnp.pi, None


def _paths(objects, p, frame, vl, idx, pix, point_lights, pool, salt, spp, bounces, effects, bounce):
    """Mean over ``spp`` paths of light arriving after ``1..bounces`` reflections; ``bounce(h, frame, local view,
    object index)`` draws a bounce direction from hash ``h``: ``(local, world, factor, ok)``, the throughput is
    multiplied by ``f(local, view) * factor`` (``factor = cos / pdf``) and a path ends where ``ok`` is False
    (``ok`` None: never)."""
    eps = _eps(p.dtype)
    shadow_objects = objects if effects.shadows else None
    base = _hash(pix ^ _hash(jnp.asarray(salt, jnp.uint32)))

    def path(s, acc):
        pos, fr, v_loc, ix = p, frame, vl, idx
        throughput = jnp.ones(p.shape, p.dtype)
        alive = jnp.ones(p.shape[:-1], bool)
        for bounce_i in range(bounces):
            h = _hash(base + jnp.uint32(s) * jnp.uint32(0x9E3779B9) + jnp.uint32((bounce_i * 0x632BE5AB) & 0xFFFFFFFF))
            loc, d, factor, ok = bounce(h, fr, v_loc, ix)
            throughput = throughput * _object_brdf(objects, ix)(loc, v_loc) * factor
            t2, ix2, hit2 = _intersect(objects, pos + eps * fr[2], d, eps)
            alive = alive & hit2 if ok is None else alive & hit2 & ok
            p2 = pos + jnp.where(hit2, t2, 0.0)[..., None] * d
            fr2 = _frame(objects, p2, ix2)
            v2 = _to_local(fr2, -d)
            l2 = _direct(_object_brdf(objects, ix2), p2, fr2, v2, point_lights, pool, _hash(h ^ jnp.uint32(7)), pix,
                         1, shadow_objects)
            acc = acc + jnp.where(alive[..., None], throughput * l2, 0.0)
            pos, fr, v_loc, ix = p2, fr2, v2, ix2
        return acc

    total = jax.lax.fori_loop(0, spp, path, jnp.zeros(p.shape, p.dtype))
    return total / spp


def without_brdfs(scene: Scene) -> Scene:
    """``scene`` with every object's BRDF replaced by None: the argument of compiled stages that do not depend on
    the BRDFs (primary rays, light samples), so that one program serves every BRDF."""
    return _replaced(scene, objects=tuple(_replaced(o, brdf=None) for o in scene.objects))


def _replaced(module: eqx.Module, **fields) -> eqx.Module:
    """A shallow copy of ``module`` with ``fields`` set (its ``__init__``, which checks and converts, not run)."""
    new = copy.copy(module)
    for name, value in fields.items():
        object.__setattr__(new, name, value)
    return new


def _primary(scene: Scene):
    """Primary rays: hit points, shading frames, local view directions (one program for every mode and every
    BRDF: :func:`without_brdfs`)."""
    return _primary_rays(without_brdfs(scene))


@eqx.filter_jit
def _primary_rays(scene: Scene):
    cam = scene.camera
    o, d = cam.rays()
    o, d = o.astype(scene.background.dtype), d.astype(scene.background.dtype)
    objects = scene.objects
    if isinstance(objects[0], NormalMap):  # the lone normal map: seen where its mask is, on the focal plane
        t = _dot(cam.target.astype(o.dtype) - o, d)
        idx, hit = jnp.zeros(t.shape, jnp.int32), objects[0].mask.reshape(-1)
    else:
        t, idx, hit = _intersect(objects, o, d, 0.0)
    p = o + jnp.where(hit, t, 0.0)[..., None] * d
    frame = _frame(objects, p, idx)
    vl = _to_local(frame, -d)
    scene_env = scene.environment
    background = scene_env.radiance(d) if scene_env is not None else jnp.broadcast_to(scene.background, d.shape)
    return dict(p=p, frame=frame, vl=vl, idx=idx, hit=hit, background=background)


@eqx.filter_jit
def _stage_point(scene: Scene, g, shadows: bool):
    brdf = _object_brdf(scene.objects, g["idx"])
    return _direct(brdf, g["p"], g["frame"], g["vl"], scene.point_lights, None, 0, None, 0,
                   scene.objects if shadows else None)


@eqx.filter_jit
def _stage_env(scene: Scene, g, pool, seed, spp: int, occluded: bool):
    brdf = _object_brdf(scene.objects, g["idx"])
    pix = jnp.arange(g["p"].shape[0], dtype=jnp.uint32)
    p, frame, vl = _fence((g["p"], g["frame"], g["vl"]))
    total = _env_sum(brdf, p, frame, vl, pool, seed ^ jnp.uint32(_ENV_KEY), pix, spp,
                     scene.objects if occluded else None, occluded_only=occluded)
    return total / spp


@eqx.filter_jit
def _stage_indirect(scene: Scene, g, pool, seed, spp: int, bounces: int, effects: Effects):
    pix = jnp.arange(g["p"].shape[0], dtype=jnp.uint32)
    point_lights = scene.point_lights if effects.direct_point else ()
    return _indirect(scene.objects, g["p"], g["frame"], g["vl"], g["idx"], pix, point_lights, pool,
                     seed ^ jnp.uint32(_INDIRECT_KEY), spp, bounces, effects)


@eqx.filter_jit
def _stage_finish(g, rad, width: int, height: int):
    img = jnp.where(g["hit"][..., None], rad, g["background"])
    return img.reshape(height, width, 3), g["hit"].reshape(height, width)


def _radiance_pool(env, n, seed, dtype, tables=None):
    """``(directions, L / pdf)`` of :func:`pool_indices`, with ``L`` gathered from the map's own (possibly
    traced) texels, so that the render differentiates with respect to them. ``tables``: the map whose
    sampling tables draw the pool (the scene's map before it was cast: concrete whenever the map was
    built outside ``jit``, so a jitted render draws the same samples as an eager one)."""
    d, k, inv_pdf = pool_indices(env if tables is None else tables, n, seed)
    radiance = env.image.reshape(-1, 3)[jnp.asarray(k)]
    return jnp.asarray(d, dtype), (radiance * jnp.asarray(inv_pdf, dtype)[:, None]).astype(dtype)


# --------------------------------------------------------------------------- BRDF importance sampling (MIS)

#: the ``sampling=`` modes of :func:`render` for the environment term
SAMPLING_MODES = ("environment", "mis", "brdf", "cosine")


def _env_pdf(env: EnvironmentLight, d):
    """Solid-angle density of :meth:`EnvironmentLight.sample` at world directions ``d``:
    ``p_ij H W / (2 pi^2 sin theta)`` for the pixel ``(i, j)`` holding ``d``."""
    h, w = env.shape
    theta = jnp.arccos(jnp.clip(d[..., 1], -1.0, 1.0))
    phi = jnp.arctan2(d[..., 0], -d[..., 2])
    i = jnp.clip(jnp.floor(theta / jnp.pi * h).astype(jnp.int32), 0, h - 1)
    j = jnp.clip(jnp.floor((phi + jnp.pi) / (2 * jnp.pi) * w).astype(jnp.int32), 0, w - 1)
    st = jnp.maximum(jnp.sin(theta), 1e-12)
    return env.pmf.astype(d.dtype)[i * w + j] * (h * w) / (2 * jnp.pi**2 * st)


def _from_local(frame, loc):
    t_, b_, n_ = frame
    return loc[..., :1] * t_ + loc[..., 1:2] * b_ + loc[..., 2:] * n_


def _sampled_direction(samplers, idx, xi, vl):
    """Local light directions and their densities from the sampler of the object hit (``None``: cosine)."""
    if samplers is None:
        u = cosine_sample(xi[..., 3:5])
        return u, cosine_pdf(u)
    us = [s.warp(xi, vl)[0] for s in samplers]
    u = _select(idx, us)
    pdf = _select(idx, [s.pdf(u, vl)[..., None] for s in samplers])[..., 0]
    return u, pdf


def _env_mis_sum(objects, env, p, frame, vl, idx, pool, samplers, salt, pix, n_env, n_brdf, shadow_objects):
    r"""Environment lighting by multiple importance sampling (balance heuristic, Veach 1997) of ``n_env``
    pooled environment samples and ``n_brdf`` BRDF samples per point:

    .. math::
        \hat L = \sum_{k} \frac{f(u_k, v)\, L_{env}(u_k) \cos^+\theta_k\, V(u_k)}
                          {n_{env}\, p_{env}(u_k) + n_{brdf}\, p_{brdf}(u_k \mid v)}

    over all ``n_env + n_brdf`` samples ``u_k`` (each drawn from one of the two densities). Unbiased when
    ``p_env`` or ``p_brdf`` is positive wherever the integrand is; the BRDF density
    (:class:`polyjax.render.ImportanceSampler`, or cosine when ``samplers`` is None) is positive on the whole
    upper hemisphere. ``n_env = 0`` is pure BRDF (or cosine) sampling. Returns the estimate ``(N, 3)`` (the
    ``1 / n`` normalisation is in the denominator).
    """
    n = frame[2]
    dirs, _ = pool
    n_pool = dirs.shape[0]
    inf = jnp.full(p.shape[:-1], jnp.inf, p.dtype)
    brdf = _object_brdf(objects, idx)
    offset = _hash(pix ^ _hash(jnp.asarray(salt, jnp.uint32)))
    stride = jnp.uint32(_pool_stride(n_pool))

    def contribution(l, cos, denom_env, denom_brdf):
        ul = _to_local(frame, l)
        c = brdf(ul, vl) * env.radiance(l) * (cos / (denom_env + denom_brdf))[..., None]
        if shadow_objects is not None:
            c = c * _visible(shadow_objects, p, n, l, inf)[..., None]
        return c

    def env_one(s, a):
        k = ((offset + jnp.uint32(s) * stride) & jnp.uint32(n_pool - 1)).astype(jnp.int32)
        l = dirs[k]
        cos = jnp.maximum(_dot(n, l), 0.0)
        ul = _to_local(frame, l)
        if samplers is None:
            pb = jnp.maximum(ul[..., 2], 0.0) / jnp.pi
        else:
            pb = _select(idx, [s.pdf(ul, vl)[..., None] for s in samplers])[..., 0]
        c = contribution(l, cos, n_env * _env_pdf(env, l), n_brdf * pb)
        return a + jnp.where((cos > 0)[..., None], c, 0.0)

    def brdf_one(s, a):
        h = _hash(offset + jnp.uint32(s) * jnp.uint32(0x9E3779B9) + jnp.uint32(0x5BD1E995))
        hs = [h]
        for _ in range(4):
            hs.append(_hash(hs[-1]))
        xi = jnp.stack([_unit(x, p.dtype) for x in hs], -1)
        ul, pb = _sampled_direction(samplers, idx, xi, vl)
        l = _from_local(frame, ul)
        cos = jnp.maximum(ul[..., 2], 0.0)
        c = contribution(l, cos, n_env * _env_pdf(env, l), n_brdf * pb)
        return a + jnp.where(((pb > 0) & (cos > 0))[..., None], c, 0.0)

    acc = jnp.zeros(p.shape, p.dtype)
    if n_env > 0:
        acc = jax.lax.fori_loop(0, n_env, env_one, acc)
    if n_brdf > 0:
        acc = jax.lax.fori_loop(0, n_brdf, brdf_one, acc)
    return acc


@eqx.filter_jit
def _stage_env_mis(scene: Scene, g, pool, samplers, seed, n_env: int, n_brdf: int, shadows: bool):
    pix = jnp.arange(g["p"].shape[0], dtype=jnp.uint32)
    env = scene.environment if scene.environment is not None else _black_env(g["p"].dtype)
    return _env_mis_sum(scene.objects, env, g["p"], g["frame"], g["vl"], g["idx"], pool, samplers,
                        seed ^ jnp.uint32(_ENV_KEY), pix, n_env, n_brdf, scene.objects if shadows else None)


def _env_sampled(scene: Scene, g, pool, seed, spp: int, sampling: str, shadows: bool, dtype):
    """The environment term with BRDF sampling: ``"mis"`` splits ``spp`` into ``spp // 2`` environment and
    ``spp - spp // 2`` BRDF samples, ``"brdf"`` and ``"cosine"`` draw all ``spp`` from the BRDF's importance
    sampler or cosine-weighted (see :func:`_env_mis_sum`)."""
    samplers = None
    if sampling in ("mis", "brdf"):
        samplers = tuple(importance_sampler(obj.brdf, dtype=dtype) for obj in scene.objects)
    n_env = spp // 2 if sampling == "mis" else 0
    return _stage_env_mis(scene, g, pool, samplers, seed, n_env, spp - n_env, shadows)


def _indirect_sampled(objects, p, frame, vl, idx, pix, point_lights, pool, samplers, salt, spp, bounces,
                      effects):
    """:func:`_indirect` with each bounce direction drawn from the importance sampler of the object it leaves
    (throughput ``*= f cos / pdf``) instead of cosine-weighted; the same estimate in expectation."""
    return _paths(objects, p, frame, vl, idx, pix, point_lights, pool, salt, spp, bounces, effects,
                  lambda h, fr, v_loc, ix: _sampled_bounce(samplers, h, fr, v_loc, ix, p.dtype))


def _sampled_bounce(samplers, h, fr, v_loc, ix, dtype):
    """A direction from the importance sampler of object ``ix`` (five numbers from hash ``h``): ``(local, world,
    cos / pdf (N, 1), ok)``; ``ok`` is False for a zero density or a direction below the horizon."""
    hs = [h]
    for _ in range(4):
        hs.append(_hash(hs[-1]))
    xi = jnp.stack([_unit(x, dtype) for x in hs], -1)
    loc, pdf = _sampled_direction(samplers, ix, xi, v_loc)
    ok = (pdf > 0) & (loc[..., 2] > 0)
    weight = jnp.where(ok, loc[..., 2] / jnp.where(ok, pdf, 1.0), 0.0)
    return loc, _from_local(fr, loc), weight[..., None], ok


@eqx.filter_jit
def _stage_indirect_sampled(scene: Scene, g, pool, samplers, seed, spp: int, bounces: int, effects: Effects):
    pix = jnp.arange(g["p"].shape[0], dtype=jnp.uint32)
    point_lights = scene.point_lights if effects.direct_point else ()
    return _indirect_sampled(scene.objects, g["p"], g["frame"], g["vl"], g["idx"], pix, point_lights, pool, samplers,
                             seed ^ jnp.uint32(_INDIRECT_KEY), spp, bounces, effects)


def _indirect_with_sampler(scene: Scene, g, pool, seed, spp: int, bounces: int, effects: Effects, dtype):
    """Indirect light with BRDF-sampled bounces (``sampling="mis"`` or ``"brdf"``)."""
    samplers = tuple(importance_sampler(obj.brdf, dtype=dtype) for obj in scene.objects)
    return _stage_indirect_sampled(scene, g, pool, samplers, seed, spp, bounces, effects)


def _black_env(dtype):
    return cast_floats(EnvironmentLight(np.zeros((8, 16, 3))), dtype)


def render(scene: Scene, *, spp: int = 64, seed: int = 0, force_all_effects: bool = False,
           dtype=jnp.float32, sampling: str = "environment") -> RenderResult:
    """Render a scene, computing only the effects :func:`plan_effects` finds in it.

    Args:
        scene: the :class:`Scene`.
        spp: samples per pixel of the sampled effects (environment, indirect); unused otherwise.
        seed: random seed of the sampled effects (each effect draws from its own stream).
        force_all_effects: compute every effect whatever the scene (for comparisons; see the module notes).
        dtype: floating-point type of the computation (the scene and its BRDFs are cast to it).
        sampling: directions of the environment term: ``"environment"`` (importance-sampled from the map),
            ``"mis"`` (half from the map, half from the BRDF's :class:`polyjax.render.ImportanceSampler`,
            balance heuristic), ``"brdf"`` or ``"cosine"`` (all from the BRDF sampler / cosine-weighted). With
            ``"mis"`` and ``"brdf"`` the indirect bounces are drawn from the BRDF sampler too.

    Returns:
        A :class:`RenderResult` with the image and the effects computed.
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene: expected a polyjax.render.Scene, found {type(scene).__name__}")
    if int(spp) < 1:
        raise InputError(f"spp: expected at least 1 sample per pixel, found {spp}")
    if sampling not in SAMPLING_MODES:
        raise InputError(f"sampling: expected one of {SAMPLING_MODES}, found {sampling!r}")
    effects = Effects.all() if force_all_effects else plan_effects(scene)
    tables = scene.environment
    scene = cast_floats(scene, dtype)
    pool = None
    if effects.environment:
        env = scene.environment if scene.environment is not None else _black_env(dtype)
        pool = _radiance_pool(env, _pool_size(int(spp)), int(seed), dtype, tables)
    bounces = max(scene.max_bounces, 1) if effects.indirect else 0
    sampled = effects.environment or effects.indirect
    seed_arr = jnp.asarray(int(seed) & 0xFFFFFFFF, jnp.uint32)
    g = _primary(scene)
    if effects.direct_point and scene.point_lights:
        rad = _stage_point(scene, g, effects.shadows)
    else:
        rad = jnp.zeros_like(g["p"])
    if effects.environment and sampling != "environment":
        rad = rad + _env_sampled(scene, g, pool, seed_arr, int(spp), sampling, effects.shadows, dtype)
    elif effects.environment:
        # the unshadowed environment term is one program whatever else is on; shadowed samples are
        # then removed by a separate estimate of the occluded part (the same samples, times 1 - V)
        rad = rad + _stage_env(scene, g, pool, seed_arr, int(spp), False)
        if effects.shadows:
            rad = rad - _stage_env(scene, g, pool, seed_arr, int(spp), True)
    if effects.indirect and sampling in ("mis", "brdf"):
        rad = rad + _indirect_with_sampler(scene, g, pool, seed_arr, int(spp), bounces, effects, dtype)
    elif effects.indirect:
        rad = rad + _stage_indirect(scene, g, pool, seed_arr, int(spp), bounces, effects)
    img, hit = _stage_finish(g, rad, scene.camera.width, scene.camera.height)
    return RenderResult(img, hit, effects, int(spp) if sampled else 0)


__all__ = ["SAMPLING_MODES", "RenderResult", "cast_floats", "render"]
