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
(``scipy.io.loadmat``). Every file is checked before any array reaches JAX, and its declared sizes before it is read:
a PNG's dimensions against the input cap (``POLYJAX_MAX_INPUT_MB``) and against what its compressed bytes can hold
(deflate inflates at most 1032-fold); a MAT-file's compressed elements inflated in chunks within the cap, every
element's byte count against what holds it, and the variable's shape against the cap; the text files' sizes against
the cap. A bad
file raises :class:`polyjax.DataFormatError` (or :class:`polyjax.DataNotFoundError`) naming it.
"""

from __future__ import annotations

import io
import os
import struct
import zlib
from typing import Sequence

import numpy as np
import png
import scipy.io

from .._config import given_or_under_root
from .._errors import DataFormatError, DataNotFoundError, InputError
from .._files import inside_folder
from .._reading.bounded import checked_size, read_bytes, read_text
from .._reading.limits import LIMIT_ENV, MAX_DEFLATE_RATIO, describe, input_limit
from ..inverse._capture import Capture

#: the camera's white level: a 16-bit PNG value is divided by it (and 1.0 is a saturated pixel)
PNG16_MAX = 65535.0
#: the same for 8-bit PNGs (linear values, e.g. DiLiGenT's cropped 8-bit copies)
PNG8_MAX = 255.0


_PNG_ERRORS = (png.Error, ValueError, OSError, EOFError, zlib.error, IndexError, TypeError, AssertionError)


def _png_reader(path: str, header_only: bool = False) -> png.Reader:
    """A pypng reader of the PNG ``path`` past its header, its dimensions checked: the decoded pixels (2 bytes a
    value) within the input cap, and the rows' bytes within what the file's size can inflate to. The file is read
    first (within the cap; its first 64 KiB when ``header_only`` and the header lies there): pypng then reads its
    chunks from memory, so a damaged chunk length never makes it allocate more than the file holds."""
    size = checked_size(path, None, "a PNG file")
    try:
        if header_only and size > 2**16:
            try:
                with open(path, "rb") as fh:
                    r = png.Reader(bytes=fh.read(2**16))
                r.preamble()
            except _PNG_ERRORS:  # chunks before the pixels longer than 64 KiB: read it all
                header_only = False
        if not header_only or size <= 2**16:
            r = png.Reader(bytes=read_bytes(path, None, "a PNG file"))
            r.preamble()
        h, w, planes, bits = int(r.height), int(r.width), int(r.planes), int(r.bitdepth)
    except _PNG_ERRORS as e:
        raise DataFormatError(path, "a readable PNG file", f"{e}") from None
    decoded, limit = 2 * h * w * planes, input_limit()
    if decoded > limit:
        raise DataFormatError(path, f"a PNG of at most {describe(limit)} of pixels (the cap {LIMIT_ENV})",
                              f"{w} x {h} pixels of {planes} channels ({describe(decoded)})")
    if h * (1 + (w * planes * bits + 7) // 8) > MAX_DEFLATE_RATIO * size + 1024:
        raise DataFormatError(path, f"{w} x {h} pixels of {planes} channels in at least "
                              f"1/{MAX_DEFLATE_RATIO} of their bytes (deflate's largest ratio)", f"{size} bytes")
    return r


def read_png(path: str, bits: int | None = 16) -> np.ndarray:
    """The pixels of a PNG as an integer array ``(H, W, channels)`` (``(H, W)`` for one channel), at its own bit
    depth (16-bit values are kept). ``bits``: the bit depth expected (None: any). Raises
    :class:`polyjax.DataFormatError` naming the file when it is not a PNG, has another depth, or declares more
    pixels than the input cap (``POLYJAX_MAX_INPUT_MB``) or its size can hold (checked before any pixel is
    decoded)."""
    r = _png_reader(path)
    if bits is not None and int(r.bitdepth) != bits:
        raise DataFormatError(path, f"a {bits}-bit PNG", f"{r.bitdepth} bits per channel")
    try:
        w, h, rows, info = r.asDirect()
        planes = int(info["planes"])
        data = np.empty((h, w * planes), np.uint16)  # filled row by row: the pixels are held once
        n = 0
        for row in rows:
            row = np.asarray(row, dtype=np.uint16)
            if n >= h or row.shape != (w * planes,):
                raise DataFormatError(path, f"{h} rows of {w * planes} values", f"row {n} of {row.shape[-1]} values")
            data[n] = row
            n += 1
    except _PNG_ERRORS as e:
        raise DataFormatError(path, "a readable PNG file", f"{e}") from None
    if bits is not None and info["bitdepth"] != bits:
        raise DataFormatError(path, f"a {bits}-bit PNG", f"{info['bitdepth']} bits per channel")
    if n != h:
        raise DataFormatError(path, f"{h} rows of {w * planes} values", f"{n} rows")
    return data.reshape(h, w, planes)[..., 0] if planes == 1 else data.reshape(h, w, planes)


def check_png_header(path: str, bits: int, shape: tuple[int, int], planes: int) -> None:
    """Check a PNG's header (no pixel is decoded): ``bits`` per channel, ``planes`` channels, ``shape = (H, W)``.
    Raises :class:`polyjax.DataFormatError` naming the file otherwise."""
    r = _png_reader(path, header_only=True)
    found = (int(r.bitdepth), int(r.planes), (int(r.height), int(r.width)))
    if found[0] != bits:
        raise DataFormatError(path, f"a {bits}-bit PNG (linear camera values)", f"{found[0]} bits per channel")
    if found[1:] != (planes, tuple(shape)):
        raise DataFormatError(path, f"{planes} channels of {shape[1]} x {shape[0]} pixels (the mask's)",
                              f"{found[1]} channels of {found[2][1]} x {found[2][0]}")


def _mat_shapes(path: str, raw: bytes) -> dict:
    """``{name: (shape, class)}`` of the variables of a MAT-file, from their headers (``scipy.io.whosmat``)."""
    try:
        return {name: (tuple(int(d) for d in shape), cls) for name, shape, cls in scipy.io.whosmat(io.BytesIO(raw))}
    except MemoryError:
        raise
    except Exception as e:  # noqa: BLE001  (scipy's parser raises many kinds on a damaged file: each is named here)
        raise DataFormatError(path, "a readable MATLAB 5 MAT-file", f"{type(e).__name__}: {e}") from None


#: the data types of MAT-file elements (MathWorks, *MAT-File Format*, table 1-1): 8, 10 and 11 are reserved
_MAT_TYPES = frozenset((1, 2, 3, 4, 5, 6, 7, 9, 12, 13, 14, 15, 16, 17, 18))


def _mat_elements(path: str, data: bytes, start: int, stop: int, end: str, depth: int = 0) -> None:
    """Check that every element tagged in ``data[start:stop]`` (and every element nested in a matrix, to depth 16)
    lies inside it: a byte count running past its parent is a DataFormatError naming the file."""
    pos = start
    while pos + 8 <= stop:
        kind, size = struct.unpack(end + "II", data[pos:pos + 8])
        if (kind & 0xFFFF if kind >> 16 else kind) not in _MAT_TYPES:  # scipy crashes on some others (type 0)
            raise DataFormatError(path, f"an element of a MAT data type {sorted(_MAT_TYPES)} at byte {pos}",
                                  f"type {kind & 0xFFFF if kind >> 16 else kind}")
        if kind >> 16:  # a small element: type and size in the first half, its data in the second
            pos += 8
            continue
        if pos + 8 + size > stop:
            raise DataFormatError(path, f"an element of {size} bytes at byte {pos} inside its parent",
                                  f"{stop - pos - 8} bytes left")
        if kind == 14 and depth < 16:  # miMATRIX: its sub-elements
            _mat_elements(path, data, pos + 8, pos + 8 + size, end, depth + 1)
            _mat_matrix_header(path, data, pos + 8, pos + 8 + size, end)
        pos += 8 + size + (-size % 8)


def _mat_matrix_header(path: str, data: bytes, start: int, stop: int, end: str) -> None:
    """A matrix's flags: an 8-byte miUINT32 of a class 1..15 and no undefined bits, and for a numeric class its
    sub-elements (flags, dims, name, real part, and an imaginary part when flagged complex): scipy reads past the
    element otherwise."""
    if stop - start < 16:
        return  # an empty matrix (scipy reads it as such)
    kind, size = struct.unpack(end + "II", data[start:start + 8])
    flags = struct.unpack(end + "I", data[start + 8:start + 12])[0] if (kind, size) == (6, 8) else None
    if flags is None or flags >> 16 or not 1 <= flags & 0xFF <= 15 or flags & 0xF100:
        raise DataFormatError(path, f"a matrix at byte {start - 8} with array flags (8 bytes of miUINT32, class 1 "
                              "to 15)", f"type {kind}, {size} bytes, flags {flags!r}")
    if 6 <= flags & 0xFF <= 15:
        count, pos = 0, start
        while pos + 8 <= stop:
            k, n = struct.unpack(end + "II", data[pos:pos + 8])
            pos += 8 if k >> 16 else 8 + n + (-n % 8)
            count += 1
        want = 5 if flags & 0x800 else 4
        if count != want:
            raise DataFormatError(path, f"a numeric matrix at byte {start - 8} of {want} parts (flags, dims, name, "
                                  "values" + (", imaginary values)" if want == 5 else ")"), f"{count} parts")


def _inflate(path: str, body: bytes, at: int, limit: int) -> bytes:
    """A compressed element's bytes inflated in chunks of 1 MiB, never more than ``limit`` of them."""
    inflater, out, rest = zlib.decompressobj(), bytearray(), body
    try:
        while rest and len(out) <= limit:
            out += inflater.decompress(rest, 2**20)
            rest = inflater.unconsumed_tail
    except zlib.error as e:
        raise DataFormatError(path, f"a compressed element at byte {at} that inflates", f"{e}") from None
    if len(out) > limit:
        raise DataFormatError(path, f"elements of at most {describe(limit)} inflated (the cap {LIMIT_ENV})",
                              f"the element at byte {at} inflating past it")
    return bytes(out)


