"""glTF 2.0 files (``.gltf`` with an embedded buffer, or binary ``.glb``) of a fitted glTF material, optionally on a
UV sphere: :func:`gltf`."""

from __future__ import annotations

import base64
import json
import struct
from pathlib import Path

import numpy as np

from .._errors import InputError
from .._files import check_output_path, write_bytes_atomically
from ._material import check_material, material_of

_CORE = {"baseColorFactor": "rgb", "metallicFactor": "unit", "roughnessFactor": "unit"}
_SPECULAR = {"specularFactor": "unit", "specularColorFactor": "rgb+", "ior": "ior"}
_ANISOTROPY = {"anisotropyStrength": "unit", "anisotropyRotation": "real"}
_ALL = {**_CORE, **_SPECULAR, **_ANISOTROPY}
#: the material dicts accepted (``baselines.standard_material`` of the ``gltf-pbr`` models)
MODELS = {name: (_ALL, tuple(_CORE)) for name in ("gltf-pbr", "gltf-pbr-specular", "gltf-pbr-anisotropic")}

_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER, _FLOAT, _UINT16, _UINT32 = 34962, 34963, 5126, 5123, 5125


def gltf(material, path, *, sphere: bool = True, segments: int = 64, rings: int = 32, name: str = "polyjax"):
    """Write a glTF 2.0 material (``.gltf``: JSON with the buffer as a data URI; ``.glb``: binary), on a unit UV
    sphere unless ``sphere=False``.

    The material is the glTF 2.0 metallic-roughness material (specification section 3.9.2, ``pbrMetallicRoughness``
    with ``baseColorFactor`` alpha 1), with ``KHR_materials_specular`` (``specularFactor``,
    ``specularColorFactor``), ``KHR_materials_ior`` (``ior``) and ``KHR_materials_anisotropy``
    (``anisotropyStrength``, ``anisotropyRotation``) when the dict has their keys; every extension used is listed in
    ``extensionsUsed``. The sphere (y up, radius 1) has positions, unit normals, unit tangents along the circles of
    latitude (``w = 1``) when the material is anisotropic (the extension requires them).

    Args:
        material: a dict of ``baselines.standard_material`` for a ``gltf-pbr`` model, e.g. ``{"model": "gltf-pbr",
            "baseColorFactor": [r, g, b], "metallicFactor": m, "roughnessFactor": r}``, or a one-material fit whose
            ``material()`` returns one.
        path: ``.gltf`` or ``.glb`` file (its folder must exist).
        sphere: put the material on a UV sphere (``segments`` around, ``rings`` from pole to pole).
        name: the material's, mesh's and node's name.

    Returns:
        The path written (written whole or not at all).

    Raises:
        InputError: a bad suffix or folder, a missing, unknown or out-of-range material value.
    """
    path = _check_path(path, (".gltf", ".glb"))
    mat = check_material("gltf", material_of(material), MODELS)
    if not (isinstance(segments, int) and isinstance(rings, int) and segments >= 3 and rings >= 2):
        raise InputError(f"segments, rings: expected integers >= 3 and >= 2, found {segments!r}, {rings!r}")
    mesh = _uv_sphere(segments, rings, tangents=any(k in mat for k in _ANISOTROPY)) if sphere else None
    doc, binary = _document(mat, name, mesh)
    if path.suffix.lower() == ".glb":
        data = _glb(doc, binary)
    else:
        if binary:
            doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(binary).decode()
        data = json.dumps(doc, indent=1).encode()
    write_bytes_atomically(path, data)
    return path


def _check_path(path, suffixes) -> Path:
    path = Path(path)
    if path.suffix.lower() not in suffixes:
        raise InputError(f"path: expected a file ending in {' or '.join(suffixes)}, found {str(path)!r}")
    if not path.parent.is_dir():
        raise InputError(f"path: the folder {str(path.parent)!r} does not exist")
    return check_output_path(path, "path")




