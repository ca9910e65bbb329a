"""The MaterialX (OpenPBR, Standard Surface) and USD (UsdPreviewSurface) exporters: the files through the formats' own
tools (MaterialX's document validation and GLSL generator, ``glslangValidator``; usd-core's stage and its
validators), and the files read back describe exactly the exported material (the specification's BRDF at the
file's inputs equals the fit's values)."""

import functools
import shutil
import subprocess

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from _standard_problems import STANDARD_PARAMS, grey_fit

import baselines as bl
import polyjax as pj
from baselines import open_pbr_surface, usd_preview_surface

from _baseline_problems import synthetic_geometry

mx = pytest.importorskip("MaterialX", reason="the MaterialX exporter's tests need MaterialX (polyjax[materialx])")
pxr = pytest.importorskip("pxr", reason="the USD exporter's tests need usd-core (polyjax[usd])")
from pxr import Sdf, Usd, UsdShade, UsdValidation  # noqa: E402


def _coloured(name: str, colours: dict) -> np.ndarray:
    """``(3, P)`` parameters of ``name``: the known ones, with the given colours per channel."""
    m = bl.get_model(name)
    p = np.tile(np.asarray(STANDARD_PARAMS[name], float), (3, 1))
    for k, rgb in colours.items():
        p[:, m.param_names.index(k)] = rgb
    return p


def _library():
    lib = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), lib)
    return lib


def _read_mtlx(path):
    doc = mx.createDocument()
    mx.readFromXmlFile(doc, str(path))
    doc.importLibrary(_library())
    return doc


def _inputs(node) -> dict:
    """A shader node's inputs as written: floats, colours as numpy ``(3,)``, at full precision."""
    out = {}
    for inp in node.getInputs():
        vals = [float(x) for x in inp.getValueString().split(",")]
        out[inp.getName()] = np.asarray(vals) if inp.getType() == "color3" else vals[0]
    return out


def _channel(inputs: dict, c: int) -> dict:
    return {k: (x[c] if isinstance(x, np.ndarray) else x) for k, x in inputs.items()}


def _check_mtlx_describes(path, name, params, u, v):
    doc = _read_mtlx(path)
    ok, message = doc.validate()
    assert ok, message
    assert doc.getNode("M_fitted_openpbr").getType() == "material"
    assert doc.getNode("SR_fitted_standard_surface").getCategory() == "standard_surface"
    written = _inputs(doc.getNode("SR_fitted_openpbr"))
    m = bl.get_model(name)
    for c in range(3):
        ours = np.asarray(jax.jit(open_pbr_surface)(_channel(written, c), u, v))
        np.testing.assert_allclose(ours, np.asarray(jax.jit(m.evaluate)(jnp.asarray(params[c]), u, v)), rtol=1e-13)
    return doc


@pytest.mark.slow  # the OpenPBR fit of the slow parameter-recovery test (about 35 CPU-seconds)
def test_materialx_file_validates_and_describes_the_fit(tmp_path):
    u, v, values, fit = grey_fit("openpbr")
    material = bl.get_model("openpbr").to_material(fit.params)
    path = pj.export.materialx(material, tmp_path / "fit.mtlx")
    _check_mtlx_describes(path, "openpbr", np.asarray(fit.params), u, v)
    np.testing.assert_allclose(bl.get_model("openpbr").evaluate(fit.params[0], u, v), values[0], atol=1e-6)


@pytest.mark.parametrize("name", ["openpbr-coat", "openpbr-anisotropic"])
def test_materialx_coloured_materials_round_trip(tmp_path, name):
    u, v = (jnp.asarray(a) for a in synthetic_geometry(60, seed=4))
    params = _coloured(name, {"base_color": [0.7, 0.4, 0.1], "specular_color": [0.9, 0.8, 0.6]})
    path = pj.export.materialx(bl.get_model(name).to_material(params), tmp_path / "c.mtlx")
    doc = _check_mtlx_describes(path, name, params, u, v)
    std = _inputs(doc.getNode("SR_fitted_standard_surface"))
    if name == "openpbr-coat":  # MaterialX's translation: roughness from the coat, base colour darkened by it
        assert std["coat"] == 1.0 and std["specular_roughness"] == pytest.approx(params[0, 6])
        assert np.all(std["base_color"] < params[:, 0])
    else:
        assert std["specular_anisotropy"] == pytest.approx(params[0, 6]) and "coat" not in std


