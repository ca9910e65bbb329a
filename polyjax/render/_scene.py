"""Scene description: a camera, analytic spheres and planes, normal maps, and lights.

World frame: right-handed, ``+y`` up. Each object carries its BRDF (a callable
``f(u, v) -> (..., 3)``, see :mod:`polyjax.render._brdf`) and defines the local shading frame
``(t, b, n)`` in which the BRDF is evaluated: ``n`` the outward normal, ``t`` a tangent (the
BRDF's ``+x``), ``b = n x t``.

Every class here can be built inside a traced function (``jax.jit``, ``jax.grad``, ``jax.vmap``):
traced arguments are checked from their shapes only (value checks such as "finite" or "positive
radius" apply when the values are concrete) and stay differentiable.
"""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._arrays import is_traced
from .._errors import InputError
from ._brdf import BRDF, rgb_brdf
from ._envmap import EnvironmentLight


def _float(x) -> Array:
    a = jnp.asarray(x)
    return a if jnp.issubdtype(a.dtype, jnp.floating) else a.astype(jnp.result_type(float))


def _vec3(x, name) -> Array:
    """:func:`_np3` as a JAX array."""
    a = _np3(x, name)
    return a if isinstance(a, jax.Array) else jnp.asarray(a)


#: the largest magnitude of a concrete position, size or height (scene units): squares and products of such numbers,
#: as ray-sphere and ray-plane intersections form, stay far from overflow in float64 and float32 (3.4e38)
MAX_COORDINATE = 1e15


def _position(x, name):
    """:func:`_np3` of a point, concrete values also within :data:`MAX_COORDINATE` in magnitude."""
    a = _np3(x, name)
    if not is_traced(a) and not np.all(np.abs(a) <= MAX_COORDINATE):
        raise InputError(f"{name}: expected coordinates within +-{MAX_COORDINATE:g} scene units, found "
                         f"{np.asarray(a).tolist()!r}")
    return a


def _scalar(x, name, positive=False):
    """A concrete finite number (positive if asked) within :data:`MAX_COORDINATE` in magnitude."""
    try:
        value = float(x)
    except (TypeError, ValueError):
        raise InputError(f"{name}: expected a number, found {x!r}") from None
    if not (np.isfinite(value) and abs(value) <= MAX_COORDINATE and (value > 0 or not positive)):
        kind = "a positive number" if positive else "a finite number"
        raise InputError(f"{name}: expected {kind} within +-{MAX_COORDINATE:g} scene units, found {x!r}")
    return value


def _unit(a, name):
    """``a / |a|`` of a concrete finite 3-vector without overflow or underflow: where ``|a|`` is out of range, ``a``
    is scaled by its largest component first (elsewhere ``a / |a|`` exactly as the traced path computes it, so
    that a scene built from values and one built inside ``jit`` agree to the bit); InputError for the zero
    vector."""
    scale = np.max(np.abs(a))
    if scale == 0:
        raise InputError(f"{name}: expected a non-zero vector")
    if 1e-100 < scale < 1e100:
        return a / np.linalg.norm(a)
    b = a / scale
    return b / np.linalg.norm(b)


def _np3(x, name):
    """A 3-vector (a scalar is repeated). Concrete values are checked for shape and finiteness; traced values
    (inside ``jit``/``grad``) are checked for shape only and kept as they are, so that they stay differentiable."""
    if is_traced(x):
        a = _float(jnp.stack([_float(c) for c in x]) if isinstance(x, (list, tuple)) else x)
        if a.shape == ():
            a = jnp.broadcast_to(a, (3,))
        if a.shape != (3,):
            raise InputError(f"{name}: expected a 3-vector (or scalar), found an array of shape {a.shape}")
        return a
    a = np.asarray(x, dtype=float)
    if a.shape == ():
        a = np.full((3,), float(a))
    if a.shape != (3,) or not np.all(np.isfinite(a)):
        raise InputError(f"{name}: expected a finite 3-vector (or scalar), found {np.asarray(x).tolist()!r}")
    return a


