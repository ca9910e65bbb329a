"""LAPACK's threads in a process that runs polyjax: one, whatever the process's environment.

jaxlib's CPU LAPACK kernels (QR, SVD, ``eigh``, Cholesky, triangular solves) call the OpenBLAS that scipy ships.
Its worker threads busy-wait for work; when processes share the cores they starve each other, and a small
factorisation runs 100x slower (OpenBLAS issue 5517). polyjax's factorisations are small (tens of columns, one
matrix at a time), so those threads buy nothing even alone: one thread is faster there
(``benchmarks/bench_concurrency.py``).

The rule (:func:`limit_lapack_threads`, run at the start of every public call of polyjax that factorises: the fits,
the PCA, the weighted solve, the sampling tables, the baselines' fits):

- if jaxlib's LAPACK library is not loaded yet, it is loaded now with ``OPENBLAS_NUM_THREADS`` set to the limit
  for the moment of loading (the variable is put back at once), so OpenBLAS starts no worker threads at all;
- if it was loaded before (the user's own scipy call), its count is set to the limit (``threadpoolctl``);
- either way the count **stays** at the limit after the call. Putting it back after each call was measured to be
  the wrong way: every change of OpenBLAS's count wakes its workers, which then spin, so a process alone kept 1.95
  cores busy on a fit that needs one, and two such processes ran 60-160x slower again (``bench_concurrency.py``,
  setting ``restore``).

Only that library is limited (scipy's OpenBLAS, found by its file path; all BLAS libraries where scipy's cannot be
told apart, as with one system OpenBLAS shared by numpy and scipy); numpy's own OpenBLAS, which polyjax does not
factorise with, keeps the user's setting. The user's scipy calls in the same process run with the limit too, once
polyjax has made its first call: ``POLYJAX_LAPACK_THREADS=off`` leaves every library as it is, ``=N`` gives ``N``
threads, and ``with pj.lapack_threads(n):`` sets a count for a block and puts the previous one back after it
(polyjax's calls inside the block then leave the block's count alone).
"""

from __future__ import annotations

import functools
import importlib
import importlib.machinery
import importlib.util
import os
import sys
import threading
from pathlib import Path

from threadpoolctl import ThreadpoolController

from .._errors import InputError

#: the environment variable: "1" (default), an integer, or "off"
THREADS_ENV = "POLYJAX_LAPACK_THREADS"
#: the module whose loading loads jaxlib's LAPACK library (jaxlib.lapack's ``initialize`` imports it)
_LAPACK_MODULE = "scipy.linalg.cython_lapack"

_LOCK = threading.RLock()
_STATE = {"depth": 0, "saved": None, "libraries": None}


def configured_threads() -> int | None:
    """The LAPACK thread count polyjax's calls use: ``$POLYJAX_LAPACK_THREADS`` (default 1), None for ``off``.

    Raises:
        InputError: the variable is neither ``off`` nor a positive integer.
    """
    text = os.environ.get(THREADS_ENV, "1").strip().lower()
    if text in ("off", "none", ""):
        return None
    if not text.isdigit() or int(text) < 1:
        raise InputError(f"${THREADS_ENV}: expected a positive integer or 'off', found {text!r}")
    return int(text)


def _load_lapack(n: int) -> None:
    """Load jaxlib's LAPACK library (scipy's) with OpenBLAS reading ``n`` threads at its start, if not loaded yet.

    OpenBLAS reads ``OPENBLAS_NUM_THREADS`` once, when it is loaded, and starts that many threads less one; the
    variable is put back right after, so subprocesses and other libraries see the user's environment."""
    if _LAPACK_MODULE in sys.modules:
        return
    saved = os.environ.get("OPENBLAS_NUM_THREADS")
    os.environ["OPENBLAS_NUM_THREADS"] = str(n)
    try:
        _import_lapack_modules()
    finally:
        if saved is None:
            os.environ.pop("OPENBLAS_NUM_THREADS", None)
        else:
            os.environ["OPENBLAS_NUM_THREADS"] = saved


