"""Compiled fits kept on disk for the command line: a warm ``polyjax fit`` neither traces, lowers nor compiles.

JAX's persistent compilation cache (:mod:`polyjax._cache`) saves the compiling, but every process still traces
and lowers each program to find its cache key: most of a warm ``polyjax fit``. Here the whole fit of one data set
(input preparation, the fit, and the L2 of the zero model the command reports beside it) is one jitted program,
compiled ahead of time and serialised (:mod:`jax.experimental.serialize_executable`) into the cache folder, keyed
by everything that shapes it: the input shapes and dtypes, the fit's options, the versions of JAX, jaxlib and
polyjax's own source files, and the machine. A later process with the same key loads the executable and runs it.

The program takes the inputs traced, so it is the fit a ``jit``-ted call of :func:`polyjax.fit_polynomial` gives
(the dense path, with the same numbers as an eager call for data below the streaming size). It is used only where
that is the eager call's result too: data below :data:`polyjax._stream.STREAM_ROWS` samples, finite values and
directions (an eager call raises on NaN where a traced one flags the lane). Anything unexpected (a missing,
stale or unreadable file, a refused input) falls back to the ordinary call; nothing here is ever an error.
``POLYJAX_SAVED_PROGRAMS=off`` turns this off (the compilation cache alone then serves a warm run).
"""

from __future__ import annotations

import hashlib
import os
import pickle
import platform
from pathlib import Path

import numpy as np

from ._threads import one_lapack_thread

#: subfolder of the compilation cache folder holding the serialised fits
FOLDER = "polyjax-programs"
#: environment variable: ``off`` (or ``0``, ``no``, ``false``) keeps no executables
ENV = "POLYJAX_SAVED_PROGRAMS"
_FIELDS = ("coefficients", "degree", "mean", "rotation", "centre", "halfwidth", "l2", "rank", "condition", "n_used",
           "status")
_SOURCE_STAMP: list[str] = []


def _source_stamp() -> str:
    """Size and modification time of every polyjax source file: any edit gives new keys."""
    if not _SOURCE_STAMP:
        root = Path(__file__).resolve().parent
        h = hashlib.sha256()
        for p in sorted(root.rglob("*.py")):
            st = p.stat()
            h.update(f"{p.relative_to(root)}:{st.st_size}:{st.st_mtime_ns};".encode())
        _SOURCE_STAMP.append(h.hexdigest())
    return _SOURCE_STAMP[0]


def _key(arrays, options: dict) -> str:
    import jax
    import jaxlib

    parts = [jax.__version__, jaxlib.__version__, platform.machine(), platform.node(), _source_stamp(),
             str(jax.config.jax_enable_x64), repr(sorted(options.items()))]
    parts += [f"{a.shape}:{a.dtype}" for a in arrays]
    return hashlib.sha256("|".join(parts).encode()).hexdigest()[:32]


def _usable(data) -> bool:
    from ._stream import STREAM_ROWS

    if data.n_samples >= STREAM_ROWS:  # an eager call streams these: not the program below
        return False
    return all(bool(np.all(np.isfinite(np.asarray(a)))) for a in (data.u, data.v, data.values, data.weights))


def _program(options: dict):
    import jax

    from ._fit import fit_polynomial
    from ._metrics import l2_error

    def run(u, v, values, weights, mask):
        model = fit_polynomial(u, v, values, weights=weights, mask=mask, **options)
        zero = l2_error(values, 0.0, u, v, weights=weights, cutoff_deg=options["cutoff_deg"], mask=mask)
        return {name: getattr(model, name) for name in _FIELDS}, zero

    return jax.jit(run)


def _load_lapack() -> None:
    """The LAPACK kernels are set up when a program using them is lowered; a loaded executable skips that step."""
    from jaxlib.cpu import _lapack

    _lapack.initialize()


@one_lapack_thread
def fit_saved(data, folder: Path | None, **options):
    """``(model, zero_model_l2)`` of :func:`polyjax.fit_polynomial` on ``data`` (a :class:`polyjax.Measurements`)
    with ``options`` (``variables``, ``degree``, ``basis``, ``interactions``, ``cutoff_deg``), from the executable
    kept in ``folder``/:data:`FOLDER` (written there on the first call); None when this path does not apply (then
    the caller fits as usual)."""
    if folder is None or os.environ.get(ENV, "").strip().lower() in ("off", "0", "no", "false") or not _usable(data):
        return None
    try:
        from jax.experimental import serialize_executable

        from ._fit import _check_options
        from ._model import PolynomialBRDF
        from ._variables import get_variables

        _check_options(options["basis"], "qr", "flag", options["degree"], 1)  # lane_block: any valid value
        vs = get_variables(options["variables"])
        arrays = (data.u, data.v, data.values, data.weights, data.mask)
        opts = dict(options, variables=vs.name, degree=tuple(options["degree"]) if isinstance(
            options["degree"], (list, tuple)) else int(options["degree"]))
        path = Path(folder) / FOLDER / f"fit-{_key(arrays, opts)}.bin"
        compiled = None
        if path.is_file():
            try:
                payload, in_tree, out_tree = pickle.loads(path.read_bytes())
                _load_lapack()
                compiled = serialize_executable.deserialize_and_load(payload, in_tree, out_tree)
            except Exception:  # noqa: BLE001 - a stale or damaged file: compile again below
                compiled = None
        if compiled is None:
            call_opts = dict(opts, degree=list(opts["degree"]) if isinstance(opts["degree"], tuple) else opts["degree"])
            compiled = _program(call_opts).lower(*arrays).compile()
            path.parent.mkdir(parents=True, exist_ok=True)
            tmp = path.with_suffix(f".{os.getpid()}.tmp")
            tmp.write_bytes(pickle.dumps(serialize_executable.serialize(compiled)))
            os.replace(tmp, path)
        fields, zero = compiled(*arrays)
        interactions = bool(opts["interactions"])
        max_degree = int(np.max(opts["degree"]))
        return PolynomialBRDF(**fields, variables=vs.name, basis=opts["basis"], interactions=interactions,
                              max_degree=max_degree), zero
    except Exception:  # noqa: BLE001 - the ordinary call decides (and raises what it raises)
        return None
