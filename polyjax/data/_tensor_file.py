r"""Mitsuba's ``tensor_file`` container (``TensorFile`` in Mitsuba 3, ``Tensor`` in the RGL-EPFL ``brdf-loader``).

Layout (little-endian):

- 12 bytes ``"tensor_file\0"``; version, 2 x uint8, ``(1, 0)``; uint32 field count;
- per field: uint16 name length, the name (ASCII), uint16 ``ndim``, uint8 dtype (Mitsuba's ``Struct`` type codes:
  1 uint8, 2 int8, 3 uint16, 4 int16, 5 uint32, 6 int32, 7 uint64, 8 int64, 9 float16, 10 float32, 11 float64),
  uint64 byte offset of the data, ``ndim`` x uint64 shape;
- each field's data, C order, at its offset.

:func:`read_tensor_file` checks every byte count against the file's size before reading, so a truncated or foreign
file is a :class:`polyjax.DataFormatError` naming the file, never a short read; the file itself is read only when its
size is within the input cap (``POLYJAX_MAX_INPUT_MB``), and a field with a zero-sized dimension is refused.
:func:`write_tensor_file` writes the same layout (each field's data 8-byte aligned, as Mitsuba's own writer), whole
or not at all.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .._errors import DataNotFoundError, InputError
from .._files import write_bytes_atomically
from .._reading.bounded import read_bytes
from ._errors import EmptyFileError, HeaderError, TruncatedFileError, WrongFormatError

MAGIC = b"tensor_file\0"
#: Mitsuba ``Struct`` type codes of a ``tensor_file`` field -> numpy dtypes (little-endian).
DTYPES = {1: "u1", 2: "i1", 3: "<u2", 4: "<i2", 5: "<u4", 6: "<i4", 7: "<u8", 8: "<i8", 9: "<f2", 10: "<f4",
          11: "<f8"}
_MAX_FIELDS = 4096
_MAX_NDIM = 16


class _Cursor:
    """Reads little-endian integers from the header, raising :class:`TruncatedFileError` past the end."""

    def __init__(self, path: Path, data: bytes, start: int):
        self.path, self.data, self.pos = path, data, start

    def take(self, n: int, what: str) -> bytes:
        if self.pos + n > len(self.data):
            raise TruncatedFileError(self.path, f"{n} bytes for {what} at byte {self.pos}",
                                     f"a file of {len(self.data)} bytes")
        out = self.data[self.pos:self.pos + n]
        self.pos += n
        return out

    def uint(self, size: int, what: str) -> int:
        return int.from_bytes(self.take(size, what), "little")


def _read_bytes(path) -> tuple[Path, bytes]:
    path = Path(path)
    if not path.is_file():
        raise DataNotFoundError(f"{path}: no such tensor file (a Mitsuba/RGL-EPFL '.bsdf' file)")
    data = read_bytes(path, what="a Mitsuba tensor_file")
    if not data:
        raise EmptyFileError(path, "a Mitsuba tensor_file", "an empty file (0 bytes)")
    if len(data) < len(MAGIC) + 6:
        raise TruncatedFileError(path, f"at least {len(MAGIC) + 6} bytes (header, version, field count)",
                                 f"{len(data)} bytes")
    if data[:len(MAGIC)] != MAGIC:
        raise WrongFormatError(path, "a Mitsuba tensor_file (starting with the 12 bytes 'tensor_file\\0')",
                               f"the bytes {data[:12]!r}")
    if tuple(data[12:14]) != (1, 0):
        raise HeaderError(path, "tensor_file version (1, 0)", f"version {tuple(data[12:14])}")
    return path, data


def _read_field(cur: _Cursor, index: int):
    path = cur.path
    name_bytes = cur.take(cur.uint(2, f"the name length of field {index}"), f"the name of field {index}")
    try:
        name = name_bytes.decode("ascii")
    except UnicodeDecodeError:
        raise HeaderError(path, f"an ASCII name for field {index}", f"the bytes {name_bytes[:40]!r}") from None
    ndim = cur.uint(2, f"the rank of field {name!r}")
    code = cur.uint(1, f"the dtype of field {name!r}")
    offset = cur.uint(8, f"the offset of field {name!r}")
    if ndim > _MAX_NDIM:
        raise HeaderError(path, f"at most {_MAX_NDIM} dimensions for field {name!r}", f"{ndim}")
    if code not in DTYPES:
        raise HeaderError(path, f"a tensor_file dtype code {sorted(DTYPES)} for field {name!r}", f"code {code}")
    shape = tuple(cur.uint(8, f"the shape of field {name!r}") for _ in range(ndim))
    if 0 in shape:
        raise HeaderError(path, f"a field {name!r} of at least one value in each dimension", f"the shape {shape}")
    dtype = np.dtype(DTYPES[code])
    nbytes = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if offset + nbytes > len(cur.data):
        raise TruncatedFileError(path, f"{nbytes} bytes of field {name!r} {shape} {dtype.name} at byte {offset}",
                                 f"a file of {len(cur.data)} bytes ({offset + nbytes - len(cur.data)} missing)")
    values = np.frombuffer(cur.data, dtype, int(np.prod(shape, dtype=object)), offset).reshape(shape)
    return name, values


def read_tensor_file(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Read every field of a ``tensor_file`` (module docstring) as read-only numpy arrays of the stored dtype.

    Args:
        path: the file.

    Returns:
        ``{name: array}`` in file order.

    Raises:
        DataNotFoundError: no such file.
        DataFormatError: not a tensor file, an unknown version or dtype, a header or data past the end of the file,
            a field named twice (:class:`TruncatedFileError`, :class:`WrongFormatError`, :class:`HeaderError`).
    """
    path, data = _read_bytes(path)
    cur = _Cursor(path, data, len(MAGIC) + 2)
    count = cur.uint(4, "the field count")
    if count > _MAX_FIELDS:
        raise HeaderError(path, f"a field count of at most {_MAX_FIELDS}", f"{count}")
    fields: dict[str, np.ndarray] = {}
    for i in range(count):
        name, values = _read_field(cur, i)
        if name in fields:
            raise HeaderError(path, "each field named once", f"the field {name!r} twice")
        fields[name] = values
    return fields



