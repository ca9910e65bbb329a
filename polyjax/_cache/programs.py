"""A compiled executable on disk without pickle of polyjax's own: the file format of every saved program
(:mod:`polyjax._fit.saved`, ``baselines``' saved fits through :mod:`polyjax.internal`).

``jax.experimental.serialize_executable.serialize`` gives the executable's bytes and two tree structures (of its
arguments and of its results). A saved program file is::

    polyjax-program 1\\n
    {"sha256": ..., "bytes": N, "in_tree": ..., "out_tree": ..., "extra": {...}}\\n   (one line of JSON)
    <N bytes: the executable>

The trees are written as plain JSON (:func:`describe_tree`: tuples, lists, dicts with string keys, None and array
leaves; any other node refuses to be saved) and rebuilt from it (:func:`tree_of`); the executable's bytes are
checked against their SHA-256 digest before JAX reads them. Nothing in the file is unpickled by polyjax; the bytes
are JAX's own serialisation of an executable, handed to JAX only after the file and its folder passed
:func:`polyjax._files.trusted` (owned by the current user, writable by no one else) and the digest matched.
"""

from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import jax
from jax.experimental import serialize_executable

from .._errors import DataFormatError
from .._files import make_cache_folder, trusted, write_bytes_atomically
from .compilation import note_cache_write

_MAGIC = b"polyjax-program 1\n"
#: the longest header line read (the trees' description); a longer one is not a saved program
_MAX_HEADER = 1 << 20
_LEAF = "*"


def describe_tree(treedef) -> object:
    """A JSON value describing ``treedef``: ``"*"`` a leaf, ``null`` None, ``{"tuple": [...]}``,
    ``{"list": [...]}``, ``{"dict": [[key, ...], ...]}`` (string keys).

    Raises:
        TypeError: a node of any other kind (a named tuple, a custom pytree), which is then not saved.
    """
    leaves = jax.tree_util.tree_unflatten(treedef, [_Leaf()] * treedef.num_leaves)

    def walk(x):
        if isinstance(x, _Leaf):
            return _LEAF
        if x is None:
            return None
        if type(x) is tuple:
            return {"tuple": [walk(e) for e in x]}
        if type(x) is list:
            return {"list": [walk(e) for e in x]}
        if type(x) is dict and all(isinstance(k, str) for k in x):
            return {"dict": [[k, walk(v)] for k, v in x.items()]}
        raise TypeError(f"a tree node of type {type(x).__name__} is not kept in a saved program")

    described = walk(leaves)
    if tree_of(described) != treedef:
        raise TypeError("the tree's description does not rebuild it")
    return described


class _Leaf:
    """A placeholder leaf while a tree is described."""


def tree_of(described) -> object:
    """The tree structure (``PyTreeDef``) that :func:`describe_tree` described.

    Raises:
        ValueError: a description that is not one.
    """

    def build(d):
        if d == _LEAF:
            return 0
        if d is None:
            return None
        if isinstance(d, dict) and len(d) == 1:
            (kind, items), = d.items()
            if kind in ("tuple", "list") and isinstance(items, list):
                seq = [build(e) for e in items]
                return tuple(seq) if kind == "tuple" else seq
            if kind == "dict" and isinstance(items, list) and all(
                    isinstance(p, list) and len(p) == 2 and isinstance(p[0], str) for p in items):
                return {k: build(v) for k, v in items}
        raise ValueError(f"not a tree description: {str(d)[:80]}")

    return jax.tree_util.tree_structure(build(described))


def save_program(path: str | os.PathLike, compiled, extra: dict | None = None) -> bool:
    """Write the executable ``compiled`` (a :class:`jax.stages.Compiled`) to ``path`` in the format of the module
    docstring, with ``extra`` (JSON values) in its header; the folder is created (mode ``0700``) when missing.
    Returns False, writing nothing, when the folder may not be trusted (:func:`polyjax._files.trusted`, warned once).

    Raises:
        TypeError: trees that cannot be described. OSError: the file cannot be written. Anything JAX raises
        serialising the executable.
    """
    path = Path(path)
    make_cache_folder(path.parent, mark=False)
    if not trusted(path.parent, what="saved programs"):
        return False
    payload, in_tree, out_tree = serialize_executable.serialize(compiled)
    header = {"sha256": hashlib.sha256(payload).hexdigest(), "bytes": len(payload), "in_tree": describe_tree(in_tree),
              "out_tree": describe_tree(out_tree), "extra": extra or {}}
    line = json.dumps(header, separators=(",", ":")).encode()
    write_bytes_atomically(path, _MAGIC + line + b"\n" + payload, mode=0o600)
    note_cache_write()
    return True


def _read(path: Path) -> tuple[dict, bytes]:
    """The header and the checked executable bytes of the saved program at ``path``."""
    with open(path, "rb") as f:
        if f.read(len(_MAGIC)) != _MAGIC:
            raise DataFormatError(path, "a polyjax saved program", "another file")
        line = f.readline(_MAX_HEADER)
        try:
            header = json.loads(line)
            size, digest = int(header["bytes"]), str(header["sha256"])
        except (ValueError, KeyError, TypeError):
            raise DataFormatError(path, "a saved program's JSON header", "an unreadable one") from None
        if size < 0 or size != os.fstat(f.fileno()).st_size - f.tell():
            raise DataFormatError(path, f"{size} bytes of executable", "another size")
        payload = f.read(size)
    if hashlib.sha256(payload).hexdigest() != digest:
        raise DataFormatError(path, "executable bytes matching their SHA-256 digest", "other bytes")
    return header, payload


def load_lapack_kernels() -> None:
    """The LAPACK kernels are set up when a program using them is lowered; a loaded executable skips that step."""
    from jaxlib.cpu import _lapack  # private jaxlib API: only a loaded executable needs it

    _lapack.initialize()


def load_program(path: str | os.PathLike, backend=None):
    """``(executable, extra)`` of the saved program at ``path``, or None when there is none or it may not be
    trusted (the file or its folder owned by another user or writable by others: warned once, naming the folder
    and the reason; the caller compiles afresh).

    Raises:
        DataFormatError: a damaged file (its header, size or digest). Anything JAX raises loading the bytes.
    """
    path = Path(path)
    if not path.is_file() or not trusted(path.parent, path, what="saved programs"):
        return None
    header, payload = _read(path)
    try:
        in_tree, out_tree = tree_of(header["in_tree"]), tree_of(header["out_tree"])
    except (KeyError, ValueError):
        raise DataFormatError(path, "a saved program's tree descriptions", "unreadable ones") from None
    extra = header.get("extra") if isinstance(header.get("extra"), dict) else {}
    load_lapack_kernels()
    return serialize_executable.deserialize_and_load(payload, in_tree, out_tree, backend), extra


__all__ = ["describe_tree", "load_lapack_kernels", "load_program", "save_program", "tree_of"]