def _mat_plain(path: str, raw: bytes, limit: int) -> bytes:
    """The MAT-file ``raw`` with every compressed element inflated (within ``limit`` in all) and every element's
    byte count checked against what holds it (:func:`_mat_elements`), for scipy to read with no size unchecked.
    Only version 5 files are read (scipy would read other headers as version 4)."""
    if len(raw) < 128 or not raw.startswith(b"MATLAB 5.0") or raw[126:128] not in (b"IM", b"MI"):
        raise DataFormatError(path, "a MATLAB 5.0 MAT-file header (128 bytes)", repr(raw[:20]))
    end, pos, out = ("<" if raw[126:128] == b"IM" else ">"), 128, bytearray(raw[:128])
    while pos + 8 <= len(raw):
        kind, size = struct.unpack(end + "II", raw[pos:pos + 8])
        if kind >> 16 or pos + 8 + size > len(raw):
            raise DataFormatError(path, f"an element of at most {len(raw) - pos - 8} bytes at byte {pos}",
                                  f"the tag of type {kind & 0xFFFF}, {size} bytes")
        if kind == 15:  # miCOMPRESSED: one element, compressed
            element = _inflate(path, raw[pos + 8:pos + 8 + size], pos, limit - len(out))
            pos += 8 + size
        else:
            element = raw[pos:pos + 8 + size + (-size % 8)]
            pos += 8 + size + (-size % 8)
        _mat_elements(path, element, 0, len(element), end)
        out += element + bytes(-len(element) % 8)
    return bytes(out)


