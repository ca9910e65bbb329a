"""Compiled fits kept on disk for the command line: a warm ``polyjax fit`` neither traces, lowers nor compiles.

JAX's persistent compilation cache (:mod:`polyjax._cache.compilation`) saves the compiling, but every process still
traces and lowers each program to find its cache key: most of a warm ``polyjax fit``. Here the whole fit of one data
set (input preparation, the fit, and the L2 of the zero model the command reports beside it) is one jitted program,
compiled ahead of time and serialised (:mod:`jax.experimental.serialize_executable`) into the cache folder, keyed
by everything that shapes it (:func:`polyjax._cache.keys.program_key`): the input shapes and dtypes, the fit's
options, the versions of JAX, jaxlib and polyjax's own source files, and the machine. A later process with the same
key loads the executable and runs it.

The program takes the inputs traced, so it is the fit a ``jit``-ted call of :func:`polyjax.fit_polynomial` gives
(the dense path, with the same numbers as an eager call for data below the streaming size). It is used only where
that is the eager call's result too: data below :func:`polyjax._fit.stream.stream_threshold` samples, finite values and
directions (an eager call raises on NaN where a traced one flags the lane). Options the fit refuses return None
before any work (the ordinary call then raises its error); anything unexpected while saving or loading (a stale or
unreadable file, a program that does not serialise) is logged once per file with its reason (logger ``polyjax``,
level WARNING) and falls back to the ordinary call. The file is written and read by :mod:`polyjax._cache.programs`
(no pickle; the executable's digest checked; nothing loaded from a folder or file that another user owns or others
may write, warned once). ``POLYJAX_SAVED_PROGRAMS=off`` turns this off (the compilation
cache alone then serves a warm run).
"""

from __future__ import annotations

import logging
import os
from pathlib import Path

import numpy as np

from .._cache.compilation import compile_for_saving
from .._cache.keys import program_key
from .._cache.programs import load_program, save_program
from .._errors import PolyjaxError
from .._metrics import l2_error
from .._model import PolynomialBRDF
from .._solve.threads import one_lapack_thread
from .._variables import get_variables
from .closed_form import check_fit_options
from .polynomial import fit_polynomial
from .stream import stream_threshold

#: subfolder of the compilation cache folder holding the serialised fits
FOLDER = "polyjax-programs"
#: environment variable: ``off`` (or ``0``, ``no``, ``false``) keeps no executables
ENV = "POLYJAX_SAVED_PROGRAMS"
_FIELDS = ("coefficients", "degree", "mean", "rotation", "centre", "halfwidth", "l2", "rank", "condition", "n_used",
           "status")
_LOG = logging.getLogger("polyjax")
_LOGGED: set[tuple[str, str]] = set()


def _usable(data) -> bool:
    if data.n_samples >= stream_threshold():  # an eager call streams these: not the program below
        return False
    return all(bool(np.all(np.isfinite(np.asarray(a)))) for a in (data.u, data.v, data.values, data.weights))


def _program(options: dict):
    def run(u, v, values, weights, mask):
        model = fit_polynomial(u, v, values, weights=weights, mask=mask, **options)
        zero = l2_error(values, 0.0, u, v, weights=weights, cutoff_deg=options["cutoff_deg"], mask=mask)
        return {name: getattr(model, name) for name in _FIELDS}, zero

    return run


def _warn_once(what: str, path: Path, error: BaseException) -> None:
    """Log (once per process, kind of failure and file) why the saved program was not used; the caller then fits as
    usual."""
    if (what, str(path)) not in _LOGGED:
        _LOGGED.add((what, str(path)))
        _LOG.warning("polyjax: saved fit program %s not used (%s: %s: %s); fitting without it", path, what,
                     type(error).__name__, error)


def _options(data, options: dict):
    """The options checked as the fit checks them (None if it refuses them) and the program's key parts."""
    try:
        check_fit_options(options["basis"], "qr", "flag", options["degree"], 1)  # lane_block: any valid value
        vs = get_variables(options["variables"])
    except PolyjaxError:  # the ordinary call raises its error
        return None
    return vs, dict(options, variables=vs.name, degree=tuple(options["degree"]) if isinstance(
        options["degree"], (list, tuple)) else int(options["degree"]))


def _load(path: Path):
    """The executable kept at ``path``, or None (a missing file; a stale or damaged one is logged)."""
    try:
        got = load_program(path)
        return None if got is None else got[0]
    except Exception as e:  # noqa: BLE001 - a stale or damaged file: logged, compiled again
        _warn_once("reading the kept program failed", path, e)
        return None


def _compile_and_keep(opts: dict, arrays, path: Path):
    call_opts = dict(opts, degree=list(opts["degree"]) if isinstance(opts["degree"], tuple) else opts["degree"])
    compiled = compile_for_saving(_program(call_opts), arrays, f"saved_{path.stem.replace('-', '_')}")
    save_program(path, compiled)
    return compiled


@one_lapack_thread
def fit_saved(data, folder: Path | None, **options):
    """``(model, zero_model_l2)`` of :func:`polyjax.fit_polynomial` on ``data`` (a :class:`polyjax.Measurements`)
    with ``options`` (``variables``, ``degree``, ``basis``, ``interactions``, ``cutoff_deg``), from the executable
    kept in ``folder``/:data:`FOLDER` (written there on the first call); None when this path does not apply or fails
    (then the caller fits as usual; a failure is logged once per file, with its reason)."""
    if folder is None or os.environ.get(ENV, "").strip().lower() in ("off", "0", "no", "false") or not _usable(data):
        return None
    checked = _options(data, options)
    if checked is None:
        return None
    vs, opts = checked
    arrays = (data.u, data.v, data.values, data.weights, data.mask)
    path = Path(folder) / FOLDER / f"fit-{program_key(arrays, opts)}.bin"
    try:
        compiled = _load(path)
        if compiled is None:
            compiled = _compile_and_keep(opts, arrays, path)
        fields, zero = compiled(*arrays)
    except Exception as e:  # noqa: BLE001 - logged; the ordinary call decides (and raises what it raises)
        _warn_once("the saved fit program failed", path, e)
        return None
    interactions = bool(opts["interactions"])
    max_degree = int(np.max(opts["degree"]))
    return PolynomialBRDF(**fields, variables=vs.name, basis=opts["basis"], interactions=interactions,
                          max_degree=max_degree), zero
