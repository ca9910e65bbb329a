r"""Photographs of an object under calibrated directional lights, in DiLiGenT's layout.

DiLiGenT (Shi et al., *A Benchmark Dataset and Evaluation for Non-Lambertian and Uncalibrated Photometric Stereo*,
CVPR 2016 / TPAMI 2019) stores each object in a folder ``pmsData/<object>PNG/``:

- ``filenames.txt``: one image name a line; line ``i`` belongs to row ``i`` of the two light files;
- ``light_directions.txt``: ``L`` rows ``x y z``, unit directions towards each light in the camera frame;
- ``light_intensities.txt``: ``L`` rows ``r g b``, each light's intensity per channel;
- the images: 16-bit RGB PNGs, linear; the camera's units are ``value / 65535`` (65535 is saturation); 8-bit
  linear PNGs (every image of one depth) are read as ``value / 255``, their quantisation step ``1 / 255`` recorded
  on the capture (:attr:`polyjax.Capture.quantisation`);
- ``mask.png``: object pixels non-zero;
- normals (optional: without them the capture's ``normals`` is None; mask pixels whose normal is the zero
  vector, unknown, leave the mask): ``Normal_gt.mat`` (MATLAB v5, variable ``Normal_gt``, ``(H, W, 3)``) or
  ``normal.txt`` (``H W`` rows of ``x y z``, row-major), unit vectors in the camera frame;
- the camera is orthographic and looks along ``-z`` of that frame: the view direction is ``(0, 0, 1)`` everywhere.

16-bit PNGs are read by pypng (Pillow would truncate them to 8 bits), the ``.mat`` file by :func:`read_mat_array`
(the subset of the MAT-file v5 format such a file uses: MathWorks, *MAT-File Format*, R2024a, chapter 1). Every
file is checked before any array reaches JAX; a bad one raises :class:`polyjax.DataFormatError` (or
:class:`polyjax.DataNotFoundError`) naming it.
"""

from __future__ import annotations

import os
import struct
import zlib
from typing import Sequence

import numpy as np
import png

from .._errors import DataFormatError, DataNotFoundError, InputError
from ..inverse._capture import Capture

#: the camera's white level: a 16-bit PNG value is divided by it (and 1.0 is a saturated pixel)
PNG16_MAX = 65535.0
#: the same for 8-bit PNGs (linear values, e.g. DiLiGenT's cropped 8-bit copies)
PNG8_MAX = 255.0


def read_png(path: str, bits: int | None = 16) -> np.ndarray:
    """The pixels of a PNG as an integer array ``(H, W, channels)`` (``(H, W)`` for one channel), at its own bit
    depth (16-bit values are kept). ``bits``: the bit depth expected (None: any). Raises
    :class:`polyjax.DataFormatError` naming the file when it is not a PNG or has another depth."""
    try:
        w, h, rows, info = png.Reader(filename=path).asDirect()
        data = np.array([np.asarray(r, dtype=np.uint16) for r in rows])
    except (png.Error, ValueError, OSError, EOFError) as e:
        raise DataFormatError(path, "a readable PNG file", f"{e}") from None
    if bits is not None and info["bitdepth"] != bits:
        raise DataFormatError(path, f"a {bits}-bit PNG", f"{info['bitdepth']} bits per channel")
    planes = int(info["planes"])
    if data.shape != (h, w * planes):
        raise DataFormatError(path, f"{h} rows of {w * planes} values", f"{data.shape}")
    return data.reshape(h, w, planes)[..., 0] if planes == 1 else data.reshape(h, w, planes)