def read_mat_array(path: str, name: str) -> np.ndarray:
    """The real numeric array ``name`` of a MATLAB v5 ``.mat`` file, as float64 in C order, read by
    ``scipy.io.loadmat``. Sizes are checked first: the file's against the input cap (``POLYJAX_MAX_INPUT_MB``),
    what its compressed elements inflate to (in chunks, within the cap), every element's byte count against what
    holds it, and the variable's declared shape against the cap and the bytes held. Raises
    :class:`polyjax.DataFormatError` naming the file for anything else (v7.3/HDF5 files, complex data, structs,
    damaged elements)."""
    limit = input_limit()
    raw = _mat_plain(path, read_bytes(path, limit, "a MATLAB MAT-file"), limit)
    held = len(raw)
    shapes = _mat_shapes(path, raw)
    if name not in shapes:
        raise DataFormatError(path, f"a variable {name!r}", f"{sorted(shapes)}")
    shape, cls = shapes[name]
    count = int(np.prod(shape, dtype=object))
    if 8 * count > limit or count > held:
        raise DataFormatError(path, f"variable {name!r} of at most {describe(limit)} as float64 (the cap "
                              f"{LIMIT_ENV}) and at most one value a byte its elements hold ({held})",
                              f"the shape {shape} ({describe(8 * count)})")
    try:
        arr = scipy.io.loadmat(io.BytesIO(raw), variable_names=[name], squeeze_me=False)[name]
    except MemoryError:
        raise
    except Exception as e:  # noqa: BLE001  (scipy's parser raises many kinds on a damaged file: each is named here)
        raise DataFormatError(path, f"a readable variable {name!r}", f"{type(e).__name__}: {e}") from None
    if not isinstance(arr, np.ndarray) or arr.dtype.kind not in "biuf" or arr.shape != shape:
        raise DataFormatError(path, f"variable {name!r}: a real numeric array of shape {shape}",
                              f"{cls} {getattr(arr, 'dtype', type(arr).__name__)} {getattr(arr, 'shape', '')}")
    return np.ascontiguousarray(arr, dtype=np.float64)