@pytest.fixture(scope="module")
def glsl_sources(tmp_path_factory):
    """MaterialX's GLSL generator's pixel and vertex shaders for both materials of an exported OpenPBR coat."""
    from MaterialX import PyMaterialXGenGlsl as mx_gen_glsl
    from MaterialX import PyMaterialXGenShader as mx_gen_shader

    folder = tmp_path_factory.mktemp("glsl")
    params = _coloured("openpbr-coat", {"base_color": [0.7, 0.4, 0.1]})
    doc = _read_mtlx(pj.export.materialx(bl.get_model("openpbr-coat").to_material(params), folder / "m.mtlx"))
    gen = mx_gen_glsl.GlslShaderGenerator.create()
    ctx = mx_gen_shader.GenContext(gen)
    ctx.registerSourceCodeSearchPath(mx.getDefaultDataSearchPath())
    files = []
    for mat in ("M_fitted_openpbr", "M_fitted_standard_surface"):
        shader = gen.generate(mat, doc.getNode(mat), ctx)
        for stage, ext in ((mx_gen_shader.PIXEL_STAGE, "frag"), (mx_gen_shader.VERTEX_STAGE, "vert")):
            files.append(folder / f"{mat}.{ext}")
            files[-1].write_text(shader.getSourceCode(stage))
    return files


@pytest.mark.skipif(shutil.which("glslangValidator") is None, reason="needs glslangValidator (glslang-tools)")
def test_materialx_glsl_shaders_compile(glsl_sources, tmp_path):
    for f in glsl_sources:
        src = f.read_text()
        assert "mx_generalized_schlick_bsdf" in src or f.suffix == ".vert" or "standard_surface" in f.name
        run = subprocess.run(["glslangValidator", str(f)], capture_output=True, text=True, timeout=120)
        assert run.returncode == 0, run.stdout + run.stderr
    broken = tmp_path / "broken.frag"  # the check can fail
    broken.write_text("#version 400\nvoid main() { undefined_name = 1.0; }\n")
    assert subprocess.run(["glslangValidator", str(broken)], capture_output=True, timeout=60).returncode != 0


def _usd_errors(stage) -> list:
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    errors = UsdValidation.ValidationContext(validators).Validate(stage)
    return [f"{e.GetName()}: {e.GetMessage()}" for e in errors]


def _usd_preview(workflow: int, inputs, u, v):
    return usd_preview_surface(dict(inputs, useSpecularWorkflow=workflow), u, v)


def _check_usda_describes(path, name, params, u, v):
    stage = Usd.Stage.Open(str(path))
    assert stage and _usd_errors(stage) == []
    assert stage.GetDefaultPrim().GetPath() == Sdf.Path("/Root")
    shader = UsdShade.Shader.Get(stage, "/Root/Materials/Fitted/PreviewSurface")
    assert shader.GetIdAttr().Get() == "UsdPreviewSurface"
    bound = UsdShade.MaterialBindingAPI(stage.GetPrimAtPath("/Root/Sphere")).ComputeBoundMaterial()[0]
    assert bound.GetPath() == Sdf.Path("/Root/Materials/Fitted")
    written = {i.GetBaseName(): i.Get() for i in shader.GetInputs()}
    written = {k: np.asarray(x, float) if hasattr(x, "__len__") else x for k, x in written.items()}
    m = bl.get_model(name)
    for c in range(3):  # the file holds float32 values
        inputs = _channel(written, c)
        workflow = inputs.pop("useSpecularWorkflow")
        ours = np.asarray(jax.jit(functools.partial(_usd_preview, int(workflow)))(inputs, u, v))
        np.testing.assert_allclose(ours, np.asarray(jax.jit(m.evaluate)(jnp.asarray(params[c]), u, v)), rtol=2e-6)


