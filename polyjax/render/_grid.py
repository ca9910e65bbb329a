"""A models x materials grid of spheres in one jitted call (the paper's Figs. 3 and 5).

Every cell is the same lone sphere under the same lights; only the BRDF changes. The geometry is
therefore computed once: per pixel the hit point, shading frame and local view direction ``v``,
and per light (or environment sample, the same random samples for every cell) the local light
direction ``u`` and its weight ``E cos theta_u`` (or ``L cos theta_u / pdf``). A cell's image is
then ``sum_terms f(u, v) * weight``, i.e. only BRDF evaluations.

BRDFs are Python callables of possibly different types. Cells whose BRDFs are
:class:`equinox.Module` s of the same structure (e.g. the materials of one fitted family, or
several :class:`polyjax.render.Phong` s) are stacked into one pytree and evaluated under
``jax.vmap``; any other callable is traced on its own. All of it is one ``jit``-compiled function.
"""

from __future__ import annotations

import functools
from typing import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float

from .._arrays import device_array
from .._errors import InputError
from ._brdf import Lambertian, evaluate_rgb, rgb_brdf
from ._envmap import sample_pool
from ._integrator import _ENV_KEY, _direct, _frame, _intersect, _pool_size, _to_local, cast_floats
from ._scene import Camera, DirectionalLight, Effects, Scene, Sphere, plan_effects


class GridResult(eqx.Module):
    """What :func:`render_grid` returns.

    Attributes:
        images: ``(rows, cols, H, W, 3)`` linear RGB.
        hit: ``(H, W)`` pixels on the sphere (shared by all cells).
        effects: the effects computed (the same for every cell).
    """

    images: Float[Array, "r c h w 3"]
    hit: Bool[Array, "h w"]
    effects: Effects = eqx.field(static=True)


def sphere_scene(size: int = 128, lights=None) -> Scene:
    """The default grid cell: a unit sphere seen by an orthographic camera that it fills, lit by a
    directional light of irradiance ``pi`` from the upper right front (a white Lambertian sphere
    then has radiance ``cos theta_u``)."""
    cam = Camera(eye=(0.0, 0.0, 5.0), width=size, height=size, ortho_height=2.1)
    if lights is None:
        lights = [DirectionalLight(direction=(1.0, 1.0, 1.5), irradiance=np.pi)]
    return Scene(cam, [Sphere(Lambertian(1.0))], lights)


def _group_key(b):
    if not isinstance(b, eqx.Module):
        return ("single", id(b))
    params, static = eqx.partition(b, eqx.is_array)
    leaves = jax.tree.leaves(params)
    return (jax.tree.structure(b), tuple((x.shape, str(x.dtype)) for x in leaves))


@eqx.filter_jit
def _grid_impl(scene: Scene, groups, pool, seed, effects: Effects, spp: int):
    cam = scene.camera
    o, d = cam.rays()
    dtype = scene.background.dtype
    o, d = o.astype(dtype), d.astype(dtype)
    sphere = scene.objects[0]
    t, idx, hit = _intersect((sphere,), o, d, 0.0)
    p = o + jnp.where(hit, t, 0.0)[..., None] * d
    frame = _frame((sphere,), p, idx)
    vl = _to_local(frame, -d)
    point_lights = scene.point_lights if effects.direct_point else ()
    pix = jnp.arange(cam.width * cam.height, dtype=jnp.uint32)
    salt = seed ^ jnp.uint32(_ENV_KEY)
    background = (scene.environment.radiance(d) if scene.environment is not None
                  else jnp.broadcast_to(scene.background, d.shape))

    def shade(brdf_module):
        rad = _direct(lambda u, v: evaluate_rgb(brdf_module, u, v), p, frame, vl, point_lights, pool, salt, pix, spp,
                      None)
        return jnp.where(hit[..., None], rad, background).reshape(cam.height, cam.width, 3)

    outs = []
    for stacked, static in groups:
        if stacked is None:
            outs.append(shade(static)[None])
        else:
            outs.append(jax.vmap(lambda prm, static=static: shade(eqx.combine(prm, static)))(stacked))
    return outs, hit.reshape(cam.height, cam.width)


