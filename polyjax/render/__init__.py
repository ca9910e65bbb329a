"""Rendering BRDFs: spheres, planes and lights, computing only the effects a scene needs.

Any BRDF renders through one protocol, a callable ``f(u, v) -> (..., 3)`` (light ``u``, view
``v``, local frame with normal ``+z``): fitted :class:`polyjax.PolynomialBRDF` s (via
:func:`rgb_brdf`), measured samples (:class:`TabulatedBRDF`), analytic BRDFs
(:class:`Lambertian`, :class:`Phong`) and ``polyjax.data.NeuralBRDF``. Every one of them can be
importance-sampled (:func:`importance_sampler`).

Typical use::

    scene = Scene(Camera(width=256, height=256), [Sphere(rgb_brdf(model))], [PointLight()])
    result = render(scene)          # result.effects says what was computed
    write_exr("sphere.exr", result.image); write_png("sphere.png", result.image)
"""

from ._brdf import BRDF, ChannelsFirst, Lambertian, Phong, SwapUV, TabulatedBRDF, evaluate_rgb, rgb_brdf
from ._envmap import EnvironmentLight, load_envmap, procedural_sky, sample_pool
from ._grid import GridResult, render_grid, sphere_scene
from ._image import comparison_figure, difference_images, mosaic, read_exr, to_srgb, write_exr, write_png
from ._integrator import RenderResult, cast_floats, render
from ._sampling import ImportanceSampler, importance_sampler
from ._scene import Camera, DirectionalLight, Effects, Plane, PointLight, Scene, Sphere, plan_effects

__all__ = [
    "BRDF", "Camera", "ChannelsFirst", "DirectionalLight", "Effects", "EnvironmentLight", "GridResult", "Lambertian",
    "Phong", "Plane", "PointLight", "RenderResult", "Scene", "Sphere", "SwapUV", "TabulatedBRDF", "cast_floats",
    "comparison_figure", "difference_images", "evaluate_rgb", "load_envmap", "mosaic", "plan_effects",
    "procedural_sky", "read_exr", "sample_pool", "render", "render_grid", "rgb_brdf", "sphere_scene", "to_srgb", "write_exr",
    "write_png", "ImportanceSampler", "importance_sampler",
]
