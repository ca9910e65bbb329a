r"""An OpenPBR material as a MaterialX document (``.mtlx``, MaterialX 1.39): an ``open_pbr_surface`` material and a
``standard_surface`` one (Autodesk Standard Surface) translated from it.

The translation is MaterialX's own graph ``NG_open_pbr_surface_to_standard_surface``
(``libraries/bxdf/translation/open_pbr_to_standard_surface.mtlx``), evaluated here on the constant inputs:
``base = base_weight``, ``base_color = base_color * B`` (``B`` the coat darkening ``mix(1, (1 - K) / (1 - E_base K),
coat_weight)``, ``K = 1 - (1 - F_0(coat_ior)) / coat_ior^2``, ``E_base = mix(base_color, specular_weight base_color,
base_metalness)``; 1 without coat), ``diffuse_roughness = base_diffuse_roughness``, ``metalness = base_metalness``,
``specular = specular_weight``, ``specular_color``, ``specular_roughness = mix(specular_roughness, coat_roughness,
coat_weight)``, ``specular_IOR = specular_ior``, ``specular_anisotropy = specular_roughness_anisotropy``, ``coat =
coat_weight``, ``coat_color``, ``coat_roughness``, ``coat_IOR = coat_ior``, ``coat_affect_roughness = 1``. Standard
Surface's lobes are not OpenPBR's (its metal Fresnel, its Oren-Nayar diffuse), so that material is an approximation;
the ``open_pbr_surface`` one is the exact material.

Only OpenPBR materials (``model`` ``openpbr...``) are written: a UsdPreviewSurface material has no exact OpenPBR form
(its Schlick-Smith visibility and its Fresnel mix differ) and is refused; write it with :func:`usd`.
"""

from __future__ import annotations

import os
from pathlib import Path

from .._errors import InputError
from .._files import write_atomically
from ._material import checked_inputs, format_float, material_of, output_path

_WHAT = "materialx"
#: OpenPBR inputs written, with their ranges (``ND_open_pbr_surface_surfaceshader``'s ``uimin``/``uimax``).
SCALARS = {
    "base_weight": (0.0, 1.0), "base_metalness": (0.0, 1.0), "base_diffuse_roughness": (0.0, 1.0),
    "specular_weight": (0.0, None), "specular_roughness": (0.0, 1.0), "specular_ior": (1.0, None),
    "specular_roughness_anisotropy": (0.0, 1.0), "coat_weight": (0.0, 1.0), "coat_roughness": (0.0, 1.0),
    "coat_ior": (1.0, None), "coat_darkening": (0.0, 1.0),
}
COLORS = ("base_color", "specular_color", "coat_color")
OPTIONAL = ("coat_weight", "coat_color", "coat_roughness", "coat_ior", "coat_darkening")
MODELS = ("openpbr", "openpbr-anisotropic", "openpbr-coat")


def _import_materialx():
    try:
        import MaterialX as mx  # optional (the "materialx" extra): imported where used
    except ImportError:
        raise ImportError("pj.export.materialx needs the MaterialX package: pip install 'polyjax[materialx]'") from None
    return mx


def check_openpbr(material, what: str = _WHAT) -> dict:
    """The OpenPBR inputs of ``material`` checked (:func:`polyjax.export._material.check_material`), coat defaults
    filled in when a coat is given."""
    if isinstance(material, dict) and str(material.get("model", "")).startswith("usd-preview"):
        raise InputError(f"{what}: a {material['model']!r} material is a UsdPreviewSurface: it has no exact OpenPBR "
                         "form; write it with pj.export.usd, or fit 'openpbr' for MaterialX")
    p = checked_inputs(what, material, MODELS, SCALARS, COLORS, OPTIONAL)
    if any(k in p for k in OPTIONAL):
        p = {"coat_weight": 0.0, "coat_color": (1.0, 1.0, 1.0), "coat_roughness": 0.0, "coat_ior": 1.6,
             "coat_darkening": 1.0, **p}
    return p


