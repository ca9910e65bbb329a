r"""A UsdPreviewSurface material as a USD stage (``.usda``): ``/Root`` (the default prim, ``upAxis`` Z,
``metersPerUnit`` 1) holding ``/Root/Materials/<name>`` (a ``UsdShade.Material`` whose ``outputs:surface`` is
connected to its ``UsdPreviewSurface`` shader ``PreviewSurface``) and, optionally, ``/Root/Sphere``, a unit sphere
bound to the material (``UsdShade.MaterialBindingAPI``).

The shader's inputs are those of the UsdPreviewSurface Specification (``diffuseColor``, ``useSpecularWorkflow``,
``specularColor``, ``metallic``, ``roughness``, ``ior``, ``clearcoat``, ``clearcoatRoughness``), typed as the
specification types them (``color3f``, ``int``, ``float``): the file holds the values rounded to float32.

Only UsdPreviewSurface materials (``model`` ``usd-preview...``) are written: an OpenPBR material has no exact
UsdPreviewSurface form (its F82 metal, EON diffuse and energy-compensated layering have no counterpart) and is
refused; write it with :func:`materialx`, or fit ``usd-preview``.
"""

from __future__ import annotations

import os
from pathlib import Path

from .._errors import InputError
from .._files import write_atomically
from ._material import checked_inputs, material_of, output_path

_WHAT = "usd"
SCALARS = {"useSpecularWorkflow": (0.0, 1.0), "metallic": (0.0, 1.0), "roughness": (0.0, 1.0), "ior": (1.0, None),
           "clearcoat": (0.0, 1.0), "clearcoatRoughness": (0.0, 1.0)}
COLORS = ("diffuseColor", "specularColor")
OPTIONAL = ("clearcoat", "clearcoatRoughness")
MODELS = ("usd-preview", "usd-preview-specular", "usd-preview-clearcoat")


def _import_pxr():
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, UsdShade  # optional (the "usd" extra): imported where used
    except ImportError:
        raise ImportError("pj.export.usd needs the usd-core package: pip install 'polyjax[usd]'") from None
    return Gf, Sdf, Usd, UsdGeom, UsdShade


def check_usd_preview(material, what: str = _WHAT) -> dict:
    """The UsdPreviewSurface inputs of ``material`` checked (``useSpecularWorkflow`` 0 or 1)."""
    if isinstance(material, dict) and str(material.get("model", "")).startswith("openpbr"):
        raise InputError(f"{what}: a {material['model']!r} material is an OpenPBR Surface: it has no exact "
                         "UsdPreviewSurface form; write it with pj.export.materialx, or fit 'usd-preview' for USD")
    p = checked_inputs(what, material, MODELS, SCALARS, COLORS, OPTIONAL)
    if p["useSpecularWorkflow"] not in (0.0, 1.0):
        raise InputError(f"{what}: material['useSpecularWorkflow'] = {material['useSpecularWorkflow']!r}: "
                         "expected 0 or 1")
    return p


def _define(stage, p: dict, name: str, sphere: bool):
    Gf, Sdf, Usd, UsdGeom, UsdShade = _import_pxr()
    root = UsdGeom.Xform.Define(stage, "/Root")
    stage.SetDefaultPrim(root.GetPrim())
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0)
    UsdGeom.Scope.Define(stage, "/Root/Materials")
    material = UsdShade.Material.Define(stage, f"/Root/Materials/{name}")
    shader = UsdShade.Shader.Define(stage, f"/Root/Materials/{name}/PreviewSurface")
    shader.CreateIdAttr("UsdPreviewSurface")
    for key, value in p.items():
        if isinstance(value, tuple):
            shader.CreateInput(key, Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*value))
        elif key == "useSpecularWorkflow":
            shader.CreateInput(key, Sdf.ValueTypeNames.Int).Set(int(value))
        else:
            shader.CreateInput(key, Sdf.ValueTypeNames.Float).Set(float(value))
    material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    if sphere:
        ball = UsdGeom.Sphere.Define(stage, "/Root/Sphere")
        ball.CreateRadiusAttr(1.0)
        ball.CreateExtentAttr([Gf.Vec3f(-1.0, -1.0, -1.0), Gf.Vec3f(1.0, 1.0, 1.0)])
        UsdShade.MaterialBindingAPI.Apply(ball.GetPrim()).Bind(material)


def usd(material, path: str | os.PathLike, *, name: str = "Fitted", sphere: bool = True) -> Path:
    """Write a UsdPreviewSurface material as a ``.usda`` stage (module docs for its layout).

    Args:
        material: ``{"model": "usd-preview...", "diffuseColor": [r, g, b], "useSpecularWorkflow": 0 or 1,
            "specularColor": [r, g, b], "metallic", "roughness", "ior"[, "clearcoat", "clearcoatRoughness"]}`` as
            ``BaselineModel.to_material`` returns it for the ``usd-preview`` models.
        path: the ``.usda`` file to write (written whole or not at all).
        name: the material prim's name (a USD identifier).
        sphere: also write ``/Root/Sphere`` bound to the material.

    Returns:
        The path written.

    Raises:
        InputError: a missing or unknown input, a value out of its range, an OpenPBR material, a bad path or name.
        ImportError: usd-core is not installed (``pip install 'polyjax[usd]'``).
    """
    p = check_usd_preview(material_of(material, _WHAT))
    out = output_path(_WHAT, path, ".usda")
    Gf, Sdf, Usd, UsdGeom, UsdShade = _import_pxr()
    if not Sdf.Path.IsValidIdentifier(name):
        raise InputError(f"{_WHAT}: name {name!r}: expected a USD prim name (letters, digits, '_')")
    stage = Usd.Stage.CreateInMemory()
    _define(stage, p, name, sphere)

    def write(tmp: Path):
        if not stage.GetRootLayer().Export(str(tmp)):
            raise InputError(f"{_WHAT}: path {str(out)!r}: USD could not write the stage")

    return write_atomically(out, write)
