"""Saved executables of :func:`baselines.fit`: a warm first fit in a fresh process neither traces, lowers nor compiles.

JAX's persistent compilation cache saves the compiling, but every process still traces and lowers each program to
find its cache key; for the multi-start kernel (a vmapped Levenberg-Marquardt loop inside a loop of jobs) that is
seconds, most of a warm first fit. So, as :mod:`polyjax._fit.saved` does for ``polyjax fit``, the whole fit of concrete
inputs (input preparation, the kernel, the kept optimum and the result codes) is one jitted program, compiled ahead
of time and serialised (:mod:`jax.experimental.serialize_executable`) into ``<cache folder>/polyjax-programs/``, keyed
the way :mod:`polyjax._fit.saved` keys its programs: the input shapes and dtypes (and which are None), every option
of the fit, the versions of JAX and jaxlib, the machine and its device kind, float64 on or off, XLA's options, and the
source files of polyjax and baselines (their sizes and modification times). A later process with the same key loads
the executable and runs it; within a process the last 16 executables stay loaded. The file is written and read by
:func:`polyjax.internal.save_program` / :func:`polyjax.internal.load_program` (no pickle, the executable's digest
checked, nothing loaded from a folder or file that another user owns or others may write).

It is on whenever JAX's persistent compilation cache is (:func:`polyjax.enable_compilation_cache`, on by default in
the command line), and off with ``POLYJAX_SAVED_PROGRAMS=off`` or ``POLYJAX_CACHE=off``. The program takes the
inputs traced, so its result is that of a ``jit``-ted call of :func:`baselines.fit`; it is used only where that is
the eager call's result too: concrete inputs (not under ``jit``, ``grad`` or ``vmap``) on one device, finite
directions, values, weights and starts, non-negative weights (an eager call raises where a traced one flags the
lane). Elsewhere the ordinary call runs, silently. A saved program that cannot be read, compiled, written or run is
reported once per process and kind of failure as a :class:`SavedProgramWarning` with its reason, then the fit goes
on without it (a file that cannot be read is compiled and written again). The key knows the source files, not
functions replaced at run time: a process that patches baselines' internals turns saved programs off.
"""

from __future__ import annotations

import dataclasses
import hashlib
import os
import warnings
from pathlib import Path

import jax
import numpy as np

import polyjax as pj
from polyjax.internal import SAVED_PROGRAMS_ENV as ENV
from polyjax.internal import SAVED_PROGRAMS_FOLDER as FOLDER
from polyjax.internal import (
    cache_disabled_by_env,
    compile_for_saving,
    load_program,
    program_key,
    save_program,
    source_stamp,
)

from ._result import BaselineFit

_OFF = ("off", "0", "no", "false", "none")
#: XLA's options for these programs: its elemental code generation instead of its fusion emitters and LLVM's
#: optimisation level 1. On the multi-start kernel this compiles 2.7x faster than XLA's defaults and runs as fast
#: or faster (Ward, CUReT 25, 16 starts: compile 3.1 s against 8.6 s, fit 1.5 ms against 2.2 ms, on a loaded
#: 2-core machine); an XLA that does not know them compiles with its defaults.
COMPILER_OPTIONS = {"xla_cpu_use_fusion_emitters": False, "xla_backend_optimization_level": 1}
_FIELDS = tuple(f.name for f in dataclasses.fields(BaselineFit) if not f.metadata.get("static", False))
_STAMP: list[str] = []
_REPORTED: set[str] = set()
#: the executables loaded or compiled in this process, by file path (the last :data:`_KEEP`)
_LOADED: dict[str, tuple] = {}
_KEEP = 16


class SavedProgramWarning(RuntimeWarning):
    """A saved program of :func:`baselines.fit` could not be used (the fit went on without it)."""


def _report(kind: str, path: Path, error: BaseException) -> None:
    """Warn once per process and ``kind`` of failure (``read``, ``compiled``, ``written``, ``run``), with the
    reason."""
    if kind in _REPORTED:
        return
    _REPORTED.add(kind)
    reason = f"{type(error).__name__}: {error}".strip()
    warnings.warn(f"baselines.fit: the saved program {path} could not be {kind} ({reason}); fitting without it",
                  SavedProgramWarning, stacklevel=2)


def _stamp() -> str:
    """polyjax's source stamp and the size and modification time of every baselines source file."""
    if not _STAMP:
        root = Path(__file__).resolve().parent
        h = hashlib.sha256(source_stamp().encode())
        for p in sorted(root.rglob("*.py")):
            st = p.stat()
            h.update(f"{p.relative_to(root)}:{st.st_size}:{st.st_mtime_ns};".encode())
        _STAMP.append(h.hexdigest())
    return _STAMP[0]


def saved_folder() -> Path | None:
    """``<compilation cache folder>/polyjax-programs`` when JAX's persistent compilation cache is on and neither
    ``POLYJAX_SAVED_PROGRAMS`` nor ``POLYJAX_CACHE`` is off; else None."""

    if os.environ.get(ENV, "").strip().lower() in _OFF or cache_disabled_by_env():
        return None
    folder = jax.config.jax_compilation_cache_dir
    return Path(folder) / FOLDER if folder and jax.config.jax_enable_compilation_cache else None