class Camera(eqx.Module):
    """A pinhole (or orthographic) camera.

    Attributes:
        eye, target, up: position, look-at point and up hint (world).
        fov_deg: vertical field of view (perspective).
        width, height: image size in pixels.
        ortho_height: if > 0, an orthographic camera whose view is this tall (world units).
    """

    eye: Float[Array, "3"]
    target: Float[Array, "3"]
    up: Float[Array, "3"]
    fov_deg: Float[Array, ""]
    ortho_height: Float[Array, ""]
    width: int = eqx.field(static=True)
    height: int = eqx.field(static=True)

    def __init__(self, eye: ArrayLike = (0.0, 0.0, 4.0), target: ArrayLike = (0.0, 0.0, 0.0),
                 up: ArrayLike = (0.0, 1.0, 0.0), fov_deg: float = 30.0, width: int = 256, height: int = 256,
                 ortho_height: float = 0.0):
        if int(width) < 1 or int(height) < 1:
            raise InputError(f"width, height: expected positive pixel counts, found {width} x {height}")
        if not is_traced(fov_deg) and not 0.0 < float(fov_deg) < 180.0:
            raise InputError(f"fov_deg: expected a field of view in (0, 180) degrees, found {fov_deg}")
        eye, target, up = _position(eye, "eye"), _position(target, "target"), _np3(up, "up")
        if not is_traced(eye, target, up):
            if np.array_equal(eye, target):
                raise InputError(f"target: expected a point other than the eye, found {target.tolist()!r}")
            if np.linalg.norm(np.cross(_unit(target - eye, "target - eye"), _unit(up, "up"))) < 1e-9:
                raise InputError("up: expected a direction not parallel to the viewing direction target - eye")
        self.eye, self.target, self.up = jnp.asarray(eye), jnp.asarray(target), jnp.asarray(up)
        self.fov_deg = _float(fov_deg) if is_traced(fov_deg) else jnp.asarray(float(fov_deg))
        self.ortho_height = _float(ortho_height) if is_traced(ortho_height) else jnp.asarray(float(ortho_height))
        self.width = int(width)
        self.height = int(height)

    def rays(self) -> tuple[Float[Array, "n 3"], Float[Array, "n 3"]]:
        """Origins and unit directions of the primary rays through pixel centres, row-major from the top."""
        w = self.target - self.eye
        w = w / jnp.linalg.norm(w)
        r = jnp.cross(w, self.up)
        r = r / jnp.linalg.norm(r)
        up = jnp.cross(r, w)
        aspect = self.width / self.height
        ys = 1.0 - 2.0 * (jnp.arange(self.height, dtype=w.dtype) + 0.5) / self.height
        xs = (2.0 * (jnp.arange(self.width, dtype=w.dtype) + 0.5) / self.width - 1.0) * aspect
        X, Y = jnp.meshgrid(xs, ys)
        X, Y = X.reshape(-1, 1), Y.reshape(-1, 1)
        ortho = self.ortho_height > 0
        half = jnp.where(ortho, 0.5 * self.ortho_height, jnp.tan(0.5 * jnp.deg2rad(self.fov_deg)))
        persp_d = w + half * (X * r + Y * up)
        persp_d = persp_d / jnp.linalg.norm(persp_d, axis=-1, keepdims=True)
        d = jnp.where(ortho, jnp.broadcast_to(w, persp_d.shape), persp_d)
        o = jnp.where(ortho, self.eye + half * (X * r + Y * up), jnp.broadcast_to(self.eye, persp_d.shape))
        return o, d


class Sphere(eqx.Module):
    """An analytic sphere. Tangent ``t`` follows the circles of latitude about ``+y`` (``+x`` at the poles)."""

    center: Float[Array, "3"]
    radius: Float[Array, ""]
    brdf: BRDF

    def __init__(self, brdf, center: ArrayLike = (0.0, 0.0, 0.0), radius: float = 1.0):
        self.center = jnp.asarray(_position(center, "center"))
        self.radius = _float(radius) if is_traced(radius) else jnp.asarray(_scalar(radius, "radius", positive=True))
        self.brdf = rgb_brdf(brdf)


class Plane(eqx.Module):
    """An infinite plane ``n . x = offset`` (one-sided, facing ``normal``); tangent: ``tangent`` projected."""

    normal: Float[Array, "3"]
    offset: Float[Array, ""]
    tangent: Float[Array, "3"]
    brdf: BRDF

    def __init__(self, brdf, height: float = -1.0, normal: ArrayLike = (0.0, 1.0, 0.0),
                 tangent: ArrayLike = (1.0, 0.0, 0.0)):
        if is_traced(normal, tangent, height):
            n = _vec3(normal, "normal")
            n = n / jnp.linalg.norm(n)
            t = _vec3(tangent, "tangent")
            t = t - n * (t @ n)
            self.normal = n
            self.offset = _float(height)
            self.tangent = t / jnp.linalg.norm(t)
            self.brdf = rgb_brdf(brdf)
            return
        n = _unit(_np3(normal, "normal"), "normal")
        t = _unit(_np3(tangent, "tangent"), "tangent")
        t = t - n * (t @ n)
        if np.linalg.norm(t) < 1e-9:
            raise InputError("tangent: expected a direction not parallel to the plane normal")
        self.normal = jnp.asarray(n)
        self.offset = jnp.asarray(_scalar(height, "height"))
        self.tangent = jnp.asarray(t / np.linalg.norm(t))
        self.brdf = rgb_brdf(brdf)


