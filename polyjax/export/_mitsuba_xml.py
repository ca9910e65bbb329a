"""Mitsuba 3 scene files (XML) of a fitted material: ``principled``, ``roughconductor`` or ``roughplastic``, alone
or on the spheres of a polyjax scene under its lights and camera: :func:`mitsuba_xml`."""

from __future__ import annotations

from xml.sax.saxutils import quoteattr

import numpy as np

from .._errors import InputError
from .._files import write_bytes_atomically
from ..render._scene import DirectionalLight, PointLight, Sphere
from ._gltf import _check_path
from ._material import check_material, material_of

_PRINCIPLED = {k: "unit" for k in ("roughness", "metallic", "specular", "spec_tint", "anisotropic", "sheen",
                                   "sheen_tint", "clearcoat", "clearcoat_gloss", "spec_trans", "flatness")}
#: the material dicts accepted: ``{model: (kinds of the accepted keys, required keys)}``
MODELS = {
    "principled": ({"base_color": "rgb", **_PRINCIPLED}, ("base_color", "roughness", "metallic", "specular")),
    "roughconductor": ({"alpha": "positive", "eta": "rgb+", "k": "rgb+"}, ("alpha", "eta", "k")),
    "roughplastic": ({"alpha": "positive", "diffuse_reflectance": "rgb", "int_ior": "ior", "ext_ior": "ior"},
                     ("alpha", "diffuse_reflectance", "int_ior")),
}


def mitsuba_xml(material, path, *, scene=None, material_id: str = "material"):
    """Write a Mitsuba 3 scene file (format version 3.0.0) holding the material as a ``<bsdf>`` with id
    ``material_id``; with ``scene`` (a :class:`polyjax.render.Scene` of spheres, point and directional lights and
    a perspective camera) also its shapes, emitters and sensor, under the conventions that make Mitsuba and polyjax
    agree (``docs/conventions.md``: vertical field of view, pixel centres, box filter, ``direct`` integrator with
    one emitter sample), so that ``mitsuba.load_file(path)`` renders the scene polyjax renders.

    Materials (``baselines.standard_material`` dicts, or a one-material fit whose ``material()`` returns one):

    - ``{"model": "principled", "base_color": [r, g, b], "roughness", "metallic", "specular", "spec_tint",
      "anisotropic", ...}``: Mitsuba's ``principled`` plugin (parameters of the same names, others at 0);
    - ``{"model": "roughconductor", "alpha", "eta": [3], "k": [3]}``: ``roughconductor``;
    - ``{"model": "roughplastic", "alpha", "diffuse_reflectance": [3], "int_ior"}``: ``roughplastic``;

    the last two with ``"distribution": "ggx"`` (the default) or ``"beckmann"``.

    Returns:
        The path written (written whole or not at all).

    Raises:
        InputError: a path not ending in ``.xml`` or in a missing folder, a missing, unknown or out-of-range
            material value, a scene that is not spheres under point or directional lights with a perspective camera.
    """
    path = _check_path(path, (".xml",))
    mat = material_of(material)
    distribution = _distribution(mat)
    mat = check_material("mitsuba_xml", {k: x for k, x in mat.items() if k != "distribution"}, MODELS)
    bsdf = _bsdf_xml(mat, material_id, distribution)
    body = [bsdf] if scene is None else [bsdf] + _scene_xml(scene, material_id)
    text = '<?xml version="1.0" encoding="utf-8"?>\n<scene version="3.0.0">\n' + "\n".join(body) + "\n</scene>\n"
    write_bytes_atomically(path, text.encode())
    return path


def _prop(key: str, value) -> str:
    if isinstance(value, list):
        return f'<rgb name="{key}" value="{", ".join(repr(float(x)) for x in value)}"/>'
    return f'<float name="{key}" value="{float(value)!r}"/>'


def _distribution(mat: dict) -> str:
    """The microfacet distribution of a ``roughconductor`` / ``roughplastic`` dict: ``"ggx"`` unless given."""
    if "distribution" not in mat:
        return "ggx"
    if mat.get("model") not in ("roughconductor", "roughplastic"):
        raise InputError(f"material['distribution']: only roughconductor and roughplastic materials take one, found "
                         f"a {mat.get('model')!r} material")
    if mat["distribution"] not in ("ggx", "beckmann"):
        raise InputError(f"material['distribution']: expected 'ggx' or 'beckmann', found {mat['distribution']!r}")
    return mat["distribution"]


def _bsdf_xml(mat: dict, material_id: str, distribution: str = "ggx") -> str:
    props = [_prop(k, v) for k, v in mat.items() if k != "model"]
    if mat["model"] != "principled":
        props.insert(0, f'<string name="distribution" value="{distribution}"/>')
    inner = "\n".join("        " + p for p in props)
    return f'    <bsdf type="{mat["model"]}" id={quoteattr(material_id)}>\n{inner}\n    </bsdf>'


def _vec(x) -> str:
    return ", ".join(repr(float(c)) for c in np.asarray(x, float).ravel())


def _scene_xml(scene, material_id: str) -> list[str]:
    """The shapes, emitters, sensor and integrator of a polyjax scene (``mitsuba_scene_dict``'s conventions)."""
    cam = scene.camera
    if float(cam.ortho_height) > 0:
        raise InputError("scene: expected a perspective camera (ortho_height = 0) for Mitsuba")
    out = ['    <integrator type="direct">\n        <integer name="emitter_samples" value="1"/>\n'
           '        <integer name="bsdf_samples" value="0"/>\n    </integrator>']
    out.append(
        f'    <sensor type="perspective">\n        <float name="fov" value="{float(cam.fov_deg)!r}"/>\n'
        f'        <string name="fov_axis" value="y"/>\n        <transform name="to_world">\n'
        f'            <lookat origin="{_vec(cam.eye)}" target="{_vec(cam.target)}" up="{_vec(cam.up)}"/>\n'
        f'        </transform>\n        <sampler type="stratified">\n'
        f'            <integer name="sample_count" value="1"/>\n            <boolean name="jitter" value="false"/>\n'
        f'        </sampler>\n        <film type="hdrfilm">\n'
        f'            <integer name="width" value="{cam.width}"/>\n'
        f'            <integer name="height" value="{cam.height}"/>\n'
        f'            <string name="pixel_format" value="rgb"/>\n            <rfilter type="box"/>\n'
        f'        </film>\n    </sensor>')
    for i, obj in enumerate(scene.objects):
        if not isinstance(obj, Sphere):
            raise InputError(f"scene.objects[{i}]: only spheres are written to Mitsuba, found {type(obj).__name__}")
        out.append(f'    <shape type="sphere">\n        <point name="center" value="{_vec(obj.center)}"/>\n'
                   f'        <float name="radius" value="{float(obj.radius)!r}"/>\n'
                   f'        <ref id={quoteattr(material_id)}/>\n    </shape>')
    for i, light in enumerate(scene.lights):
        if isinstance(light, PointLight):
            out.append(f'    <emitter type="point">\n        <point name="position" value="{_vec(light.position)}"/>\n'
                       f'        <rgb name="intensity" value="{_vec(light.intensity)}"/>\n    </emitter>')
        elif isinstance(light, DirectionalLight):
            out.append(f'    <emitter type="directional">\n'
                       f'        <vector name="direction" value="{_vec(-np.asarray(light.direction, float))}"/>\n'
                       f'        <rgb name="irradiance" value="{_vec(light.irradiance)}"/>\n    </emitter>')
        else:
            raise InputError(f"scene.lights[{i}]: only point and directional lights are written to Mitsuba, "
                             f"found {type(light).__name__}")
    return out
