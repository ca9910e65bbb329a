"""Exports of standard materials: glTF 2.0 (``.gltf``, ``.glb``) checked by the Khronos ``gltf-validator``, and
Mitsuba 3 scene files loaded and rendered by Mitsuba next to polyjax's render of the same model.

The validator is the npm package ``gltf-validator``, found in the ``node_modules`` folder named by
``POLYJAX_NODE_MODULES`` (default: ``.ci/node/node_modules`` of the repository, where CI installs it)."""

import json
import struct
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import baselines as bl
import polyjax as pj
import polyjax.render as pr

ROOT = Path(__file__).resolve().parents[1]
COLOURS = [0.2, 0.5, 0.8]
GLTF = {"model": "gltf-pbr", "baseColorFactor": COLOURS, "metallicFactor": 0.3, "roughnessFactor": 0.4}
SPECULAR = dict(GLTF, model="gltf-pbr-specular", specularFactor=0.7, specularColorFactor=[1.0, 1.0, 1.0], ior=1.6)
ANISOTROPIC = dict(GLTF, model="gltf-pbr-anisotropic", anisotropyStrength=0.5, anisotropyRotation=0.7)



def _fit_of(name, params):
    """A one-material :class:`baselines.BaselineFit` holding ``params (3, P)``."""
    p = jnp.asarray(params, float)
    z = jnp.zeros((3,), jnp.int32)
    return bl.BaselineFit(params=p, raw=p, l2=jnp.zeros(3), status=z, steps=z, success=z == 0,
                          start_l2=jnp.zeros((3, 1)), start_status=z[:, None], best_start=z,
                          at_limit=jnp.zeros(p.shape, bool), name=name)


def _read_gltf(path: Path) -> dict:
    data = path.read_bytes()
    if path.suffix == ".glb":
        magic, version, length = struct.unpack("<III", data[:12])
        assert (magic, version, length) == (0x46546C67, 2, len(data))
        n, kind = struct.unpack("<II", data[12:20])
        assert kind == 0x4E4F534A
        return json.loads(data[20:20 + n])
    return json.loads(data)


@pytest.mark.parametrize("material, suffix, sphere", [
    (GLTF, ".glb", True), (GLTF, ".gltf", True), (SPECULAR, ".glb", True), (ANISOTROPIC, ".gltf", True),
    (SPECULAR, ".gltf", False),
])
def test_gltf_passes_the_khronos_validator(validator, tmp_path, material, suffix, sphere):
    path = pj.export.gltf(material, tmp_path / f"m{suffix}", sphere=sphere, segments=24, rings=12)
    issues = validator(path)
    assert issues["numErrors"] == 0 and issues["numWarnings"] == 0, issues["messages"]
    doc = _read_gltf(path)
    mat = doc["materials"][0]
    pbr = mat["pbrMetallicRoughness"]
    assert pbr["baseColorFactor"] == COLOURS + [1.0]
    assert (pbr["metallicFactor"], pbr["roughnessFactor"]) == (0.3, 0.4)
    used = sorted(mat.get("extensions", {}))
    assert doc.get("extensionsUsed", []) == used
    if material is SPECULAR:
        assert used == ["KHR_materials_ior", "KHR_materials_specular"]
        assert mat["extensions"]["KHR_materials_ior"]["ior"] == 1.6
    if material is ANISOTROPIC:
        assert mat["extensions"]["KHR_materials_anisotropy"] == {"anisotropyStrength": 0.5, "anisotropyRotation": 0.7}
        assert "TANGENT" in doc["meshes"][0]["primitives"][0]["attributes"]
    assert ("meshes" in doc) == sphere


def test_gltf_of_a_fit_names_its_parameters(tmp_path):
    fit = _fit_of("gltf-pbr", [[c, 0.3, 0.4] for c in COLOURS])
    doc = _read_gltf(pj.export.gltf(fit, tmp_path / "fit.gltf", sphere=False))
    assert doc["materials"][0]["pbrMetallicRoughness"] == {"baseColorFactor": COLOURS + [1.0], "metallicFactor": 0.3,
                                                           "roughnessFactor": 0.4}


