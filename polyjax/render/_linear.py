r"""A render as a linear function of the BRDF: per pixel, the light directions and their weights.

For a fixed scene without inter-reflection, the radiance of a pixel that sees object ``target`` is

.. math::
    L = \sum_j c_j\, f(u_j, v), \qquad
    c_j = E_j \cos\theta_{u_j} V_j \ \text{(point / directional light } j), \quad
    c_s = \frac{L_{env}(u_s) \cos^+\theta_{u_s} V_s}{\mathrm{pdf}(u_s)\, n_s} \ \text{(environment sample } s)

(:mod:`polyjax.render._integrator`, direct terms): ``f`` enters linearly, with RGB weights ``c``
known from the scene alone. :func:`light_samples` returns ``(v, u_j, c_j)`` per pixel;
``sum_j c_j f(u_j, v)`` is the render of the scene with ``f`` on the target object (exactly for
point and directional lights; for an environment map it is the same kind of estimate from the
same importance-sampled pool, with ``spp`` samples per pixel).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .._errors import InputError
from ._brdf import evaluate_rgb
from ._integrator import (
    _ENV_KEY,
    _dot,
    _hash,
    _light_at,
    _pool_entry,
    _pool_size,
    _primary,
    _radiance_pool,
    _to_local,
    _visible,
    cast_floats,
    without_brdfs,
)
from ._scene import Scene, plan_effects


class LightSamples(eqx.Module):
    """What a pixel sees of the target object and its lights (``N = H W`` pixels, ``J`` light samples).

    Attributes:
        v: ``(N, 3)`` view direction in the local shading frame.
        u: ``(N, J, 3)`` light directions in the local frame.
        weight: ``(N, J, 3)`` RGB weights ``c_j`` (0 for a light below the horizon, occluded, or padding).
        is_point: ``(J,)`` True for point and directional lights, False for environment samples.
        on_target: ``(N,)`` True where the primary ray hits the target object.
        shadowed: ``(N,)`` True where a point or directional light above the horizon is occluded.
    """

    v: Float[Array, "n 3"]
    u: Float[Array, "n j 3"]
    weight: Float[Array, "n j 3"]
    is_point: Bool[Array, " j"]
    on_target: Bool[Array, " n"]
    shadowed: Bool[Array, " n"]


def light_samples(scene: Scene, target: int = 0, *, spp: int = 64, seed: int = 0, dtype=jnp.float64) -> LightSamples:
    """Per pixel, the light directions and weights of the direct lighting of object ``target``.

    Differentiable with respect to the scene's lights, environment texels and geometry (as
    :func:`polyjax.render.render`); visibility is piecewise constant.

    Args:
        scene: the :class:`Scene` (its objects' BRDFs are not used).
        target: index into ``scene.objects`` of the object whose pixels are returned.
        spp: environment samples per pixel (when the scene has an environment map).
        seed: random seed of the environment samples.
        dtype: floating-point type of the computation.

    Raises:
        InputError: ``target`` is not an object index, or the scene has inter-reflections
            (``max_bounces > 0`` with several objects): the radiance is then not linear in one BRDF.
    """
    if not isinstance(scene, Scene):
        raise InputError(f"scene: expected a polyjax.render.Scene, found {type(scene).__name__}")
    if not 0 <= int(target) < len(scene.objects):
        raise InputError(f"target: expected an object index in [0, {len(scene.objects)}), found {target}")
    effects = plan_effects(scene)
    if effects.indirect:
        raise InputError("scene: expected direct lighting only (max_bounces=0): with inter-reflections the "
                         "radiance is not linear in the target's BRDF")
    tables = scene.environment
    scene = cast_floats(scene, dtype)
    env = scene.environment
    # the pool is drawn outside the compiled function, like the renderer's (the same samples)
    pool = None if env is None else _radiance_pool(env, _pool_size(int(spp)), int(seed), dtype, tables)
    # one program for every BRDF of the objects (not used here)
    return _light_samples(without_brdfs(scene), pool, int(target), int(spp), int(seed), effects.shadows)


@eqx.filter_jit
def _light_samples(scene, pool, target, spp, seed, shadows):
    g = _primary(scene)
    p, frame, vl = g["p"], g["frame"], g["vl"]
    n = frame[2]
    shadow_objects = scene.objects if shadows else None
    us, cs, points = [], [], []
    shadowed = jnp.zeros(p.shape[:-1], bool)
    for light in scene.point_lights:
        l, dist, cos, c = _light_at(light, p, n)
        if shadow_objects is not None:
            vis = _visible(shadow_objects, p, n, l, dist)
            shadowed = shadowed | ((vis == 0) & (cos > 0))
            c = c * vis[..., None]
        us.append(_to_local(frame, l))
        cs.append(c)
        points.append(True)
    if pool is not None:
        pix = jnp.arange(p.shape[0], dtype=jnp.uint32)
        offset = _hash(pix ^ _hash(jnp.asarray(int(seed) & 0xFFFFFFFF, jnp.uint32) ^ jnp.uint32(_ENV_KEY)))
        inf = jnp.full(p.shape[:-1], jnp.inf, p.dtype)
        for s in range(int(spp)):
            l, lp = _pool_entry(pool, offset, s)
            cos = jnp.maximum(_dot(n, l), 0.0)
            c = lp * cos[..., None] / spp
            if shadow_objects is not None:
                c = c * _visible(shadow_objects, p, n, l, inf)[..., None]
            us.append(_to_local(frame, l))
            cs.append(c)
            points.append(False)
    if not us:
        raise InputError("scene: expected at least one light")
    return LightSamples(
        v=vl, u=jnp.stack(us, axis=1), weight=jnp.stack(cs, axis=1), is_point=jnp.asarray(points),
        on_target=g["hit"] & (g["idx"] == int(target)), shadowed=shadowed,
    )


def render_linear(samples: LightSamples, brdf) -> Float[Array, "n 3"]:
    """``sum_j c_j f(u_j, v)`` per pixel (0 off the target): the render of ``brdf`` from :func:`light_samples`."""
    f = evaluate_rgb(brdf, samples.u, samples.v[:, None, :])
    out = jnp.sum(samples.weight * f, axis=1)
    return jnp.where(samples.on_target[:, None], out, 0.0)

__all__ = ["LightSamples", "light_samples", "render_linear"]