def standard_surface_inputs(p: dict) -> dict:
    """The Standard Surface inputs of the checked OpenPBR inputs ``p`` (MaterialX's translation graph, module docs)."""
    cw = p.get("coat_weight", 0.0)
    base_color = p["base_color"]
    out = {"base": p["base_weight"], "diffuse_roughness": p["base_diffuse_roughness"],
           "metalness": p["base_metalness"], "specular": p["specular_weight"], "specular_color": p["specular_color"],
           "specular_roughness": p["specular_roughness"], "specular_IOR": p["specular_ior"],
           "specular_anisotropy": p["specular_roughness_anisotropy"]}
    if "coat_weight" in p:
        ci = p["coat_ior"]
        k = 1.0 - (1.0 - ((ci - 1.0) / (ci + 1.0)) ** 2) / ci**2
        m, cd = p["base_metalness"], cw * p["coat_darkening"]
        e_base = [c + (c * p["specular_weight"] - c) * m for c in base_color]
        base_color = tuple(c * (1.0 + ((1.0 - k) / (1.0 - e * k) - 1.0) * cd) for c, e in zip(base_color, e_base))
        out.update(specular_roughness=p["specular_roughness"] + (p["coat_roughness"] - p["specular_roughness"]) * cw,
                   coat=cw, coat_color=p["coat_color"], coat_roughness=p["coat_roughness"], coat_IOR=ci,
                   coat_affect_roughness=1.0)
    return {"base_color": base_color, **out}


def _add_shader(mx, doc, category: str, name: str, inputs: dict):
    node = doc.addNode(category, f"SR_{name}", "surfaceshader")
    for key, value in inputs.items():
        if isinstance(value, tuple):
            node.addInput(key, "color3").setValueString(", ".join(format_float(x) for x in value))
        else:
            node.addInput(key, "float").setValueString(format_float(value))
    doc.addMaterialNode(f"M_{name}", node)


def materialx(material, path: str | os.PathLike, *, name: str = "fitted") -> Path:
    """Write an OpenPBR material as a MaterialX document: materials ``M_<name>_openpbr`` (an ``open_pbr_surface``)
    and ``M_<name>_standard_surface`` (module docs for the translation).

    Args:
        material: ``{"model": "openpbr..." , "base_color": [r, g, b], ...}`` as ``BaselineModel.to_material`` returns
            it for the ``openpbr`` models (every input of :data:`SCALARS` and :data:`COLORS` but the coat's).
        path: the ``.mtlx`` file to write (written whole or not at all).
        name: the materials' base name (an XML name).

    Returns:
        The path written. The document is validated by MaterialX against its standard libraries before it is
        written.

    Raises:
        InputError: a missing or unknown input, a value out of its range, a UsdPreviewSurface material, a bad path.
        ImportError: MaterialX is not installed (``pip install 'polyjax[materialx]'``).
    """
    p = check_openpbr(material_of(material, _WHAT))
    out = output_path(_WHAT, path, ".mtlx")
    mx = _import_materialx()
    if not mx.isValidName(name):
        raise InputError(f"{_WHAT}: name {name!r}: expected a valid MaterialX element name")
    doc = mx.createDocument()
    _add_shader(mx, doc, "open_pbr_surface", f"{name}_openpbr", p)
    _add_shader(mx, doc, "standard_surface", f"{name}_standard_surface", standard_surface_inputs(p))
    checked = mx.createDocument()
    checked.copyContentFrom(doc)
    libraries = mx.createDocument()
    mx.loadLibraries(mx.getDefaultDataLibraryFolders(), mx.getDefaultDataSearchPath(), libraries)
    checked.importLibrary(libraries)
    ok, message = checked.validate()
    if not ok:
        raise InputError(f"{_WHAT}: MaterialX rejects the document: {message}")
    return write_atomically(out, lambda tmp: mx.writeToXmlFile(doc, str(tmp)))