def check_png_header(path: str, bits: int, shape: tuple[int, int], planes: int) -> None:
    """Check a PNG's header (no pixel is decoded): ``bits`` per channel, ``planes`` channels, ``shape = (H, W)``.
    Raises :class:`polyjax.DataFormatError` naming the file otherwise."""
    try:
        with open(path, "rb") as fh:
            r = png.Reader(file=fh)
            r.preamble()
            found = (int(r.bitdepth), int(r.planes), (int(r.height), int(r.width)))
    except (png.Error, ValueError, OSError, EOFError) as e:
        raise DataFormatError(path, "a readable PNG file", f"{e}") from None
    if found[0] != bits:
        raise DataFormatError(path, f"a {bits}-bit PNG (linear camera values)", f"{found[0]} bits per channel")
    if found[1:] != (planes, tuple(shape)):
        raise DataFormatError(path, f"{planes} channels of {shape[1]} x {shape[0]} pixels (the mask's)",
                              f"{found[1]} channels of {found[2][1]} x {found[2][0]}")


_MAT_TYPES = {1: "i1", 2: "u1", 3: "i2", 4: "u2", 5: "i4", 6: "u4", 7: "f4", 9: "f8", 12: "i8", 13: "u8"}


def read_mat_array(path: str, name: str) -> np.ndarray:
    """The real numeric array ``name`` of a MATLAB v5 ``.mat`` file, as float64 in C order (MATLAB stores it in
    Fortran order). Reads compressed (``miCOMPRESSED``) and plain ``miMATRIX`` elements of numeric classes; raises
    :class:`polyjax.DataFormatError` naming the file for anything else (v7.3/HDF5 files, complex data, structs)."""
    with open(path, "rb") as fh:
        raw = fh.read()
    if len(raw) < 128 or not raw[:10].startswith(b"MATLAB 5.0"):
        raise DataFormatError(path, "a MATLAB 5.0 MAT-file header", repr(raw[:10]))
    end = "<" if raw[126:128] == b"IM" else ">"
    pos, found = 128, []
    while pos + 8 <= len(raw):
        kind, size = struct.unpack(end + "II", raw[pos:pos + 8])
        body, pos = raw[pos + 8:pos + 8 + size], pos + 8 + size + (-size % 8 if kind != 15 else 0)
        if kind == 15:
            try:
                body = zlib.decompress(body)
            except zlib.error as e:
                raise DataFormatError(path, "a compressed element that decompresses", f"{e}") from None
            kind, size = struct.unpack(end + "II", body[:8])
            body = body[8:8 + size]
        if kind == 14:
            arr_name, arr = _mat_matrix(path, body, end)
            found.append(arr_name)
            if arr_name == name:
                return arr
    raise DataFormatError(path, f"a variable {name!r}", f"{found}")


def _mat_subelements(body: bytes, end: str):
    """The ``(type, bytes)`` sub-elements of a ``miMATRIX`` element (small ones packed in 4 bytes)."""
    pos, out = 0, []
    while pos + 8 <= len(body):
        kind, size = struct.unpack(end + "II", body[pos:pos + 8])
        if kind >> 16:  # small data element: size in the upper half, data in the next 4 bytes
            kind, size = kind & 0xFFFF, kind >> 16
            out.append((kind, body[pos + 4:pos + 4 + size]))
            pos += 8
        else:
            out.append((kind, body[pos + 8:pos + 8 + size]))
            pos += 8 + size + (-size % 8)
    return out


def _mat_matrix(path, body, end):
    """``(name, array)`` of one ``miMATRIX`` element of a numeric class."""
    parts = _mat_subelements(body, end)
    if len(parts) < 4:
        raise DataFormatError(path, "a matrix element of flags, dims, name, data", f"{len(parts)} parts")
    flags = struct.unpack(end + "I", parts[0][1][:4])[0]
    name = parts[2][1].decode("ascii", "replace")
    if not 6 <= (flags & 0xFF) <= 15 or flags & 0x800 or len(parts) != 4:
        return name, None  # not a real numeric array
    dims = np.frombuffer(parts[1][1], end + "i4")
    kind, data = parts[3]
    if kind not in _MAT_TYPES:
        raise DataFormatError(path, f"variable {name!r} of a numeric MAT type", f"type {kind}")
    values = np.frombuffer(data, end + _MAT_TYPES[kind]).astype(np.float64)
    if values.size != int(np.prod(dims)):
        raise DataFormatError(path, f"variable {name!r} of shape {tuple(dims)}", f"{values.size} values")
    return name, np.ascontiguousarray(values.reshape(tuple(dims), order="F"))