def _text_rows(path: str, cols: int | None) -> list:
    """Non-blank lines of a text file (split into ``cols`` floats when ``cols`` is given)."""
    if not os.path.isfile(path):
        raise DataNotFoundError(f"{path}: file not found (a DiLiGenT object folder holds filenames.txt, "
                                "light_directions.txt, light_intensities.txt, mask.png and the images)")
    lines = [ln.strip() for ln in read_text(path, None, "a text file of the capture").splitlines() if ln.strip()]
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
    for i, name in enumerate(names):
        inside_folder(folder, name, os.path.join(folder, "filenames.txt"), f"line {i + 1}")
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


#: the folders below the data root where :func:`resolve_photometric_folder` looks for an object's folder by name
PHOTOMETRIC_FOLDERS = ("diligent", "diligent/crop8")


def resolve_photometric_folder(folder: str | os.PathLike, root: str | os.PathLike | None = None) -> str:
    """The object's folder as given, else ``<data root>/diligent/<folder>`` or ``<data root>/diligent/crop8/<folder>``
    (:data:`PHOTOMETRIC_FOLDERS`, e.g. ``"catPNG"``); :class:`polyjax.DataNotFoundError` naming every place tried
    when none is a folder."""
    folder = os.fspath(folder)
    found, tried = given_or_under_root(folder, [os.path.join(sub, folder) for sub in PHOTOMETRIC_FOLDERS],
                                       os.path.isdir, root)
    if found is not None:
        return os.fspath(found)
    raise DataNotFoundError(f"{folder}: not a folder (expected a DiLiGenT object folder, e.g. pmsData/ballPNG, or "
                            f"an object's name under the data root's {' or '.join(PHOTOMETRIC_FOLDERS)}; looked at "
                            f"{', '.join(tried)})")


def load_photometric(folder: str, lights: Sequence[int] | None = None, *, root: str | os.PathLike | None = None):
    """Load a capture in DiLiGenT's layout (module notes) as a :class:`polyjax.Capture`.

    Args:
        folder: the object's folder (e.g. ``.../pmsData/ballPNG``), or its name under the data root's
            ``diligent/`` or ``diligent/crop8/`` (e.g. ``"catPNG"``; :func:`resolve_photometric_folder`).
        lights: 0-based indices of the lines of ``filenames.txt`` to load (None: every light).
        root: data root (default ``$POLYJAX_DATA``), for a folder given by name.

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
    folder = resolve_photometric_folder(folder, root)
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
    :class:`polyjax.DataFormatError` naming the file for another depth. The header is read as
    :func:`check_png_header` reads it (from memory): pypng reading a file object asks it for a whole chunk at once,
    and a damaged chunk length (a flipped bit of ``IHDR``'s) made it allocate up to 2 GiB for a file of 200 bytes."""
    bits = int(_png_reader(path, header_only=True).bitdepth)
    if bits not in (8, 16):
        raise DataFormatError(path, "a 16-bit or 8-bit PNG (linear camera values)", f"{bits} bits per channel")
    return bits


__all__ = ["PNG8_MAX", "PNG16_MAX", "check_png_header", "load_photometric", "read_mat_array", "read_png"]