#: numpy dtypes -> Mitsuba ``Struct`` type codes (the inverse of :data:`DTYPES`)
_CODES = {np.dtype(v): k for k, v in DTYPES.items()}


def tensor_file_bytes(fields: dict[str, np.ndarray]) -> bytes:
    """The bytes of a ``tensor_file`` holding ``fields`` (``{ASCII name: array}``, in order; module docstring).

    Raises:
        InputError: a name that is not ASCII or over 65,535 bytes, a dtype without a ``tensor_file`` code, an empty
            array or more than 16 dimensions.
    """
    arrays = {}
    for name, a in fields.items():
        a = np.ascontiguousarray(a)
        a = a.astype(a.dtype.newbyteorder("<")) if a.dtype.byteorder == ">" else a
        if not name.isascii() or not 0 < len(name) < 1 << 16:
            raise InputError(f"tensor_file field {name!r}: expected a non-empty ASCII name")
        if a.dtype not in _CODES or a.size == 0 or a.ndim > _MAX_NDIM:
            raise InputError(f"tensor_file field {name!r}: expected a non-empty array of at most {_MAX_NDIM} "
                             f"dimensions of one of {sorted(str(d) for d in _CODES)}, found {a.dtype} {a.shape}")
        arrays[name] = a
    pos = len(MAGIC) + 6 + sum(2 + len(k) + 11 + 8 * a.ndim for k, a in arrays.items())
    offsets = []
    for a in arrays.values():
        pos += -pos % 8
        offsets.append(pos)
        pos += a.nbytes
    out = bytearray(MAGIC + bytes((1, 0)) + np.uint32(len(arrays)).astype("<u4").tobytes())
    for (name, a), offset in zip(arrays.items(), offsets):
        out += np.uint16(len(name)).astype("<u2").tobytes() + name.encode("ascii")
        out += np.uint16(a.ndim).astype("<u2").tobytes() + bytes((_CODES[a.dtype],))
        out += np.uint64(offset).astype("<u8").tobytes() + np.asarray(a.shape, "<u8").tobytes()
    for a, offset in zip(arrays.values(), offsets):
        out += bytes(offset - len(out)) + a.tobytes()
    return bytes(out)


def write_tensor_file(path: str | os.PathLike, fields: dict[str, np.ndarray]) -> Path:
    """Write ``fields`` as a ``tensor_file`` at ``path`` (:func:`tensor_file_bytes`), atomically; returns the path."""
    return write_bytes_atomically(path, tensor_file_bytes(fields))