def _text_rows(path: str, cols: int | None) -> list:
    """Non-blank lines of a text file (split into ``cols`` floats when ``cols`` is given)."""
    if not os.path.isfile(path):
        raise DataNotFoundError(f"{path}: file not found (a DiLiGenT object folder holds filenames.txt, "
                                "light_directions.txt, light_intensities.txt, mask.png and the images)")
    with open(path) as fh:
        lines = [ln.strip() for ln in fh if ln.strip()]
    if cols is None:
        return lines
    try:
        rows = [[float(x) for x in ln.split()] for ln in lines]
    except ValueError as e:
        raise DataFormatError(path, f"rows of {cols} numbers", f"{e}") from None
    for i, r in enumerate(rows):
        if len(r) != cols or not np.all(np.isfinite(r)):
            raise DataFormatError(path, f"{cols} finite numbers on line {i + 1}", repr(lines[i]))
    return rows


def _lights(folder: str, lights):
    """Names, directions ``(L, 3)`` and intensities ``(L, 3)`` of the lights kept (``lights``: 0-based indices)."""
    names = _text_rows(os.path.join(folder, "filenames.txt"), None)
    d_path, e_path = os.path.join(folder, "light_directions.txt"), os.path.join(folder, "light_intensities.txt")
    dirs, ints = np.asarray(_text_rows(d_path, 3)), np.asarray(_text_rows(e_path, 3))
    for path, a in ((d_path, dirs), (e_path, ints)):
        if len(a) != len(names):
            raise DataFormatError(path, f"one row per image of filenames.txt ({len(names)})", f"{len(a)} rows")
    bad = np.flatnonzero(np.abs(np.linalg.norm(dirs, axis=1) - 1.0) > 1e-2)
    if bad.size:
        raise DataFormatError(d_path, f"a unit direction on line {bad[0] + 1}",
                              f"length {np.linalg.norm(dirs[bad[0]]):.4g}")
    if np.any(ints <= 0):
        raise DataFormatError(e_path, "positive intensities", f"line {np.argwhere(ints <= 0)[0, 0] + 1}")
    idx = np.arange(len(names)) if lights is None else np.asarray(lights, dtype=int).reshape(-1)
    if idx.size == 0 or np.any((idx < 0) | (idx >= len(names))):
        raise InputError(f"lights: expected indices in [0, {len(names)}) (lines of filenames.txt), found "
                         f"{np.asarray(lights).tolist()}")
    missing = [names[i] for i in idx if not os.path.isfile(os.path.join(folder, names[i]))]
    if missing:
        raise DataNotFoundError(f"{os.path.join(folder, missing[0])}: image not found ({len(missing)} of the "
                                f"{idx.size} images of filenames.txt are missing)")
    return tuple(names[i] for i in idx), dirs[idx] / np.linalg.norm(dirs[idx], axis=1, keepdims=True), ints[idx]


def _normals(folder: str, shape, mask) -> np.ndarray | None:
    """``(H, W, 3)`` unit normals from ``Normal_gt.mat`` or ``normal.txt``, checked on the mask (None: neither)."""
    mat, txt = os.path.join(folder, "Normal_gt.mat"), os.path.join(folder, "normal.txt")
    if os.path.isfile(mat):
        path, n = mat, read_mat_array(mat, "Normal_gt")
    elif os.path.isfile(txt):
        path, n = txt, np.asarray(_text_rows(txt, 3))
        if n.shape[0] != shape[0] * shape[1]:
            raise DataFormatError(txt, f"{shape[0] * shape[1]} rows (H x W = {shape})", f"{n.shape[0]}")
        n = n.reshape(shape[0], shape[1], 3)
    else:
        return None
    if n.shape != (shape[0], shape[1], 3):
        raise DataFormatError(path, f"normals of shape {(shape[0], shape[1], 3)}", f"{n.shape}")
    length = np.linalg.norm(n, axis=-1)
    bad = mask & ~(np.abs(length - 1.0) <= 1e-3) & (length > 0)  # zero: no normal known there
    if np.any(bad):
        i, j = np.argwhere(bad)[0]
        raise DataFormatError(path, "unit normals on the mask", f"{int(bad.sum())} that are not (pixel ({i}, {j}) "
                              f"has length {length[i, j]:.6g})")
    return np.where(mask[..., None], n / np.where(length > 0, length, 1.0)[..., None], np.array([0.0, 0.0, 1.0]))


