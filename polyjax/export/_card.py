r"""The capture card: a binary glTF 2.0 (``.glb``) of a capture fit (:func:`gltf_card`): the image plane as one quad,
the orthographic camera of the capture, and a glTF metallic-roughness material whose textures (PNG, in the binary
chunk) are the fit's maps (:func:`polyjax.export.card_maps`) and normal map (:func:`polyjax.export.normal_map`).

Geometry (glTF's frame, which is the capture's camera frame: ``x`` right, ``y`` up, ``z`` towards the camera): the
image of ``H`` rows and ``W`` columns spans ``y`` in ``[-1, 1]`` and ``x`` in ``[-W/H, W/H]`` at ``z = 0`` (the
frame of :attr:`polyjax.Capture.scenes`); the quad covers the mask's bounding box (``crop=True``) or the whole image,
its normal ``(0, 0, 1)``, tangent ``(1, 0, 0, 1)`` and texture coordinates ``u`` rightwards, ``v`` downwards, so that
texel ``(row, column)`` of the maps lies over pixel ``(row, column)`` and the normal texture's tangent space is the
camera frame. The camera node at ``(0, 0, 2)`` looks along ``-z`` (glTF's default), orthographic with ``ymag = 1``,
``xmag = W / H``. The base colour's alpha is the mask (``alphaMode: MASK``, cutoff 0.5). A dielectric's specular
weight (:class:`~polyjax.export.CardMaps` ``specular``: ``F0 = 0.04 k``) is ``KHR_materials_specular``'s
``specularColorTexture`` (sRGB, grey), the one input of that extension Blender 3.4's importer reads.

The card records under ``asset.extras.polyjax``: ``lightScale`` (:class:`~polyjax.export.CardMaps` ``scale``: a
directional light of the capture's irradiance ``E`` is rendered with ``lightScale * E``), the image size and the
GGX fits of the lobes (roughness, amplitude, relative L2).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import InputError
from .._files import write_atomically
from ._card_maps import CardMaps, card_maps
from ._gltf import _glb
from ._material import output_path
from ._normal_map import encode_normals
from ._texture import png_bytes

_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER, _FLOAT, _UINT16 = 34962, 34963, 5126, 5123
_LINEAR, _CLAMP = 9729, 33071


def _window(mask: np.ndarray, crop: bool) -> tuple[slice, slice]:
    if not crop:
        return slice(0, mask.shape[0]), slice(0, mask.shape[1])
    if not mask.any():
        raise InputError("fit.mask: expected at least one object pixel to crop the card to")
    ys, xs = np.nonzero(mask)
    return slice(int(ys.min()), int(ys.max()) + 1), slice(int(xs.min()), int(xs.max()) + 1)


def _quad(shape, rows: slice, cols: slice) -> dict:
    """The quad over pixels ``rows x cols`` of an ``H x W`` image (module notes): float32 attributes, indices."""
    h, w = shape
    x0, x1 = (cols.start - w / 2) * 2 / h, (cols.stop - w / 2) * 2 / h
    y0, y1 = (h / 2 - rows.start) * 2 / h, (h / 2 - rows.stop) * 2 / h  # top, bottom
    pos = np.array([[x0, y0, 0], [x0, y1, 0], [x1, y1, 0], [x1, y0, 0]], np.float32)
    return {"POSITION": pos, "NORMAL": np.tile(np.float32([0, 0, 1]), (4, 1)),
            "TANGENT": np.tile(np.float32([1, 0, 0, 1]), (4, 1)),
            "TEXCOORD_0": np.array([[0, 0], [0, 1], [1, 1], [1, 0]], np.float32),
            "indices": np.array([0, 1, 2, 0, 2, 3], np.uint16)}  # counter-clockwise seen from +z


def _textures(maps: CardMaps, rows: slice, cols: slice) -> list[bytes]:
    """PNG bytes of the base colour (sRGB, alpha = mask), metallic-roughness (G roughness, B metallic) and normals."""
    m = np.asarray(maps.mask)[rows, cols]
    base = np.concatenate([np.asarray(maps.base_color)[rows, cols], m[..., None]], -1)
    mr = np.stack([np.ones(m.shape), np.asarray(maps.roughness)[rows, cols], np.asarray(maps.metallic)[rows, cols]],
                  -1)
    normals = encode_normals(np.asarray(maps.normals)[rows, cols], m)
    spec = np.repeat(np.asarray(maps.specular)[rows, cols][..., None], 3, -1)
    return [png_bytes(base, srgb=True), png_bytes(mr), png_bytes(normals), png_bytes(spec, srgb=True)]


def _buffers(quad: dict, images: list[bytes]) -> tuple[list, list, dict, bytes]:
    """bufferViews, accessors, the primitive's attributes and the binary chunk (4-byte aligned pieces)."""
    views, accessors, attributes, chunks, offset = [], [], {}, [], 0
    for key, arr in quad.items():
        raw = arr.tobytes()
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(raw),
                      "target": _ELEMENT_ARRAY_BUFFER if key == "indices" else _ARRAY_BUFFER})
        acc = {"bufferView": len(views) - 1, "count": int(arr.shape[0]),
               "componentType": _UINT16 if key == "indices" else _FLOAT,
               "type": "SCALAR" if arr.ndim == 1 else f"VEC{arr.shape[1]}"}
        if key == "POSITION":
            acc.update(min=arr.min(0).tolist(), max=arr.max(0).tolist())
        accessors.append(acc)
        if key != "indices":
            attributes[key] = len(accessors) - 1
        chunks.append(raw + b"\0" * ((-len(raw)) % 4))
        offset += len(chunks[-1])
    for data in images:
        views.append({"buffer": 0, "byteOffset": offset, "byteLength": len(data)})
        chunks.append(data + b"\0" * ((-len(data)) % 4))
        offset += len(chunks[-1])
    return views, accessors, attributes, b"".join(chunks)


