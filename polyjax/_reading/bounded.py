"""Readers of the containers several loaders share, each checking declared sizes before it reads.

- :func:`checked_size`, :func:`read_bytes`: a file read whole, after its size on disk is checked against the cap.
- :func:`read_zip_member`: a zip member, its declared size checked against the cap and against deflate's largest
  ratio to its compressed size, then inflated in chunks of 1 MiB, never more than the cap.
- :func:`read_npz`: the arrays of an ``.npz`` (a zip of ``.npy`` members), each member's ``.npy`` header (shape,
  dtype) read first and checked: a numeric dtype, a size within the cap, and exactly the bytes the member holds.
- :func:`load_json`: a JSON document after its size is checked, with integers of at most
  :data:`~polyjax._reading.limits.JSON_MAX_DIGITS` digits and nesting Python can follow.

Every fault is a :class:`polyjax.DataFormatError` (or :class:`~polyjax.data.TruncatedFileError`) naming the file,
what was expected (the cap and where it is set) and what was found.
"""

from __future__ import annotations

import json
import os
import tokenize
import zipfile
import zlib

import numpy as np

from .._errors import DataFormatError
from .limits import JSON_MAX_DIGITS, LIMIT_ENV, MAX_DEFLATE_RATIO, describe, input_limit

_CHUNK = 2**20
#: dtype kinds an array of a data file may have: bool, integers, floats
NUMERIC_KINDS = "biuf"


def checked_size(path, limit: int | None = None, what: str = "a file") -> int:
    """The size of ``path`` on disk, or a DataFormatError when it is over ``limit`` (default :func:`input_limit`)."""
    limit = input_limit() if limit is None else limit
    try:
        size = os.stat(path).st_size
    except OSError as e:
        raise DataFormatError(path, f"{what} that can be read", f"{e.strerror or e}") from None
    if size > limit:
        raise DataFormatError(path, f"{what} of at most {describe(limit)} (the cap {LIMIT_ENV})", describe(size))
    return size


def read_bytes(path, limit: int | None = None, what: str = "a file") -> bytes:
    """The bytes of ``path``, read after :func:`checked_size` (and never more than the cap if it grows)."""
    limit = input_limit() if limit is None else limit
    size = checked_size(path, limit, what)
    try:
        with open(path, "rb") as fh:  # read(n) allocates n bytes first: the size on disk, not the cap
            data = fh.read(min(size, limit) + 1)
    except OSError as e:
        raise DataFormatError(path, f"{what} that can be read", f"{e.strerror or e}") from None
    if len(data) > min(size, limit):
        raise DataFormatError(path, f"{what} of {size} bytes, as when its size was read", "a file that grew")
    return data


def read_text(path, limit: int | None = None, what: str = "a text file") -> str:
    """:func:`read_bytes` decoded as UTF-8 (else a DataFormatError: binary content)."""
    data = read_bytes(path, limit, what)
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError as e:
        raise DataFormatError(path, what, f"bytes that are not UTF-8 text (byte {e.start})") from None


def _check_declared(path, name: str, declared: int, stored: int, limit: int, cap: str = LIMIT_ENV) -> None:
    where = f"member {name!r}"
    if declared > limit:
        raise DataFormatError(path, f"{where} of at most {describe(limit)} inflated (the cap {cap})",
                              f"a declared size of {describe(declared)}")
    if declared > MAX_DEFLATE_RATIO * stored + 64:
        raise DataFormatError(path, f"{where} of at most {MAX_DEFLATE_RATIO} times its {stored} stored bytes "
                              "(deflate's largest ratio)", f"a declared size of {describe(declared)}")


def read_zip_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path, limit: int | None = None,
                    cap: str = LIMIT_ENV) -> bytes:
    """The inflated bytes of ``info`` in ``zf`` (the archive ``path``): its declared size checked against ``limit``
    (default :func:`input_limit`; ``cap`` says where it is set) and deflate's ratio, then read in chunks, never past
    the declared size."""
    limit = input_limit() if limit is None else limit
    _check_declared(path, info.filename, info.file_size, info.compress_size, limit, cap)
    out = bytearray()
    try:
        with zf.open(info) as fh:
            while len(out) <= info.file_size:
                chunk = fh.read(min(_CHUNK, info.file_size + 1 - len(out)))
                if not chunk:
                    break
                out += chunk
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError, RuntimeError, ValueError) as e:
        raise DataFormatError(path, f"a readable zip member {info.filename!r}", f"{type(e).__name__}: {e}") from None
    if len(out) != info.file_size:
        raise DataFormatError(path, f"{info.file_size} bytes in member {info.filename!r} (its declared size)",
                              f"{len(out)} bytes")
    return bytes(out)


def open_zip(path, what: str) -> zipfile.ZipFile:
    """``zipfile.ZipFile(path)`` after :func:`checked_size`; a DataFormatError when it is not a zip archive."""
    checked_size(path, None, what)
    try:
        return zipfile.ZipFile(path)
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, ValueError, NotImplementedError) as e:
        raise DataFormatError(path, what, f"a file that is not a readable zip archive ({e})") from None