def test_usd_stage_validates_and_describes_the_fit(tmp_path):
    u, v, values, fit = grey_fit("usd-preview")
    path = pj.export.usd(bl.get_model("usd-preview").to_material(fit.params), tmp_path / "fit.usda")
    _check_usda_describes(path, "usd-preview", np.asarray(fit.params), u, v)


@pytest.mark.parametrize("name", ["usd-preview-specular", "usd-preview-clearcoat"])
def test_usd_coloured_materials_round_trip(tmp_path, name):
    u, v = (jnp.asarray(a) for a in synthetic_geometry(60, seed=4))
    colours = {"diffuseColor": [0.7, 0.4, 0.1]}
    if name == "usd-preview-specular":
        colours["specularColor"] = [0.3, 0.2, 0.05]
    params = _coloured(name, colours)
    _check_usda_describes(pj.export.usd(bl.get_model(name).to_material(params), tmp_path / "c.usda"), name, params,
                          u, v)


def test_usd_validators_catch_a_mistyped_input(tmp_path):
    """The validation can fail: a UsdPreviewSurface input authored as double is reported."""
    material = bl.get_model("usd-preview").to_material(_coloured("usd-preview", {}))
    stage = Usd.Stage.Open(str(pj.export.usd(material, tmp_path / "ok.usda", sphere=False)))
    shader = UsdShade.Shader.Get(stage, "/Root/Materials/Fitted/PreviewSurface")
    shader.GetPrim().RemoveProperty("inputs:roughness")
    shader.GetPrim().CreateAttribute("inputs:roughness", Sdf.ValueTypeNames.Double).Set(0.5)
    assert any("roughness" in e for e in _usd_errors(stage)), _usd_errors(stage)
    assert not stage.GetPrimAtPath("/Root/Sphere")


def test_bad_materials_and_paths_give_clear_errors(tmp_path):
    openpbr = bl.get_model("openpbr").to_material(_coloured("openpbr", {}))
    preview = bl.get_model("usd-preview").to_material(_coloured("usd-preview", {}))
    cases = [
        (pj.export.materialx, {k: x for k, x in openpbr.items() if k != "specular_ior"}, "no 'specular_ior'"),
        (pj.export.materialx, dict(openpbr, specular_ior=0.5), r"specular_ior'\] = 0.5: expected a finite value >= 1"),
        (pj.export.materialx, dict(openpbr, base_color=[0.1, 1.2, 0.3]), r"base_color.*three values \[r, g, b\]"),
        (pj.export.materialx, dict(openpbr, sheen=1.0), r"unknown material inputs \['sheen'\]"),
        (pj.export.materialx, preview, "UsdPreviewSurface: it has no exact OpenPBR form; write it with pj.export.usd"),
        (pj.export.usd, openpbr, "OpenPBR Surface: it has no exact UsdPreviewSurface form"),
        (pj.export.usd, dict(preview, useSpecularWorkflow=0.5), "expected 0 or 1"),
        (pj.export.usd, dict(preview, roughness=float("nan")), r"roughness'\] = nan: expected a finite value"),
        (pj.export.usd, dict(preview, model="gltf-pbr"), r"material\['model'\] = 'gltf-pbr': expected one of"),
        (pj.export.usd, [1, 2], "expected a material dict"),
    ]
    for write, material, match in cases:
        with pytest.raises(pj.InputError, match=match):
            write(material, tmp_path / ("m.mtlx" if write is pj.export.materialx else "m.usda"))
    with pytest.raises(pj.InputError, match=r"materialx: path .*: expected a \.mtlx file name"):
        pj.export.materialx(openpbr, tmp_path / "m.xml")
    with pytest.raises(pj.InputError, match="usd: path .* does not exist"):
        pj.export.usd(preview, tmp_path / "missing" / "m.usda")
    with pytest.raises(pj.InputError, match="expected a USD prim name"):
        pj.export.usd(preview, tmp_path / "m.usda", name="bad name")
    assert list(tmp_path.iterdir()) == []  # nothing half-written