def _document(maps: CardMaps, rows: slice, cols: slice, name: str) -> tuple[dict, bytes]:
    """The glTF JSON and its binary chunk (module notes)."""
    h, w = np.asarray(maps.mask).shape
    quad = _quad((h, w), rows, cols)
    views, accessors, attributes, binary = _buffers(quad, _textures(maps, rows, cols))
    first_image = len(quad)
    lobes = maps.lobes
    extras = {"polyjax": {"lightScale": float(maps.scale), "imageSize": [w, h],
                          "lobeRoughness": np.asarray(lobes.roughness).tolist(),
                          "lobeAmplitude": np.asarray(lobes.amplitude).tolist(),
                          "lobeRelativeL2": np.asarray(lobes.relative_l2).tolist()}}
    material = {"name": name, "alphaMode": "MASK", "alphaCutoff": 0.5,
                "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}, "metallicRoughnessTexture": {"index": 1},
                                         "metallicFactor": 1.0, "roughnessFactor": 1.0},
                "normalTexture": {"index": 2},
                "extensions": {"KHR_materials_specular": {"specularColorTexture": {"index": 3}}}}
    doc = {
        "asset": {"version": "2.0", "generator": "polyjax", "extras": extras},
        "scene": 0, "scenes": [{"nodes": [0, 1]}],
        "nodes": [{"name": name, "mesh": 0}, {"name": "camera", "camera": 0, "translation": [0.0, 0.0, 2.0]}],
        "cameras": [{"type": "orthographic", "orthographic": {"xmag": w / h, "ymag": 1.0, "znear": 0.01,
                                                              "zfar": 10.0}}],
        "meshes": [{"name": name, "primitives": [{"attributes": attributes, "indices": len(accessors) - 1,
                                                  "material": 0}]}],
        "materials": [material], "extensionsUsed": ["KHR_materials_specular"],
        "samplers": [{"magFilter": _LINEAR, "minFilter": _LINEAR, "wrapS": _CLAMP, "wrapT": _CLAMP}],
        "images": [{"bufferView": first_image + i, "mimeType": "image/png"} for i in range(4)],
        "textures": [{"sampler": 0, "source": i} for i in range(4)],
        "buffers": [{"byteLength": len(binary)}], "bufferViews": views, "accessors": accessors,
    }
    return doc, binary


def gltf_card(fit, path, *, crop: bool = True, name: str = "capture", maps: CardMaps | None = None) -> Path:
    """Write the ``.glb`` card of a capture fit (module notes).

    Args:
        fit: a :class:`polyjax.CaptureFit` (or an object with its fields and ``lobes``); unused when ``maps`` is
            given.
        path: the ``.glb`` file (its folder must exist).
        crop: the quad covers the mask's bounding box (else the whole image).
        name: the material's, mesh's and node's name.
        maps: the :func:`~polyjax.export.card_maps` of ``fit``, if already made.

    Returns:
        The path written (whole or not at all).

    Raises:
        InputError: a bad path (checked first), a fit without the capture fit's fields, an empty mask with ``crop``.
    """
    out = output_path("gltf_card", path, ".glb")
    maps = card_maps(fit) if maps is None else maps
    rows, cols = _window(np.asarray(maps.mask), crop)
    doc, binary = _document(maps, rows, cols, name)
    data = _glb(doc, binary)
    return write_atomically(out, lambda tmp: tmp.write_bytes(data))