def load_photometric(folder: str, lights: Sequence[int] | None = None):
    """Load a capture in DiLiGenT's layout (module notes) as a :class:`polyjax.Capture`.

    Args:
        folder: the object's folder (e.g. ``.../pmsData/ballPNG``).
        lights: 0-based indices of the lines of ``filenames.txt`` to load (None: every light).

    Returns:
        :class:`polyjax.Capture`: ``images (L, H, W, 3)`` in the camera's units (PNG value / 65535, or / 255 for
        8-bit images), ``mask``, ``normals`` (None without a normal file), ``quantisation`` (``1 / 65535`` or
        ``1 / 255``), ``light_directions``, ``light_intensities``, ``names`` and its ``scenes``.

    Raises:
        DataNotFoundError: the folder, a light file, the mask or an image is missing.
        DataFormatError: light files of other lengths than ``filenames.txt``, an image that is not RGB of the
            mask's size and of the first image's depth (16 or 8 bits), normals not of unit length on the mask, a
            malformed file (each naming the file).
        InputError: light indices out of range.
    """
    folder = os.fspath(folder)
    if not os.path.isdir(folder):
        raise DataNotFoundError(f"{folder}: not a folder (expected a DiLiGenT object folder, e.g. pmsData/ballPNG)")
    names, dirs, ints = _lights(folder, lights)
    mask_path = os.path.join(folder, "mask.png")
    if not os.path.isfile(mask_path):
        raise DataNotFoundError(f"{mask_path}: file not found (the object's mask)")
    mask = read_png(mask_path, bits=None)
    mask = (mask.max(axis=-1) if mask.ndim == 3 else mask) > 0
    normals = _normals(folder, mask.shape, mask)
    if normals is not None:  # mask pixels whose normal is a zero vector (unknown) leave the mask
        mask = mask & (np.linalg.norm(normals, axis=-1) > 0.5)
        normals = np.where(mask[..., None], normals, np.array([0.0, 0.0, 1.0]))
    bits = _bit_depth(os.path.join(folder, names[0]))
    for name in names:  # every header before any image is decoded
        check_png_header(os.path.join(folder, name), bits, mask.shape, 3)
    white = PNG16_MAX if bits == 16 else PNG8_MAX
    images = np.empty((len(names),) + mask.shape + (3,), np.float64)
    for i, name in enumerate(names):
        images[i] = read_png(os.path.join(folder, name), bits=bits) / white
    return Capture(images=images, mask=mask, normals=normals, light_directions=dirs, light_intensities=ints,
                   names=names, quantisation=1.0 / white)


def _bit_depth(path: str) -> int:
    """The bit depth of the first image (16 or 8; every image must share it). Raises
    :class:`polyjax.DataFormatError` naming the file for another depth."""
    try:
        with open(path, "rb") as fh:
            r = png.Reader(file=fh)
            r.preamble()
            bits = int(r.bitdepth)
    except (png.Error, ValueError, OSError, EOFError) as e:
        raise DataFormatError(path, "a readable PNG file", f"{e}") from None
    if bits not in (8, 16):
        raise DataFormatError(path, "a 16-bit or 8-bit PNG (linear camera values)", f"{bits} bits per channel")
    return bits


__all__ = ["PNG8_MAX", "PNG16_MAX", "check_png_header", "load_photometric", "read_mat_array", "read_png"]