def render_grid(brdfs: Sequence[Sequence], scene: Scene | None = None, *, size: int = 128, spp: int = 64, seed: int = 0,
                dtype=jnp.float32) -> GridResult:
    """Render one sphere per BRDF: a ``rows x cols`` grid (e.g. models x materials) in one jitted call.

    Args:
        brdfs: rows of BRDFs (anything :func:`polyjax.render.rgb_brdf` accepts), all rows the same length.
        scene: a scene with exactly one :class:`Sphere` (its BRDF is ignored) and its lights;
            default :func:`sphere_scene` of ``size`` pixels.
        spp: environment samples per pixel (used only when the scene has an environment map).
        seed: random seed of the environment samples (the same samples for every cell, as in :func:`render`).
        dtype: floating-point type of the computation.

    Returns:
        A :class:`GridResult`.
    """
    rows = [list(r) for r in brdfs]
    if not rows or not rows[0] or any(len(r) != len(rows[0]) for r in rows):
        raise InputError("brdfs: expected a non-empty rectangular grid of BRDFs, "
                         f"found rows of lengths {[len(r) for r in rows]}")
    scene = sphere_scene(size) if scene is None else scene
    if not (isinstance(scene, Scene) and len(scene.objects) == 1 and isinstance(scene.objects[0], Sphere)):
        raise InputError("scene: expected a polyjax.render.Scene with exactly one Sphere for a grid of spheres")
    if int(spp) < 1:
        raise InputError(f"spp: expected at least 1 sample per pixel, found {spp}")
    effects = plan_effects(scene)
    scene = cast_floats(scene, dtype)
    n_r, n_c = len(rows), len(rows[0])
    flat = [cast_floats(rgb_brdf(b), dtype) for r in rows for b in r]
    order: dict = {}
    for k, b in enumerate(flat):
        order.setdefault(_group_key(b), []).append(k)
    groups, where = [], []
    for members in order.values():
        b0 = flat[members[0]]
        if isinstance(b0, eqx.Module):
            params = [eqx.filter(flat[k], eqx.is_array) for k in members]
            stacked = _stacked(params)
            groups.append((stacked, eqx.filter(b0, eqx.is_array, inverse=True)))
        else:
            groups.append((None, b0))
        where.append(members)
    pool = None
    if effects.environment:
        pool = tuple(device_array(a, dtype) for a in sample_pool(scene.environment, _pool_size(int(spp)), int(seed)))
    seed = jnp.asarray(int(seed) & 0xFFFFFFFF, jnp.uint32)
    outs, hit = _grid_impl(scene, groups, pool, seed, effects, int(spp))
    images = _assemble(tuple(outs), tuple(tuple(m) for m in where), (n_r, n_c))
    return GridResult(images, hit, effects)


@jax.jit
def _stacked(params):
    """The array leaves of the models of one group stacked along a new first axis (one compiled program)."""
    return jax.tree.map(lambda *xs: jnp.stack(xs), *params)


@functools.partial(jax.jit, static_argnames=("where", "grid"))
def _assemble(outs, where, grid):
    """The ``grid`` ``(rows, columns)`` of images from the groups' images ``outs`` (group ``g`` holds the cells
    ``where[g]``, row-major), in one compiled program."""
    h, w = outs[0].shape[1:3]
    images = jnp.zeros((grid[0] * grid[1], h, w, 3), outs[0].dtype)
    for members, out in zip(where, outs):
        images = images.at[jnp.asarray(members)].set(out.astype(images.dtype))
    return images.reshape(*grid, h, w, 3)


__all__ = ["GridResult", "render_grid", "sphere_scene"]