def _import_lapack_modules() -> None:
    """Import scipy's ``cython_blas`` and ``cython_lapack``, whose function tables jaxlib's LAPACK kernels use (and
    whose loading loads scipy's OpenBLAS), without the package ``scipy.linalg`` around them: its ``__init__``
    imports the whole of ``scipy.linalg``, about 0.15 s, a third of a warm first fit's time in a fresh process
    (``benchmarks/bench_latency.py``), where the two extension modules take 15 ms. Each is loaded from its file
    under its own name, so jaxlib, and a later ``import scipy.linalg``, find it in ``sys.modules``; with any other
    layout of scipy, the plain import."""
    try:
        folder = Path(importlib.util.find_spec("scipy").origin).parent / "linalg"
        for name in ("cython_blas", "cython_lapack"):
            full = f"scipy.linalg.{name}"
            if full in sys.modules:
                continue
            path = next(folder / (name + s) for s in importlib.machinery.EXTENSION_SUFFIXES
                        if (folder / (name + s)).is_file())
            spec = importlib.util.spec_from_file_location(full, path)
            module = importlib.util.module_from_spec(spec)
            sys.modules[full] = module
            try:
                spec.loader.exec_module(module)
            except BaseException:
                del sys.modules[full]
                raise
    except (StopIteration, ImportError, AttributeError, TypeError, OSError):
        importlib.import_module(_LAPACK_MODULE)  # the plain import, as jaxlib itself would do it


def _libraries(n: int):
    """The BLAS libraries limited: scipy's OpenBLAS, loaded first with ``n`` threads (all BLAS libraries where no
    loaded one's path names scipy)."""
    if _STATE["libraries"] is None:
        _load_lapack(n)
        blas = ThreadpoolController().select(user_api="blas").lib_controllers
        # a scipy wheel keeps its OpenBLAS in ``scipy.libs/`` (numpy's wheel in ``numpy.libs/``)
        scipy_own = [lib for lib in blas if os.path.basename(os.path.dirname(lib.filepath)).startswith("scipy")]
        _STATE["libraries"] = scipy_own or blas
    return _STATE["libraries"]


def limit_lapack_threads() -> None:
    """Set jaxlib's LAPACK library to ``$POLYJAX_LAPACK_THREADS`` threads (default 1) and leave it there.

    Does nothing with ``off``, inside a :class:`lapack_threads` block (the block's count holds) and when the
    count is already the limit (a change wakes OpenBLAS's threads: the module's docstring)."""
    n = configured_threads()
    if n is None:
        return
    with _LOCK:
        if _STATE["depth"]:
            return
        for lib in _libraries(n):
            if lib.num_threads != n:
                lib.set_num_threads(n)


class lapack_threads:
    """Within the block, jaxlib's LAPACK library runs ``n`` threads; its previous count is put back after.

    Re-entrant and shared by Python threads (the thread count is a process-wide setting of the library): the
    outermost block sets and restores it, and polyjax's own calls inside leave it alone. The caller's results
    should be ready before the block ends (JAX dispatches asynchronously; OpenBLAS reads its count when a kernel
    starts).

    Args:
        n: threads; default ``$POLYJAX_LAPACK_THREADS`` (1 unless set; ``off`` makes the block do nothing).
    """

    def __init__(self, n: int | None = None):
        if n is not None and (not isinstance(n, int) or isinstance(n, bool) or n < 1):
            raise InputError(f"lapack_threads(n): expected a positive integer or None, found {n!r}")
        self.n = n

    def __enter__(self):
        n = configured_threads() if self.n is None else self.n
        with _LOCK:
            _STATE["depth"] += 1
            if _STATE["depth"] == 1 and n is not None:
                libs = _libraries(n)
                _STATE["saved"] = [(lib, lib.num_threads) for lib in libs]
                for lib in libs:
                    lib.set_num_threads(n)
        return self

    def __exit__(self, *exc):
        with _LOCK:
            _STATE["depth"] -= 1
            if _STATE["depth"] == 0 and _STATE["saved"] is not None:
                for lib, count in _STATE["saved"]:
                    lib.set_num_threads(count)
                _STATE["saved"] = None
        return False


def one_lapack_thread(fn):
    """Decorate a public function that factorises: :func:`limit_lapack_threads` before it runs.

    Under a JAX trace the limit is set while tracing, so the compiled program runs with it too."""

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        limit_lapack_threads()
        return fn(*args, **kwargs)

    return wrapped