class NormalMap(eqx.Module):
    """A surface known only through its normals as seen by the camera, one per pixel: a measured normal map
    (photometric stereo, a capture's ground truth). Pixel ``(i, j)`` of the camera sees the surface where
    ``mask[i, j]``, with unit normal ``normals[i, j]`` (world frame); the point seen lies on the camera's focal
    plane (the plane through ``target`` facing the camera), so the map has no depth: it casts no shadow, is hit by
    no secondary ray and reflects no light onto itself. It is a scene's only object, seen by an orthographic
    camera of its own size (``Scene`` checks both). Tangent ``t``: as :class:`Sphere`'s, ``(0, 1, 0) x n``
    normalised (``+x`` where ``n`` is along ``+-y``), so a normal map of a sphere has the sphere's frames.

    Attributes:
        normals: ``(H, W, 3)`` unit normals in the world frame (rows from the top of the image).
        mask: ``(H, W)`` True where the pixel sees the surface.
        brdf: the BRDF (:func:`polyjax.render.rgb_brdf` of a model, or a placeholder for fits).
    """

    normals: Float[Array, "h w 3"]
    mask: Array
    brdf: BRDF

    def __init__(self, brdf, normals: ArrayLike, mask: ArrayLike | None = None):
        n = normals if is_traced(normals) else np.asarray(normals, dtype=float)
        if n.ndim != 3 or n.shape[-1] != 3:
            raise InputError(f"normals: expected an (H, W, 3) normal map, found shape {tuple(n.shape)}")
        m = np.ones(n.shape[:2], bool) if mask is None else np.asarray(mask)
        if m.shape != n.shape[:2]:
            raise InputError(f"mask: expected shape {tuple(n.shape[:2])} (the normal map's), found {m.shape}")
        m = m.astype(bool)
        if not is_traced(n):
            length = np.linalg.norm(n, axis=-1)
            bad = m & ~(np.abs(length - 1.0) <= 1e-3)
            if np.any(bad):
                i, j = np.argwhere(bad)[0]
                raise InputError(f"normals: expected unit normals where the mask is set; {int(bad.sum())} are not "
                                 f"(pixel ({i}, {j}) has length {length[i, j]:.6g})")
            n = np.where(m[..., None], n, np.array([0.0, 0.0, 1.0]))
        self.normals = n if is_traced(n) else jnp.asarray(n)
        self.mask = jnp.asarray(m)
        self.brdf = rgb_brdf(brdf)

    @property
    def shape(self) -> tuple[int, int]:
        """``(H, W)``."""
        return tuple(self.normals.shape[:2])


class DirectionalLight(eqx.Module):
    """A distant light: irradiance ``irradiance`` (RGB, on a surface facing it) from ``direction`` (towards the
    light)."""

    direction: Float[Array, "3"]
    irradiance: Float[Array, "3"]

    def __init__(self, direction: ArrayLike = (0.0, 0.0, 1.0), irradiance: ArrayLike = 1.0):
        if is_traced(direction):  # normalised in JAX; the derivative of d / |d| flows back to ``direction``
            d = _vec3(direction, "direction")
            self.direction = d / jnp.linalg.norm(d)
            self.irradiance = _vec3(irradiance, "irradiance")
            return
        self.direction = jnp.asarray(_unit(_np3(direction, "direction"), "direction"))
        self.irradiance = _vec3(irradiance, "irradiance")


class PointLight(eqx.Module):
    """An isotropic point light of radiant intensity ``intensity`` (RGB); irradiance ``I cos / r^2``."""

    position: Float[Array, "3"]
    intensity: Float[Array, "3"]

    def __init__(self, position: ArrayLike = (2.0, 2.0, 4.0), intensity: ArrayLike = 24.0):
        self.position = jnp.asarray(_position(position, "position"))
        self.intensity = _vec3(intensity, "intensity")


