"""Texture files: PNG (8- or 16-bit grey, grey + alpha, RGB or RGBA; linear or sRGB-encoded) and OpenEXR (float32,
any number of named channels), each written whole or not at all (:func:`write_texture`), and the PNG bytes a
``.glb`` embeds (:func:`png_bytes`)."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import OpenEXR
import png

from .._config import check_output_file
from .._errors import InputError
from .._files import write_atomically

_PNG_MODES = {1: (True, False), 2: (True, True), 3: (False, False), 4: (False, True)}


def srgb_encode(x) -> np.ndarray:
    r"""The sRGB transfer function of linear values clipped to ``[0, 1]``: ``12.92 x`` below 0.0031308, else
    ``1.055 x^{1/2.4} - 0.055`` (glTF's ``baseColorTexture`` holds these)."""
    x = np.clip(np.nan_to_num(np.asarray(x, np.float64)), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def _channels_last(image, what: str) -> np.ndarray:
    a = np.asarray(image, np.float64)
    a = a[..., None] if a.ndim == 2 else a
    if a.ndim != 3 or a.shape[0] < 1 or a.shape[1] < 1:
        raise InputError(f"{what}: expected an (H, W) or (H, W, C) image, found shape {np.shape(image)}")
    return a


def png_bytes(image, *, bits: int = 8, srgb: bool = False) -> bytes:
    """``image`` (``(H, W)`` or ``(H, W, C)``, ``C`` in 1-4: grey, grey + alpha, RGB, RGBA; values in ``[0, 1]``,
    clipped, NaN as 0) as PNG bytes of ``bits`` (8 or 16) per channel; ``srgb=True`` encodes the colour channels
    (not alpha) with :func:`srgb_encode`, else they are stored as they are (linear data: normals, roughness)."""
    a = _channels_last(image, "image")
    if a.shape[-1] not in _PNG_MODES:
        raise InputError(f"image: expected 1 to 4 channels for a PNG, found {a.shape[-1]}")
    if bits not in (8, 16):
        raise InputError(f"bits: expected 8 or 16, found {bits!r}")
    grey, alpha = _PNG_MODES[a.shape[-1]]
    a = np.clip(np.nan_to_num(a), 0.0, 1.0)
    if srgb:
        colour = a.shape[-1] - int(alpha)
        a = np.concatenate([srgb_encode(a[..., :colour]), a[..., colour:]], -1)
    q = np.round(a * (2 ** bits - 1)).astype(np.uint16 if bits == 16 else np.uint8)
    h, w, c = q.shape
    buf = io.BytesIO()
    png.Writer(w, h, greyscale=grey, alpha=alpha, bitdepth=bits).write(buf, q.reshape(h, w * c))
    return buf.getvalue()


def _write_exr(tmp: Path, a: np.ndarray, names) -> None:
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
    channels = {n: np.ascontiguousarray(a[..., i], dtype=np.float32) for i, n in enumerate(names)}
    with OpenEXR.File(header, channels) as f:
        f.write(str(tmp))


def write_texture(path, image, *, bits: int = 8, srgb: bool = False, channels: tuple[str, ...] | None = None) -> Path:
    """Write ``image`` as a ``.png`` (:func:`png_bytes`: ``bits``, ``srgb``) or a float32 ``.exr`` (linear values as
    they are, channels named ``channels``, default ``Y``; ``Y, A``; ``R, G, B``; ``R, G, B, A`` or ``c0, c1, ...``).

    Returns:
        The path written (whole or not at all).

    Raises:
        InputError: a bad suffix, a missing folder, a bad shape or bit depth, before anything is written.
    """
    p = check_output_file(path, "texture: path")
    a = _channels_last(image, "image")
    if p.suffix.lower() == ".png":
        data = png_bytes(a, bits=bits, srgb=srgb)
        return write_atomically(p, lambda tmp: tmp.write_bytes(data))
    if p.suffix.lower() != ".exr":
        raise InputError(f"texture: path {str(p)!r}: expected a .png or .exr file name")
    c = a.shape[-1]
    default = {1: ("Y",), 2: ("Y", "A"), 3: ("R", "G", "B"), 4: ("R", "G", "B", "A")}
    names = tuple(channels) if channels is not None else default.get(c, tuple(f"c{i}" for i in range(c)))
    if len(names) != c or len(set(names)) != c:
        raise InputError(f"channels: expected {c} distinct names, found {names!r}")
    return write_atomically(p, lambda tmp: _write_exr(tmp, a, names))