def _host_arrays(u, v, values, weights, mask, starts):
    """The array inputs, a :class:`polyjax.Measurements` in ``u`` unpacked and lists made arrays; None when they
    are not for this path (a mixed call the ordinary one rejects, ragged lists)."""
    if isinstance(u, pj.Measurements):
        if v is not None or values is not None:
            return None
        data = u
        u, v, values = data.u, data.v, data.values
        weights = data.weights if weights is None else weights
        mask = data.mask if mask is None else mask
    out = []
    for a in (u, v, values, weights, mask, starts):
        if isinstance(a, (list, tuple)):
            try:
                a = np.asarray(a)
            except ValueError:
                return None
        out.append(a)
    return None if out[0] is None or out[1] is None or out[2] is None else tuple(out)


def _applies(arrays, key) -> bool:
    """Concrete inputs on one device whose eager checks pass: finite numbers, non-negative weights."""
    if not pj.is_concrete(arrays, key) or jax.device_count() != 1:
        return False
    if key is not None and jax.dtypes.issubdtype(getattr(key, "dtype", np.uint32), jax.dtypes.prng_key):
        return False  # a typed key: kept out of saved programs
    u, v, values, weights, mask, starts = (None if a is None else np.asarray(a) for a in arrays)
    if any(a is not None and a.dtype.kind not in "fiub" for a in (u, v, values, weights, starts)):
        return False
    finite = all(bool(np.all(np.isfinite(a))) for a in (u, v, values, weights, starts) if a is not None)
    return finite and (weights is None or bool(np.all(weights >= 0)))


def _program(fit, name: str, options: dict):
    def run(u, v, values, weights, mask, starts, key):
        out = fit(name, u, v, values, weights=weights, mask=mask, starts=starts, key=key, **options)
        return {f: getattr(out, f) for f in _FIELDS}, out.backend

    return run


def _load(path: Path):
    """The executable kept at ``path`` and its backend name; None when there is none or it cannot be read."""
    try:
        got = load_program(path)  # no pickle; None for a missing file or one in a folder others may write
        if got is None:
            return None
        compiled, extra = got
        return compiled, str(extra["backend"])
    except Exception as e:  # noqa: BLE001 - a stale or damaged file: reported, then compiled again
        _report("read", path, e)
        return None


def _path(folder: Path, name: str, arrays, options: dict) -> Path:
    """The file of the program of model ``name`` for ``arrays`` (the inputs and the key) and ``options``."""
    device = jax.devices()[0]
    opts = dict(options, baselines_source=_stamp(), model=name, given="".join("01"[a is not None] for a in arrays),
                compiler=sorted(COMPILER_OPTIONS.items()), device=f"{device.platform}:{device.device_kind}")
    return folder / f"baseline-{program_key([a for a in arrays if a is not None], opts)}.bin"


def _compile(fit, name: str, options: dict, arrays, path: Path):
    """Compile the fit's program for ``arrays`` and write it to ``path``; None when it cannot be compiled."""
    run = _program(fit, name, options)
    backend = []

    def fields(*a):
        out, b = run(*a)
        backend.append(b)
        return out

    try:
        compiled = compile_for_saving(fields, arrays, f"saved_{path.stem.replace('-', '_')}", COMPILER_OPTIONS)
    except pj.InputError:  # the ordinary call raises it with the eager message
        return None
    except Exception as e:  # noqa: BLE001 - fitted without a saved program
        _report("compiled", path, e)
        return None
    try:  # serialised before its first run (an executable that has run may no longer serialise: its sort kernels)
        save_program(path, compiled, {"backend": str(backend[0])})
    except Exception as e:  # noqa: BLE001 - used in this process all the same
        _report("written", path, e)
    return compiled, backend[0]


def fit_saved(fit, name: str, u, v, values, weights, mask, starts, key, throw: bool, options: dict):
    """The :class:`BaselineFit` of ``fit(name, u, v, values, ..., **options)`` (``fit`` is :func:`baselines.fit`)
    from its saved program (compiled and written on the first call), or None when this path does not apply or
    fails (then the caller fits as usual). ``throw`` is applied to the result as :func:`baselines.fit` does."""
    folder = saved_folder()
    arrays = None if folder is None else _host_arrays(u, v, values, weights, mask, starts)
    if arrays is None or not _applies(arrays, key):
        return None
    arrays = arrays + (key,)
    path = _path(folder, name, arrays, options)
    got = _LOADED.get(str(path)) or _load(path) or _compile(fit, name, options, arrays, path)
    if got is None:
        return None
    _LOADED[str(path)] = got
    while len(_LOADED) > _KEEP:
        del _LOADED[next(iter(_LOADED))]
    compiled, backend = got
    try:
        fields = compiled(*arrays)
    except Exception as e:  # noqa: BLE001 - the ordinary call decides
        _report("run", path, e)
        return None
    out = BaselineFit(**fields, name=name, backend=backend)
    return pj.raise_on_status("fit", out.status, out) if throw else out
