"""Rendering BRDFs: spheres, planes and lights, computing only the effects a scene needs.

Any BRDF renders through one protocol, a callable ``f(u, v) -> (..., 3)`` (light ``u``, view
``v``, local frame with normal ``+z``): fitted :class:`polyjax.PolynomialBRDF` s (via
:func:`rgb_brdf`), measured samples (:class:`TabulatedBRDF`), analytic BRDFs
(:class:`Lambertian`, :class:`Phong`, :class:`ParametricBRDF`) and ``polyjax.data.NeuralBRDF``.

Scenes can be built inside ``jit``/``grad``; renders differentiate with respect to BRDF parameters,
lights and environment texels (:mod:`polyjax.render._integrator`). :func:`light_samples` writes a
render as a linear function of one object's BRDF (behind ``polyjax.fit_polynomial_to_images``);
:func:`render_mitsuba` renders the same scene with Mitsuba 3 (optional, ``docs/conventions.md``). Every BRDF can be
importance-sampled (:func:`importance_sampler`), on the area-preserving map of the unit square to the hemisphere
whose square its tables cover (:func:`square_to_hemisphere`, :func:`hemisphere_to_square`; :func:`cosine_sample` draws
cosine-weighted directions on it).

Typical use::

    scene = Scene(Camera(width=256, height=256), [Sphere(rgb_brdf(model))], [PointLight()])
    result = render(scene)          # result.effects says what was computed
    write_exr("sphere.exr", result.image); write_png("sphere.png", result.image)
"""

from ._brdf import BRDF, ChannelsFirst, Lambertian, ParametricBRDF, Phong, SwapUV, TabulatedBRDF, evaluate_rgb, rgb_brdf
from ._envmap import EnvironmentLight, load_envmap, pool_indices, procedural_sky, sample_pool
from ._grid import GridResult, render_grid, sphere_scene
from ._image import difference_images, mosaic, read_exr, to_srgb, write_exr, write_png
from ._integrator import RenderResult, cast_floats, render
from ._linear import LightSamples, light_samples, render_linear
from ._mitsuba import RoughPlastic, mitsuba_bsdf_eval, mitsuba_roughplastic, mitsuba_scene_dict, render_mitsuba
from ._sampling import ImportanceSampler, cosine_sample, hemisphere_to_square, importance_sampler, square_to_hemisphere
from ._scene import Camera, DirectionalLight, Effects, NormalMap, Plane, PointLight, Scene, Sphere, plan_effects

__all__ = [
    "BRDF", "Camera", "ChannelsFirst", "DirectionalLight", "Effects", "EnvironmentLight", "GridResult", "Lambertian",
    "LightSamples", "ParametricBRDF", "Phong", "Plane", "PointLight", "RenderResult", "RoughPlastic", "Scene", "Sphere",
    "SwapUV", "TabulatedBRDF", "cast_floats", "comparison_figure", "difference_images", "evaluate_rgb",
    "light_samples", "load_envmap", "mitsuba_bsdf_eval", "mitsuba_roughplastic", "mitsuba_scene_dict", "mosaic",
    "plan_effects", "pool_indices", "procedural_sky", "read_exr", "render", "render_grid", "render_linear",
    "render_mitsuba", "rgb_brdf", "sample_pool", "sphere_scene", "to_srgb", "write_exr", "write_png",
    "ImportanceSampler", "importance_sampler", "NormalMap",
    "cosine_sample", "hemisphere_to_square", "square_to_hemisphere",
]


def __getattr__(name):
    if name == "comparison_figure":  # the lazy package face: matplotlib only when a figure is drawn
        from ._figure import comparison_figure

        globals()[name] = comparison_figure
        return comparison_figure
    raise AttributeError(f"module 'polyjax.render' has no attribute {name!r}")