def zip_members(zf: zipfile.ZipFile, path, what: str) -> list[zipfile.ZipInfo]:
    """The archive's members (``zf.infolist()``), each with a name: a damaged central directory can give a member
    an empty name, on which ``zipfile``'s own ``ZipInfo.is_dir`` fails with an IndexError; a DataFormatError
    naming the file instead."""
    infos = zf.infolist()
    for k, info in enumerate(infos):
        if not info.filename:
            raise DataFormatError(path, f"{what}: members with names", f"member {k} without a name (a damaged "
                                  "central directory)")
    return infos


def _npy_header(fh, path, name: str, kinds: str) -> tuple[tuple[int, ...], bool, np.dtype]:
    """``(shape, fortran_order, dtype)`` from the ``.npy`` header at the start of ``fh``."""
    try:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, fortran, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise ValueError(f"unsupported .npy version {version}")
    except (ValueError, TypeError, SyntaxError, tokenize.TokenError, RecursionError, MemoryError, OSError, EOFError,
            zipfile.BadZipFile, zlib.error) as e:  # numpy parses the header as Python text: its errors are these
        raise DataFormatError(path, f"an .npy header in member {name!r}", f"{type(e).__name__}: {e}") from None
    if dtype.kind not in kinds or dtype.hasobject or dtype.subdtype is not None:
        raise DataFormatError(path, f"a numeric array in member {name!r}", f"dtype {dtype.str}")
    return tuple(int(s) for s in shape), bool(fortran), dtype


def _npz_member(zf: zipfile.ZipFile, info: zipfile.ZipInfo, path, budget: int, kinds: str) -> np.ndarray:
    """One ``.npy`` member: header checked against the member's size and ``budget``, then read in place."""
    name = info.filename
    _check_declared(path, name, info.file_size, info.compress_size, budget)
    try:
        with zf.open(info) as fh:
            shape, fortran, dtype = _npy_header(fh, path, name, kinds)
            count = int(np.prod(shape, dtype=object))
            nbytes = count * dtype.itemsize
            if fh.tell() + nbytes != info.file_size:
                raise DataFormatError(path, f"{info.file_size - fh.tell()} bytes of data in member {name!r} "
                                      "(its size less its header)", f"a header of shape {shape} {dtype.str} "
                                      f"({describe(nbytes)})")
            buf = np.empty(nbytes, np.uint8)
            view, got = memoryview(buf), 0
            while got < nbytes:
                k = fh.readinto(view[got:got + _CHUNK])
                if not k:
                    break
                got += k
    except (zipfile.BadZipFile, zlib.error, OSError, EOFError, NotImplementedError, RuntimeError) as e:
        raise DataFormatError(path, f"a readable member {name!r}", f"{type(e).__name__}: {e}") from None
    if got != nbytes:
        raise DataFormatError(path, f"{nbytes} bytes of data in member {name!r}", f"{got} bytes")
    return buf.view(dtype).reshape(shape, order="F" if fortran else "C")


def read_npz(path, what: str = "an .npz archive of arrays", kinds: str = NUMERIC_KINDS) -> dict[str, np.ndarray]:
    """``{name: array}`` of every ``.npy`` member of the ``.npz`` ``path`` (names without ``.npy``), each header
    checked before its data is read, all of them together within :func:`input_limit`; dtypes of ``kinds`` only
    (numeric by default; never objects, so nothing is unpickled)."""
    limit = input_limit()
    out: dict[str, np.ndarray] = {}
    with open_zip(path, what) as zf:
        budget = limit
        for info in zip_members(zf, path, what):
            if info.is_dir():
                continue
            if not info.filename.endswith(".npy"):
                raise DataFormatError(path, f"{what}: .npy members only", f"the member {info.filename!r}")
            arr = _npz_member(zf, info, path, budget, kinds)
            budget -= arr.nbytes
            out[info.filename[:-4]] = arr
    return out


class _HugeInteger(ValueError):
    pass


def _bounded_int(text: str) -> int:
    if len(text.lstrip("-")) > JSON_MAX_DIGITS:
        raise _HugeInteger(text)
    return int(text)


def parse_json(text: str | bytes, path, what: str):
    """``json.loads(text)`` of the file ``path`` with integers of at most :data:`JSON_MAX_DIGITS` digits, and any
    fault (invalid JSON, nesting deeper than Python can follow, a huge integer) a DataFormatError naming it."""
    try:
        return json.loads(text, parse_int=_bounded_int)
    except _HugeInteger as e:
        raise DataFormatError(path, f"{what} with integers of at most {JSON_MAX_DIGITS} digits",
                              f"an integer of {len(str(e).lstrip('-'))} digits") from None
    except RecursionError:
        raise DataFormatError(path, what, "JSON nested deeper than can be read") from None
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise DataFormatError(path, what, f"invalid JSON ({e})") from None


def load_json(path, what: str):
    """The JSON document in ``path`` (:func:`parse_json`), its size checked first against :func:`json_limit`."""
    return parse_json(read_bytes(path, json_limit(), what), path, what)


def json_limit() -> int:
    """The byte cap of a JSON file: a 16th of :func:`input_limit` (Python's objects take ~16 times the text)."""
    return max(input_limit() // 16, 1)