class Scene(eqx.Module):
    """Everything a render needs.

    Attributes:
        camera: the :class:`Camera`.
        objects: tuple of :class:`Sphere` / :class:`Plane`, or one :class:`NormalMap` alone.
        lights: tuple of :class:`DirectionalLight`, :class:`PointLight` and at most one
            :class:`polyjax.render.EnvironmentLight`.
        background: RGB radiance of rays that hit nothing (used when there is no environment map).
        max_bounces: indirect bounces to simulate (0: direct lighting only).
    """

    camera: Camera
    objects: tuple
    lights: tuple
    background: Float[Array, "3"]
    max_bounces: int = eqx.field(static=True)

    def __init__(self, camera: Camera, objects, lights, background: ArrayLike = 0.0, max_bounces: int = 0):
        objects = tuple(objects) if isinstance(objects, (list, tuple)) else (objects,)
        lights = tuple(lights) if isinstance(lights, (list, tuple)) else (lights,)
        if not isinstance(camera, Camera):
            raise InputError(f"camera: expected a polyjax.render.Camera, found {type(camera).__name__}")
        for i, o in enumerate(objects):
            if not isinstance(o, (Sphere, Plane, NormalMap)):
                raise InputError(f"objects[{i}]: expected a Sphere, Plane or NormalMap, found {type(o).__name__}")
        _check_normal_map(camera, objects)
        n_env = 0
        for i, li in enumerate(lights):
            if not isinstance(li, (DirectionalLight, PointLight, EnvironmentLight)):
                raise InputError(
                    f"lights[{i}]: expected a DirectionalLight, PointLight or EnvironmentLight, "
                    f"found {type(li).__name__}"
                )
            n_env += isinstance(li, EnvironmentLight)
        if n_env > 1:
            raise InputError(f"lights: expected at most one EnvironmentLight, found {n_env}")
        if int(max_bounces) < 0:
            raise InputError(f"max_bounces: expected >= 0, found {max_bounces}")
        self.camera = camera
        self.objects = objects
        self.lights = lights
        self.background = _vec3(background, "background")
        self.max_bounces = int(max_bounces)

    @property
    def environment(self):
        """The scene's :class:`EnvironmentLight`, or None."""
        envs = [li for li in self.lights if isinstance(li, EnvironmentLight)]
        return envs[0] if envs else None

    @property
    def point_lights(self) -> tuple:
        """Directional and point lights."""
        return tuple(li for li in self.lights if isinstance(li, (DirectionalLight, PointLight)))


def _check_normal_map(camera: Camera, objects: tuple) -> None:
    """A :class:`NormalMap` is a scene's only object, seen by an orthographic camera of the map's size."""
    maps = [o for o in objects if isinstance(o, NormalMap)]
    if not maps:
        return
    if len(objects) != 1:
        raise InputError(f"objects: a NormalMap has no depth and must be the scene's only object, found "
                         f"{len(objects)} objects")
    h, w = maps[0].shape
    if (camera.height, camera.width) != (h, w):
        raise InputError(f"camera: expected {w} x {h} pixels (the NormalMap's), found {camera.width} x "
                         f"{camera.height}")
    if not is_traced(camera.ortho_height) and not float(camera.ortho_height) > 0:
        raise InputError("camera: a NormalMap is seen by an orthographic camera (ortho_height > 0)")


@dataclasses.dataclass(frozen=True)
class Effects:
    """Which light-transport effects a render computes (decided before tracing by :func:`plan_effects`).

    Attributes:
        direct_point: direct lighting from directional/point lights (closed form per pixel: one BRDF evaluation per
            light).
        shadows: visibility (shadow) rays towards lights; only when an object can occlude another.
        environment: environment-map lighting, importance-sampled (``spp`` samples per pixel).
        indirect: light reflected between objects (``max_bounces`` bounces, ``spp`` paths per pixel).
    """

    direct_point: bool = False
    shadows: bool = False
    environment: bool = False
    indirect: bool = False

    @classmethod
    def all(cls) -> "Effects":
        return cls(True, True, True, True)

    def names(self) -> tuple[str, ...]:
        """The names of the effects that are on."""
        return tuple(f.name for f in dataclasses.fields(self) if getattr(self, f.name))


def plan_effects(scene: Scene) -> Effects:
    """Decide from the scene, before any ray is traced, which effects exist.

    - ``direct_point``: the scene has a directional or point light.
    - ``shadows``: there is a light and at least two objects. One sphere or one plane is convex
      (or flat) and cannot occlude itself; its self-shadowing is exactly the ``max(0, n . l)``
      factor, so a lone object needs no shadow ray.
    - ``environment``: the scene has an :class:`EnvironmentLight`.
    - ``indirect``: ``max_bounces > 0`` and at least two objects (light leaving a lone convex or
      flat object never returns to it, so bounces there contribute nothing).
    """
    n_obj = len(scene.objects)
    has_point = bool(scene.point_lights)
    has_env = scene.environment is not None
    return Effects(
        direct_point=has_point,
        shadows=n_obj >= 2 and (has_point or has_env),
        environment=has_env,
        indirect=scene.max_bounces > 0 and n_obj >= 2,
    )


__all__ = ["Camera", "DirectionalLight", "Effects", "NormalMap", "Plane", "PointLight", "Scene", "Sphere",
           "plan_effects"]