@pytest.mark.parametrize("material, path, match", [
    ({k: v for k, v in GLTF.items() if k != "roughnessFactor"}, "m.glb", r"has no 'roughnessFactor'"),
    (dict(GLTF, metallicFactor=1.5), "m.glb",
     r"gltf: material\['metallicFactor'\] = 1.5: expected a finite value \[0, 1\]"),
    (dict(GLTF, baseColorFactor=[0.1, 0.2]), "m.glb", r"expected three values \[r, g, b\]"),
    (dict(GLTF, ior=0.5), "m.glb", r"material\['ior'\] = 0.5: expected a finite value >= 1"),
    (dict(GLTF, shininess=3.0), "m.glb", r"unknown material inputs \['shininess'\]"),
    (dict(GLTF, model="openpbr"), "m.glb", r"material\['model'\] = 'openpbr': expected one of"),
    (GLTF, "m.obj", r"path: expected a file ending in .gltf or .glb"),
    (GLTF, "missing/m.glb", r"path: the folder .* does not exist"),
    ("gltf-pbr", "m.glb", r"material: expected a standard material dict"),
])
def test_gltf_bad_material_or_path_writes_nothing(tmp_path, material, path, match):
    with pytest.raises(pj.InputError, match=match):
        pj.export.gltf(material, tmp_path / path)
    assert list(tmp_path.iterdir()) == []


# --- Mitsuba XML --------------------------------------------------------------------------------------------------


def _scene(brdf, size=48, light=None):
    """A unit sphere seen from distance 5 under one light (Mitsuba's ``direct`` integrator picks one emitter per
    sample: with one sample per pixel, one light for an exact comparison)."""
    cam = pr.Camera(eye=(0.0, 0.0, 5.0), width=size, height=size, fov_deg=30.0)
    return pr.Scene(cam, [pr.Sphere(brdf)], [light or pr.PointLight((3.0, 2.0, 4.0), 30.0)])


def _mitsuba_render(path):
    mi = pytest.importorskip("mitsuba")
    mi.set_variant("scalar_rgb")
    return np.asarray(mi.render(mi.load_file(str(path))), float)


def test_mitsuba_xml_principled_renders_as_polyjax(tmp_path):
    """The fitted principled model's file rendered by Mitsuba against polyjax's render of the same fit."""
    fit = _fit_of("principled", [[c, 0.35, 0.4, 0.6] for c in COLOURS])
    scene = _scene(fit)
    path = pj.export.mitsuba_xml(fit, tmp_path / "principled.xml", scene=scene)
    theirs = _mitsuba_render(path)
    ours = np.asarray(pr.render(scene, dtype=jnp.float64).image)
    assert theirs.max() > 0.1
    assert float(pj.psnr(ours, theirs)) >= 40.0  # measured: 142.7 dB (float32 rounding in Mitsuba)


def test_mitsuba_xml_roughplastic_and_roughconductor(tmp_path):
    from polyjax.render import mitsuba_roughplastic

    model, _ = mitsuba_roughplastic(0.2, COLOURS, int_ior=1.5)
    material = {"model": "roughplastic", "alpha": 0.2, "diffuse_reflectance": COLOURS, "int_ior": 1.5}
    scene = _scene(model)
    theirs = _mitsuba_render(pj.export.mitsuba_xml(material, tmp_path / "plastic.xml", scene=scene))
    assert float(pj.psnr(np.asarray(pr.render(scene, dtype=jnp.float64).image), theirs)) >= 40.0
    metal = {"model": "roughconductor", "alpha": 0.3, "eta": [0.2, 0.9, 1.1], "k": [3.9, 2.4, 2.2]}
    sun = _scene(model, light=pr.DirectionalLight((-1.0, 1.0, 1.0), 2.0))
    img = _mitsuba_render(pj.export.mitsuba_xml(metal, tmp_path / "metal.xml", scene=sun))
    assert np.all(np.isfinite(img)) and img.max() > 0.05
    alone = pj.export.mitsuba_xml(metal, tmp_path / "alone.xml")
    assert '<bsdf type="roughconductor" id="material">' in alone.read_text()
    pytest.importorskip("mitsuba").load_file(str(alone))


@pytest.mark.parametrize("material, match", [
    ({"model": "principled", "base_color": COLOURS, "roughness": 0.3, "metallic": 0.1}, r"has no 'specular'"),
    ({"model": "roughconductor", "alpha": -0.1, "eta": [1, 1, 1], "k": [1, 1, 1]},
     r"'alpha'\] = -0.1: expected a finite value > 0"),
    ({"model": "roughplastic", "alpha": 0.1, "diffuse_reflectance": COLOURS, "int_ior": float("nan")},
     r"'int_ior'\] = nan: expected a finite value >= 1"),
])
def test_mitsuba_xml_bad_material_writes_nothing(tmp_path, material, match):
    with pytest.raises(pj.InputError, match=match):
        pj.export.mitsuba_xml(material, tmp_path / "m.xml")
    with pytest.raises(pj.InputError, match=r"path: expected a file ending in .xml"):
        pj.export.mitsuba_xml({"model": "roughconductor", "alpha": 0.1, "eta": [1] * 3, "k": [1] * 3}, tmp_path / "m")
    assert list(tmp_path.iterdir()) == []
