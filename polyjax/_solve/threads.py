"""LAPACK's threads inside polyjax's calls: one by default, whatever the process's environment.

jaxlib's CPU LAPACK kernels (QR, SVD, ``eigh``, Cholesky, triangular solves) call the OpenBLAS that scipy ships.
Its worker threads busy-wait for work; when processes share the cores they starve each other, and a small
factorisation runs 100x slower (OpenBLAS issue 5517). polyjax's factorisations are small (tens of columns, one
matrix at a time), so those threads buy nothing even alone: one thread is 1.8x faster there
(``benchmarks/bench_concurrency.py``).

So every public call of polyjax that factorises (the fits, the PCA, the weighted solve, the sampling tables)
runs inside :class:`lapack_threads`: on entry the BLAS libraries loaded in the process (scipy's OpenBLAS, which
jaxlib's LAPACK uses, and numpy's) are set to one thread; the call's results are waited for (JAX dispatches
asynchronously, and OpenBLAS reads its thread count when a kernel starts); on exit each library's previous count
is put back. Outside polyjax's calls the user's setting (``OPENBLAS_NUM_THREADS``, ``threadpoolctl``) is
untouched. Calls under a JAX trace (``jit``/``grad``/``vmap`` of polyjax) run later, in the caller's program: wrap
that program's call in ``with pj.lapack_threads():`` to get the same.

The switch: ``POLYJAX_LAPACK_THREADS`` (read at each call) is ``1`` by default, an integer ``N`` for ``N``
threads, or ``off`` to leave the libraries as they are.
"""

from __future__ import annotations

import functools
import os
import threading

import jax
from threadpoolctl import ThreadpoolController

from .._arrays import is_traced
from .._errors import InputError

#: the environment variable: "1" (default), an integer, or "off"
THREADS_ENV = "POLYJAX_LAPACK_THREADS"

_LOCK = threading.RLock()
_STATE = {"depth": 0, "saved": None, "controller": None}


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


def _libraries():
    """The BLAS libraries of the process, found once, after scipy's LAPACK (jaxlib's) has been loaded."""
    if _STATE["controller"] is None:
        # jaxlib loads scipy's LAPACK on its first factorisation (jaxlib.lapack's initialize); load it now so that
        # its OpenBLAS is among the libraries limited (0.15 s, paid once, and by jaxlib's first call anyway)
        from scipy.linalg import cython_lapack  # noqa: F401

        _STATE["controller"] = ThreadpoolController().select(user_api="blas").lib_controllers
    return _STATE["controller"]


class lapack_threads:
    """Within the block, the process's BLAS/LAPACK libraries run ``n`` threads; their counts are put back after.

    Re-entrant and shared by Python threads (the thread count is a process-wide setting of each library): the
    outermost block sets and restores it. The caller's results should be ready before the block ends (the
    functions polyjax wraps wait for theirs).

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
                libs = _libraries()
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


def _wait(out):
    """Block until the concrete JAX arrays of ``out`` are computed (tracers and other leaves pass)."""
    for leaf in jax.tree.leaves(out):
        if isinstance(leaf, jax.Array) and not is_traced(leaf):
            leaf.block_until_ready()
    return out


def one_lapack_thread(fn):
    """Decorate a public function: it runs inside :class:`lapack_threads` and waits for its results."""

    @functools.wraps(fn)
    def wrapped(*args, **kwargs):
        with lapack_threads():
            return _wait(fn(*args, **kwargs))

    return wrapped
