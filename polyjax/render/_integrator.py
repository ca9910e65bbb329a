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
- **environment**: Monte Carlo with ``spp`` samples importance-sampled from the map
  (:class:`polyjax.render.EnvironmentLight`).
- **indirect**: ``spp`` paths per pixel of ``max_bounces`` cosine-sampled bounces; at each
  secondary hit the direct terms above are added (the environment with one sample). Rays that
  leave the scene add nothing here (that light is the environment term).

``force_all_effects=True`` computes every term whatever the scene (a black environment map when
there is none, shadow rays, one indirect bounce at least); on a scene where the extra terms
contribute nothing the pixels are identical, since they add exact zeros and multiply by exact ones.
"""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._errors import InputError
from ._brdf import evaluate_rgb
from ._envmap import EnvironmentLight
from ._scene import DirectionalLight, Effects, Plane, PointLight, Scene, Sphere, plan_effects

_ENV_KEY, _INDIRECT_KEY = 1, 2


def cast_floats(tree, dtype):
    """Cast every floating-point array leaf of a pytree (scene, BRDF) to ``dtype``."""
    return jax.tree.map(lambda x: x.astype(dtype) if eqx.is_inexact_array(x) else x, tree)


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


def _eps(dtype) -> float:
    return 1e-4 if jnp.finfo(dtype).bits <= 32 else 1e-7


def _intersect(objects, o, d, tmin):
    """Nearest hit along rays: ``(t, index, hit)``; ``t = inf`` where nothing is hit beyond ``tmin``."""
    ts = []
    for obj in objects:
        if isinstance(obj, Sphere):
            oc = o - obj.center
            b = jnp.sum(oc * d, -1)
            c = jnp.sum(oc * oc, -1) - obj.radius**2
            disc = b * b - c
            sq = jnp.sqrt(jnp.maximum(disc, 0.0))
            t0, t1 = -b - sq, -b + sq
            t = jnp.where(t0 > tmin, t0, jnp.where(t1 > tmin, t1, jnp.inf))
            ts.append(jnp.where(disc >= 0, t, jnp.inf))
        else:
            denom = jnp.sum(d * obj.normal, -1)
            safe = jnp.where(denom != 0, denom, 1.0)
            t = (obj.offset - jnp.sum(o * obj.normal, -1)) / safe
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
        else:
            ns.append(jnp.broadcast_to(obj.normal, p.shape))
            tans.append(jnp.broadcast_to(obj.tangent, p.shape))
    n = _select(idx, ns)
    t = _select(idx, tans)
    return t, jnp.cross(n, t), n


def _to_local(frame, w):
    t, b, n = frame
    return jnp.stack([jnp.sum(w * t, -1), jnp.sum(w * b, -1), jnp.sum(w * n, -1)], -1)


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


def _direct(brdf, p, frame, vl, point_lights, env, key, n_env, shadow_objects):
    """Direct lighting ``(N, 3)`` at points ``p`` (frame, local view ``vl``).

    ``shadow_objects`` is None when no shadow ray is needed; ``env`` None when the environment
    effect is off; ``n_env`` the environment samples per point.
    """
    n = frame[2]
    acc = jnp.zeros(p.shape, p.dtype)
    for light in point_lights:
        if isinstance(light, DirectionalLight):
            l = jnp.broadcast_to(light.direction, p.shape)
            e = light.irradiance
            dist = jnp.full(p.shape[:-1], jnp.inf, p.dtype)
            cos = jnp.maximum(jnp.sum(n * l, -1), 0.0)
            weight = e * cos[..., None]
        else:
            delta = light.position - p
            d2 = jnp.sum(delta * delta, -1)
            dist = jnp.sqrt(d2)
            l = delta / dist[..., None]
            cos = jnp.maximum(jnp.sum(n * l, -1), 0.0)
            weight = light.intensity * (cos / d2)[..., None]
        c = brdf(_to_local(frame, l), vl) * weight
        if shadow_objects is not None:
            c = c * _visible(shadow_objects, p, n, l, dist)[..., None]
        acc = acc + c
    if env is not None:
        inf = jnp.full(p.shape[:-1], jnp.inf, p.dtype)

        def one(s, a):
            xi = jax.random.uniform(jax.random.fold_in(key, s), p.shape, p.dtype)
            l, lp = env.sample(xi)
            cos = jnp.maximum(jnp.sum(n * l, -1), 0.0)
            c = brdf(_to_local(frame, l), vl) * (lp * cos[..., None])
            if shadow_objects is not None:
                c = c * _visible(shadow_objects, p, n, l, inf)[..., None]
            return a + c

        env_sum = jax.lax.fori_loop(0, n_env, one, jnp.zeros(p.shape, p.dtype)) if n_env > 1 else one(0, jnp.zeros(p.shape, p.dtype))
        acc = acc + env_sum / n_env
    return acc


def _indirect(objects, p, frame, vl, idx, point_lights, env, key, spp, bounces, effects):
    """Mean over ``spp`` cosine-sampled paths of light arriving after ``1..bounces`` reflections."""
    eps = _eps(p.dtype)
    shadow_objects = objects if effects.shadows else None

    def path(s, acc):
        k = jax.random.fold_in(key, s)
        pos, fr, v_loc, ix = p, frame, vl, idx
        throughput = jnp.ones(p.shape, p.dtype)
        alive = jnp.ones(p.shape[:-1], bool)
        for bounce in range(bounces):
            kb = jax.random.fold_in(k, bounce)
            xi = jax.random.uniform(jax.random.fold_in(kb, 0), p.shape[:-1] + (2,), p.dtype)
            r = jnp.sqrt(xi[..., 0])
            ph = 2 * jnp.pi * xi[..., 1]
            loc = jnp.stack([r * jnp.cos(ph), r * jnp.sin(ph), jnp.sqrt(jnp.maximum(1 - xi[..., 0], 0.0))], -1)
            t_, b_, n_ = fr
            d = loc[..., :1] * t_ + loc[..., 1:2] * b_ + loc[..., 2:] * n_
            # cosine-weighted sampling: f cos / pdf = f pi
            throughput = throughput * _object_brdf(objects, ix)(loc, v_loc) * jnp.pi
            t2, ix2, hit2 = _intersect(objects, pos + eps * n_, d, eps)
            alive = alive & hit2
            p2 = pos + jnp.where(hit2, t2, 0.0)[..., None] * d
            fr2 = _frame(objects, p2, ix2)
            v2 = _to_local(fr2, -d)
            l2 = _direct(_object_brdf(objects, ix2), p2, fr2, v2, point_lights, env, jax.random.fold_in(kb, 1), 1,
                         shadow_objects)
            acc = acc + jnp.where(alive[..., None], throughput * l2, 0.0)
            pos, fr, v_loc, ix = p2, fr2, v2, ix2
        return acc

    total = jax.lax.fori_loop(0, spp, path, jnp.zeros(p.shape, p.dtype))
    return total / spp


@eqx.filter_jit
def _render_impl(scene: Scene, env, key, effects: Effects, spp: int, bounces: int):
    cam = scene.camera
    o, d = cam.rays()
    o, d = o.astype(scene.background.dtype), d.astype(scene.background.dtype)
    objects = scene.objects
    t, idx, hit = _intersect(objects, o, d, 0.0)
    p = o + jnp.where(hit, t, 0.0)[..., None] * d
    frame = _frame(objects, p, idx)
    vl = _to_local(frame, -d)
    brdf = _object_brdf(objects, idx)
    point_lights = scene.point_lights if effects.direct_point else ()
    shadow_objects = objects if effects.shadows else None
    env_used = env if effects.environment else None
    rad = _direct(brdf, p, frame, vl, point_lights, env_used, jax.random.fold_in(key, _ENV_KEY), spp, shadow_objects)
    if effects.indirect:
        rad = rad + _indirect(objects, p, frame, vl, idx, point_lights, env_used, jax.random.fold_in(key, _INDIRECT_KEY),
                              spp, bounces, effects)
    scene_env = scene.environment
    background = scene_env.radiance(d) if scene_env is not None else jnp.broadcast_to(scene.background, d.shape)
    img = jnp.where(hit[..., None], rad, background)
    return img.reshape(cam.height, cam.width, 3), hit.reshape(cam.height, cam.width)


def _black_env(dtype):
    return cast_floats(EnvironmentLight(np.zeros((8, 16, 3))), dtype)


def render(scene: Scene, *, spp: int = 64, seed: int = 0, force_all_effects: bool = False,
           dtype=jnp.float32) -> RenderResult:
    """Render a scene, computing only the effects :func:`plan_effects` finds in it.

    Args:
        scene: the :class:`Scene`.
        spp: samples per pixel of the sampled effects (environment, indirect); unused otherwise.
        seed: random seed of the sampled effects (each effect draws from its own stream).
        force_all_effects: compute every effect whatever the scene (for comparisons; see the module notes).
        dtype: floating-point type of the computation (the scene and its BRDFs are cast to it).

    Returns:
        A :class:`RenderResult` with the image and the effects computed.
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene: expected a polyjax.render.Scene, found {type(scene).__name__}")
    if int(spp) < 1:
        raise InputError(f"spp: expected at least 1 sample per pixel, found {spp}")
    effects = Effects.all() if force_all_effects else plan_effects(scene)
    scene = cast_floats(scene, dtype)
    env = scene.environment
    if effects.environment and env is None:
        env = _black_env(dtype)
    bounces = max(scene.max_bounces, 1) if effects.indirect else 0
    sampled = effects.environment or effects.indirect
    img, hit = _render_impl(scene, env, jax.random.key(seed), effects, int(spp), bounces)
    return RenderResult(img, hit, effects, int(spp) if sampled else 0)


__all__ = ["RenderResult", "cast_floats", "render"]
