"""Images: OpenEXR input/output (linear RGB float), sRGB previews (8-bit PNG through pypng), difference images,
mosaics; the figure of the paper's Fig. 4 is :mod:`polyjax.render._figure`."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np
import OpenEXR
import png
from jaxtyping import ArrayLike

from .._errors import DataFormatError, DataNotFoundError, InputError
from .._files import check_output_path, write_atomically


def _as_rgb(image, name="image") -> np.ndarray:
    a = np.asarray(image)
    if a.ndim == 2:
        a = np.repeat(a[..., None], 3, axis=-1)
    if a.ndim != 3 or a.shape[-1] not in (3, 4):
        raise InputError(f"{name}: expected an (H, W, 3) RGB image (or (H, W) grey), found shape {a.shape}")
    return a[..., :3]


def write_exr(path: str | os.PathLike, image: ArrayLike) -> Path:
    """Write an ``(H, W, 3)`` linear RGB image as a 32-bit float OpenEXR file (ZIP compression).

    Returns:
        The path written.
    """
    rgb = np.ascontiguousarray(_as_rgb(image), dtype=np.float32)
    path = check_output_path(path, "path")
    header = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}

    def write(tmp: Path) -> None:
        with OpenEXR.File(header, {"RGB": rgb}) as f:
            f.write(str(tmp))

    return write_atomically(path, write)


def read_exr(path: str | os.PathLike) -> np.ndarray:
    """Read an OpenEXR file into an ``(H, W, 3)`` float32 array (linear RGB).

    Accepts ``R``, ``G``, ``B`` channels (any pixel type) or a single ``Y`` channel (grey).

    Raises:
        DataNotFoundError: the file does not exist.
        DataFormatError: the file is not a readable EXR with RGB or Y channels.
    """
    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"EXR file {str(path)!r} does not exist")
    try:
        with OpenEXR.File(str(path), separate_channels=True) as f:
            ch = {k: np.asarray(c.pixels) for k, c in f.channels().items()}
    except Exception as e:  # OpenEXR raises plain exceptions on malformed files
        raise DataFormatError(path, "an OpenEXR image", f"an unreadable file ({e})") from None
    if all(k in ch for k in "RGB"):
        return np.stack([ch["R"], ch["G"], ch["B"]], axis=-1).astype(np.float32)
    if "Y" in ch:
        return np.repeat(ch["Y"][..., None], 3, axis=-1).astype(np.float32)
    raise DataFormatError(path, "channels R, G, B (or Y)", f"channels {sorted(ch)}")


def to_srgb(image: ArrayLike, exposure: float = 0.0, tonemap: str = "clip") -> np.ndarray:
    r"""Tone-map linear radiance to display sRGB in ``[0, 1]``.

    ``x = 2^exposure L``; ``tonemap="reinhard"`` maps ``x -> x / (1 + x)``, ``"clip"`` keeps ``x``;
    then ``x`` is clipped to ``[0, 1]`` and encoded with the sRGB transfer function
    (``12.92 x`` below 0.0031308, else ``1.055 x^{1/2.4} - 0.055``). Non-finite values become 0.
    """
    x = _as_rgb(image).astype(np.float64) * 2.0 ** float(exposure)
    x = np.where(np.isfinite(x), x, 0.0)
    if tonemap == "reinhard":
        x = np.maximum(x, 0.0)
        x = x / (1.0 + x)
    elif tonemap != "clip":
        raise InputError(f"tonemap: expected 'clip' or 'reinhard', found {tonemap!r}")
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def write_png(path: str | os.PathLike, image: ArrayLike, exposure: float = 0.0, tonemap: str = "clip",
              srgb: bool = True) -> Path:
    """Write a preview PNG: tone-mapped sRGB (``srgb=True``) or an image already in ``[0, 1]`` display values."""
    disp = to_srgb(image, exposure, tonemap) if srgb else np.clip(_as_rgb(image), 0.0, 1.0)
    path = check_output_path(path, "path")
    rows = np.round(disp * 255).astype(np.uint8)
    h, w, _ = rows.shape

    def write(tmp: Path) -> None:
        with open(tmp, "wb") as fh:
            png.Writer(w, h, greyscale=False, bitdepth=8).write(fh, rows.reshape(h, w * 3))

    return write_atomically(path, write)


def difference_images(images: Sequence[ArrayLike], reference: ArrayLike, scale: float | None = None
                      ) -> tuple[np.ndarray, float]:
    """Absolute differences to a reference on one common scale (the insets of the paper's Fig. 4).

    ``D_k = mean_c |I_k - R| / s`` clipped to ``[0, 1]``, where ``s`` is shared by all images: by
    default the largest absolute difference over every image, so the insets are comparable.

    Returns:
        ``(D, s)``: ``(K, H, W)`` differences in ``[0, 1]`` and the scale ``s`` used.
    """
    ref = _as_rgb(reference).astype(np.float64)
    diffs = []
    for k, im in enumerate(images):
        a = _as_rgb(im, f"images[{k}]").astype(np.float64)
        if a.shape != ref.shape:
            raise InputError(f"images[{k}]: expected the reference's shape {ref.shape}, found {a.shape}")
        diffs.append(np.mean(np.abs(a - ref), axis=-1))
    d = np.stack(diffs) if diffs else np.zeros((0,) + ref.shape[:2])
    s = float(np.max(d)) if scale is None else float(scale)
    s = s if s > 0 else 1.0
    return np.clip(d / s, 0.0, 1.0), s


def mosaic(images: Sequence[Sequence[ArrayLike]] | np.ndarray, pad: int = 2, fill: float = 1.0) -> np.ndarray:
    """Assemble a ``rows x cols`` grid of equally sized ``(H, W, 3)`` images into one image."""
    rows = [[_as_rgb(im) for im in row] for row in images]
    if not rows or not rows[0]:
        raise InputError("images: expected at least one row with one image")
    h, w = rows[0][0].shape[:2]
    n_r, n_c = len(rows), max(len(r) for r in rows)
    out = np.full((n_r * h + (n_r + 1) * pad, n_c * w + (n_c + 1) * pad, 3), fill, dtype=np.float32)
    for i, row in enumerate(rows):
        for j, im in enumerate(row):
            if im.shape[:2] != (h, w):
                raise InputError(f"images[{i}][{j}]: expected size {(h, w)}, found {im.shape[:2]}")
            y, x = pad + i * (h + pad), pad + j * (w + pad)
            out[y : y + h, x : x + w] = im
    return out


__all__ = ["difference_images", "mosaic", "read_exr", "to_srgb", "write_exr", "write_png"]
