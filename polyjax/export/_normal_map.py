r"""Normal maps of a capture: the camera frame's unit normals as a tangent-space normal map of the image plane
(:func:`encode_normals`, :func:`decode_normals`, :func:`normal_map` writes PNG or EXR).

The convention is glTF's and MikkTSpace's ("OpenGL", +Y up): texel ``(r, g, b) = n * 0.5 + 0.5`` with ``x`` to the
right of the image, ``y`` up in the image (towards row 0), ``z`` out of the image towards the camera. The capture's
camera frame (an orthographic camera looking along ``-z``, view direction ``(0, 0, 1)``, image rows top to bottom
along ``-y``) is exactly this frame, so the map is the normals themselves: ``n_tangent = n_camera``. On a quad in the
image plane whose texture coordinates grow to the right (``u``) and downwards (``v``, glTF's convention), the tangent
is ``(1, 0, 0)``, the bitangent ``(0, 1, 0)`` and the normal ``(0, 0, 1)``, and a renderer reading the map in tangent
space recovers the camera-frame normal. Off the mask the map holds the flat normal ``(0, 0, 1)`` (``(0.5, 0.5, 1)``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import InputError
from ._texture import write_texture


def _checked_normals(normals, mask):
    n = np.asarray(normals, np.float64)
    if n.ndim != 3 or n.shape[-1] != 3:
        raise InputError(f"normals: expected an (H, W, 3) normal map, found shape {n.shape}")
    m = np.ones(n.shape[:2], bool) if mask is None else np.asarray(mask, bool)
    if m.shape != n.shape[:2]:
        raise InputError(f"mask: expected shape {n.shape[:2]} (the normals'), found {m.shape}")
    return n, m


def encode_normals(normals, mask=None) -> np.ndarray:
    """Tangent-space texel values ``n * 0.5 + 0.5`` in ``[0, 1]`` of unit camera-frame normals ``(H, W, 3)`` (module
    notes); pixels off ``mask`` (and non-finite or zero normals) hold the flat normal ``(0.5, 0.5, 1)``."""
    n, m = _checked_normals(normals, mask)
    length = np.linalg.norm(np.nan_to_num(n), axis=-1, keepdims=True)
    ok = m[..., None] & np.isfinite(n).all(-1, keepdims=True) & (length > 1e-12)
    unit = np.where(ok, np.nan_to_num(n) / np.where(ok, length, 1.0), np.array([0.0, 0.0, 1.0]))
    return np.clip(unit * 0.5 + 0.5, 0.0, 1.0)


def decode_normals(texels) -> np.ndarray:
    """Unit normals ``(H, W, 3)`` of texel values in ``[0, 1]`` (``2 t - 1``, renormalised): the inverse of
    :func:`encode_normals` up to the file's quantisation (an 8-bit texel moves a normal by at most about 0.4
    degrees, a 16-bit one by about 0.002)."""
    t = np.asarray(texels, np.float64)
    if t.ndim != 3 or t.shape[-1] < 3:
        raise InputError(f"texels: expected an (H, W, 3) image, found shape {t.shape}")
    n = 2.0 * t[..., :3] - 1.0
    return n / np.maximum(np.linalg.norm(n, axis=-1, keepdims=True), 1e-12)


def normal_map(normals, path, *, mask=None, bits: int = 16) -> Path:
    """Write the tangent-space normal map (module notes) of camera-frame ``normals (H, W, 3)``: a ``.png`` of
    ``bits`` (8 or 16) per channel, linear (no sRGB curve), or a float32 ``.exr`` of the same encoded values
    ``n * 0.5 + 0.5`` (channels ``R, G, B``; :func:`decode_normals` reads either back).

    Returns:
        The path written (whole or not at all).
    """
    return write_texture(path, encode_normals(normals, mask), bits=bits)