def _material_json(mat: dict, name: str) -> tuple[dict, list[str]]:
    """The glTF ``material`` object and the extensions it uses."""
    pbr = {"baseColorFactor": mat["baseColorFactor"] + [1.0], "metallicFactor": mat["metallicFactor"],
           "roughnessFactor": mat["roughnessFactor"]}
    ext = {}
    spec = {k: mat[k] for k in ("specularFactor", "specularColorFactor") if k in mat}
    if spec:
        ext["KHR_materials_specular"] = spec
    if "ior" in mat:
        ext["KHR_materials_ior"] = {"ior": mat["ior"]}
    aniso = {k: mat[k] for k in _ANISOTROPY if k in mat}
    if aniso:
        ext["KHR_materials_anisotropy"] = aniso
    out = {"name": name, "pbrMetallicRoughness": pbr}
    return (dict(out, extensions=ext) if ext else out), sorted(ext)


def _uv_sphere(segments: int, rings: int, tangents: bool) -> dict:
    """A unit UV sphere, y up: float32 positions (= normals), tangents ``(-sin phi, 0, -cos phi, 1)`` along the
    circles of latitude when asked for (anisotropy needs them), counter-clockwise triangles seen from outside (one
    per quad at the poles: none degenerate)."""
    theta = np.linspace(0.0, np.pi, rings + 1)
    phi = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    pos = np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    tan = np.stack([-np.sin(p), np.zeros_like(p), -np.cos(p), np.ones_like(p)], -1).reshape(-1, 4)
    idx = lambda i, j: i * (segments + 1) + j  # noqa: E731
    tris = []
    for i in range(rings):
        for j in range(segments):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            if i > 0:
                tris.append((a, b, d))
            if i < rings - 1:
                tris.append((b, c, d))
    tris = np.asarray(tris)
    e1, e2 = pos[tris[:, 1]] - pos[tris[:, 0]], pos[tris[:, 2]] - pos[tris[:, 0]]
    if np.sum(np.cross(e1, e2) * pos[tris].mean(1)) < 0:  # make them counter-clockwise seen from outside
        tris = tris[:, ::-1]
    pos = pos.astype(np.float32)
    pos /= np.linalg.norm(pos, axis=1, keepdims=True)
    out = {"POSITION": pos, "NORMAL": pos.copy()}
    if tangents:
        out["TANGENT"] = tan.astype(np.float32)
    return dict(out, indices=tris.ravel())


def _document(mat: dict, name: str, mesh: dict | None) -> tuple[dict, bytes]:
    """The glTF JSON (without the buffer's URI) and its binary buffer."""
    material, extensions = _material_json(mat, name)
    doc = {"asset": {"version": "2.0", "generator": "polyjax"}, "materials": [material]}
    if extensions:
        doc["extensionsUsed"] = extensions
    if mesh is None:
        return doc, b""
    chunks, views, accessors, attributes = [], [], [], {}
    offset = 0
    for key, arr in mesh.items():
        if key == "indices":
            arr = arr.astype(np.uint16 if len(mesh["POSITION"]) < 65535 else np.uint32)
        raw = arr.tobytes()
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(raw),
                      "target": _ELEMENT_ARRAY_BUFFER if key == "indices" else _ARRAY_BUFFER})
        acc = {"bufferView": len(views) - 1, "count": int(arr.shape[0]),
               "componentType": {np.dtype(np.uint16): _UINT16, np.dtype(np.uint32): _UINT32}.get(arr.dtype, _FLOAT),
               "type": "SCALAR" if arr.ndim == 1 else f"VEC{arr.shape[1]}"}
        if key == "POSITION":
            acc.update(min=arr.min(0).tolist(), max=arr.max(0).tolist())
        accessors.append(acc)
        if key != "indices":
            attributes[key] = len(accessors) - 1
        pad = (-len(raw)) % 4
        chunks.append(raw + b"\0" * pad)
        offset += len(raw) + pad
    binary = b"".join(chunks)
    doc.update(
        scene=0, scenes=[{"nodes": [0]}], nodes=[{"name": name, "mesh": 0}],
        meshes=[{"name": name, "primitives": [{"attributes": attributes, "indices": len(accessors) - 1,
                                               "material": 0}]}],
        buffers=[{"byteLength": len(binary)}], bufferViews=views, accessors=accessors,
    )
    return doc, binary


def _glb(doc: dict, binary: bytes) -> bytes:
    """The binary container (glTF 2.0 section 4.4): header, JSON chunk padded with spaces, BIN chunk with zeros."""
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * ((-len(js)) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js
    if binary:
        body += struct.pack("<II", len(binary), 0x004E4942) + binary
    return struct.pack("<III", 0x46546C67, 2, 12 + len(body)) + body
