"""The same scene in Mitsuba 3: polyjax's camera, spheres and point/directional lights as a Mitsuba scene.

Mitsuba 3 (``pip install "polyjax[mitsuba]"``) is an optional reference renderer. The conventions
that make the two renderers agree (``docs/conventions.md``):

- **Field of view**: polyjax's ``fov_deg`` is vertical; Mitsuba's ``fov`` is along ``fov_axis``
  (default ``"x"``), so the scene is written with ``fov_axis="y"``.
- **Pixel centres**: polyjax traces one ray through each pixel centre; Mitsuba integrates over
  the pixel with its reconstruction filter. ``pixel_centres=True`` (default) makes Mitsuba do
  the same: a box filter and the ``stratified`` sampler without jitter at one sample per pixel.
  With ``pixel_centres=False`` Mitsuba averages ``spp`` jittered samples over each pixel (box
  filter): pixels on the silhouette then mix object and background.
- **Point lights**: both take the radiant intensity ``I`` (W/sr): irradiance ``I cos / r^2``.
  Directional lights: polyjax's ``direction`` points towards the light, Mitsuba's along the
  light's travel, so it is negated; both take the irradiance on a surface facing the light.
- **BRDF vs BSDF**: Mitsuba's ``eval`` returns ``f cos(theta_o)`` (the cosine of the direction
  towards the light); polyjax's BRDFs return ``f``.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import InputError
from ._envmap import EnvironmentLight
from ._scene import DirectionalLight, PointLight, Scene, Sphere


def mitsuba_scene_dict(scene: Scene, bsdf: dict, *, pixel_centres: bool = True, spp: int = 1,
                       integrator: dict | None = None) -> dict:
    """A Mitsuba 3 scene dictionary (for ``mitsuba.load_dict``) of a polyjax scene.

    Args:
        scene: a :class:`Scene` of spheres lit by point and directional lights, perspective camera.
        bsdf: the Mitsuba BSDF dictionary given to every sphere (e.g. ``{"type": "diffuse", ...}``).
        pixel_centres: one sample at each pixel centre (polyjax's convention), else ``spp`` jittered samples.
        spp: samples per pixel when ``pixel_centres`` is False.
        integrator: Mitsuba integrator (default: ``direct`` with one emitter sample, no BSDF sample,
            which is exact for point and directional lights).

    Raises:
        InputError: the scene has planes, an environment map, or an orthographic camera.
    """
    cam = scene.camera
    if float(cam.ortho_height) > 0:
        raise InputError("scene: expected a perspective camera (ortho_height = 0) for Mitsuba")
    shapes = {}
    for i, obj in enumerate(scene.objects):
        if not isinstance(obj, Sphere):
            raise InputError(f"scene.objects[{i}]: only spheres are converted to Mitsuba, found {type(obj).__name__}")
        shapes[f"sphere{i}"] = {"type": "sphere", "center": np.asarray(obj.center, float).tolist(),
                                "radius": float(obj.radius), "bsdf": dict(bsdf)}
    lights = {}
    for i, light in enumerate(scene.lights):
        if isinstance(light, PointLight):
            lights[f"light{i}"] = {"type": "point", "position": np.asarray(light.position, float).tolist(),
                                   "intensity": {"type": "rgb", "value": np.asarray(light.intensity, float).tolist()}}
        elif isinstance(light, DirectionalLight):
            lights[f"light{i}"] = {"type": "directional", "direction": (-np.asarray(light.direction, float)).tolist(),
                                   "irradiance": {"type": "rgb", "value": np.asarray(light.irradiance, float).tolist()}}
        elif isinstance(light, EnvironmentLight):
            raise InputError(f"scene.lights[{i}]: environment maps are not converted to Mitsuba")
    import mitsuba as mi  # optional (the "mitsuba" extra): imported where used

    sampler = ({"type": "stratified", "sample_count": 1, "jitter": False} if pixel_centres
               else {"type": "independent", "sample_count": int(spp)})
    sensor = {
        "type": "perspective", "fov": float(cam.fov_deg), "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=np.asarray(cam.eye, float).tolist(),
                                                   target=np.asarray(cam.target, float).tolist(),
                                                   up=np.asarray(cam.up, float).tolist()),
        "film": {"type": "hdrfilm", "width": cam.width, "height": cam.height, "rfilter": {"type": "box"},
                 "pixel_format": "rgb"},
        "sampler": sampler,
    }
    integrator = integrator or {"type": "direct", "emitter_samples": 1, "bsdf_samples": 0}
    return {"type": "scene", "integrator": integrator, "sensor": sensor, **shapes, **lights}


def render_mitsuba(scene: Scene, bsdf: dict, *, variant: str = "scalar_rgb", seed: int = 0, **options) -> np.ndarray:
    """Render a polyjax scene with Mitsuba 3 (:func:`mitsuba_scene_dict`): ``(H, W, 3)`` linear RGB, float64."""
    import mitsuba as mi  # optional (the "mitsuba" extra): imported where used

    mi.set_variant(variant)
    return np.asarray(mi.render(mi.load_dict(mitsuba_scene_dict(scene, bsdf, **options)), seed=seed), dtype=np.float64)




_TABLE_RES = 64  # Mitsuba's MI_ROUGH_TRANSMITTANCE_RES: its diffuse transmittance table, linear in cos(theta)


class RoughPlastic(eqx.Module):
    r"""Mitsuba 3's ``roughplastic`` BSDF (GGX, ``nonlinear=false``) as a polyjax BRDF ``f(u, v)``.

    .. math::
        f(u, v) = \frac{F(u \cdot h, \eta)\, D(h)\, G_1(u, h)\, G_1(v, h)}{4 \cos\theta_u \cos\theta_v}
                  + g(\cos\theta_u)\, g(\cos\theta_v),

    ``D`` the GGX distribution of roughness ``alpha``, ``G_1`` its Smith shadowing (separable form),
    ``F`` the unpolarised Fresnel reflectance of a dielectric of relative index ``eta``. The diffuse term
    is Mitsuba's ``rho / (1 - F_dr) / (pi eta^2) T(cos theta_u) T(cos theta_v)``, written
    ``g(mu_u) g(mu_v)`` with ``g`` per channel tabulated at Mitsuba's 64 nodes ``mu_i = i / 63`` and
    linearly interpolated, like Mitsuba's own table (:func:`mitsuba_roughplastic` reads it from Mitsuba).
    Differentiable with respect to ``alpha``, ``eta`` and the table.

    Attributes:
        alpha: GGX roughness; eta: relative index of refraction; table: ``(64, 3)`` values of ``g``.
    """

    alpha: Float[Array, ""]
    eta: Float[Array, ""]
    table: Float[Array, "r 3"]

    def __call__(self, u: Array, v: Array) -> Float[Array, "... 3"]:
        u, v = jnp.broadcast_arrays(u, v)
        cu, cv = u[..., 2], v[..., 2]
        above = (cu > 0) & (cv > 0)
        cu_s, cv_s = jnp.where(above, cu, 1.0), jnp.where(above, cv, 1.0)
        s = u + v
        h = s / jnp.sqrt(jnp.maximum(jnp.sum(s * s, -1, keepdims=True), 1e-300))
        a2 = self.alpha**2
        ch = h[..., 2]
        d = a2 / (jnp.pi * (ch * ch * (a2 - 1.0) + 1.0) ** 2)

        def g1(w, cw):
            t2 = jnp.maximum(1.0 - cw * cw, 0.0) / (cw * cw)
            ok = jnp.sum(w * h, -1) * cw > 0
            return jnp.where(ok, 2.0 / (1.0 + jnp.sqrt(1.0 + a2 * t2)), 0.0)

        spec = _fresnel(jnp.sum(u * h, -1), self.eta) * d * g1(u, cu_s) * g1(v, cv_s) / (4.0 * cu_s * cv_s)
        diff = _lerp(self.table, cu_s) * _lerp(self.table, cv_s)
        return jnp.where(above[..., None], spec[..., None] + diff, 0.0)


def _lerp(table, mu):
    """Linear interpolation of ``table (r, 3)`` at ``mu`` in [0, 1] (nodes ``i / (r - 1)``)."""
    r = table.shape[0]
    x = jnp.clip(mu, 0.0, 1.0) * (r - 1)
    i = jnp.clip(jnp.floor(x).astype(jnp.int32), 0, r - 2)
    w = (x - i)[..., None]
    return (1.0 - w) * table[i] + w * table[i + 1]


def _fresnel(cos_i, eta):
    """Unpolarised Fresnel reflectance of a dielectric interface (relative index ``eta``, from outside)."""
    c = jnp.clip(cos_i, 0.0, 1.0)
    s2t = (1.0 - c * c) / (eta * eta)
    ct = jnp.sqrt(jnp.maximum(1.0 - s2t, 0.0))
    rs = (c - eta * ct) / (c + eta * ct)
    rp = (eta * c - ct) / (eta * c + ct)
    return jnp.where(s2t >= 1.0, 1.0, 0.5 * (rs * rs + rp * rp))


def mitsuba_bsdf_eval(bsdf: dict, u, v, variant: str = "scalar_rgb") -> np.ndarray:
    """Mitsuba's own BRDF ``f(u, v)`` (its ``eval`` divided by ``cos theta_u``) at local directions ``(n, 3)``."""
    import mitsuba as mi  # optional (the "mitsuba" extra): imported where used

    mi.set_variant(variant)
    b = mi.load_dict(dict(bsdf))
    ctx = mi.BSDFContext()
    si = mi.SurfaceInteraction3f()
    si.sh_frame = mi.Frame3f(mi.Vector3f(0.0, 0.0, 1.0))
    out = []
    for ui, vi in zip(np.asarray(u, float), np.asarray(v, float)):
        si.wi = mi.Vector3f(*vi)
        out.append(np.asarray(b.eval(ctx, si, mi.Vector3f(*ui)), float) / max(ui[2], 1e-300))
    return np.asarray(out)


def mitsuba_roughplastic(alpha: float = 0.1, diffuse=0.5, int_ior: float = 1.49, ext_ior: float = 1.000277):
    """A :class:`RoughPlastic` equal to Mitsuba's ``roughplastic`` (GGX) with these parameters, and its dictionary.

    The diffuse table ``g`` is read from Mitsuba's own evaluation of the BSDF with the specular term
    switched off (``specular_reflectance = 0``): ``f(mu, 1) = g(mu) g(1)``, ``f(1, 1) = g(1)^2``, at
    the nodes of Mitsuba's transmittance table (Mitsuba computes it by quadrature when the BSDF is loaded).

    Returns:
        ``(RoughPlastic, bsdf_dict)``.
    """
    rgb = np.broadcast_to(np.asarray(diffuse, float), (3,)).tolist()
    bsdf = {"type": "roughplastic", "distribution": "ggx", "alpha": float(alpha), "int_ior": float(int_ior),
            "ext_ior": float(ext_ior), "diffuse_reflectance": {"type": "rgb", "value": rgb}}
    mu = np.maximum(np.linspace(0.0, 1.0, _TABLE_RES), 1e-6)
    u = np.stack([np.sqrt(1 - mu * mu), np.zeros_like(mu), mu], -1)
    n = np.tile([0.0, 0.0, 1.0], (_TABLE_RES, 1))
    f = mitsuba_bsdf_eval({**bsdf, "specular_reflectance": 0.0}, u, n)
    table = f / np.sqrt(f[-1:])
    model = RoughPlastic(jnp.asarray(float(alpha)), jnp.asarray(float(int_ior) / float(ext_ior)), jnp.asarray(table))
    return model, bsdf


__all__ = ["RoughPlastic", "mitsuba_bsdf_eval", "mitsuba_roughplastic", "mitsuba_scene_dict", "render_mitsuba"]
