"""The end of a command-line process: its outputs flushed and its exit handlers run, then the process ends without
the interpreter's teardown.

After the last ``atexit`` handler, CPython tears its interpreter down: it clears every module and runs the cyclic
garbage collector over the whole heap several times. With JAX imported that heap is large, and the teardown costs
0.3-0.4 s of CPU in every process, more than a warm first fit (``benchmarks/RESULTS.md``, "A warm first fit, whole
process"); nothing in it writes anything a command made. :func:`end_process` does what must be done and skips the
rest: it flushes ``sys.stdout`` and ``sys.stderr``, runs the exit handlers (:func:`atexit._run_exitfuncs`:
``logging.shutdown``, JAX's clean-up of its backends, ``weakref.finalize``'s pending finalizers, whatever the
process registered), flushes again, flushes the C library's own stream buffers (``fflush(NULL)``: what a native
library printed, which :func:`os._exit` would otherwise drop) and ends with :func:`os._exit`.

It falls back to the ordinary exit (returns, so the caller's ``sys.exit`` runs) when the streams cannot be flushed
(a closed pipe: Python's own exit reports it), when a non-daemon thread is still alive (Python would wait for it),
or when this Python has no ``atexit._run_exitfuncs``. Every file a command writes is written, closed and renamed
into place by the atomic writer before the command returns (``polyjax/_files/atomic.py``), so none is open here.
"""

from __future__ import annotations

import atexit
import ctypes
import os
import sys
import threading

#: set to ``off`` to end every command with Python's ordinary exit (interpreter teardown included)
ENV = "POLYJAX_FAST_EXIT"


def _flushed() -> bool:
    """Flush ``sys.stdout`` and ``sys.stderr``; False when one cannot be."""
    for stream in (sys.stdout, sys.stderr):
        if stream is None:
            continue
        try:
            stream.flush()
        except (OSError, ValueError, AttributeError):
            return False
    return True


def _flush_c_streams() -> bool:
    """``fflush(NULL)`` of the C library (every C ``FILE`` stream of the process); False where it cannot be called
    or fails."""
    try:
        return ctypes.CDLL(None).fflush(None) == 0
    except (OSError, AttributeError, TypeError):
        return False


def can_end_now() -> bool:
    """True when :func:`end_process` would end the process here: allowed by :data:`ENV`, no non-daemon thread
    alive besides the main thread, and this Python's ``atexit`` able to run its handlers."""
    if os.environ.get(ENV, "").strip().lower() in ("off", "0", "no", "false"):
        return False
    if not callable(getattr(atexit, "_run_exitfuncs", None)):
        return False
    main = threading.main_thread()
    return threading.current_thread() is main and not any(
        t is not main and t.is_alive() and not t.daemon for t in threading.enumerate())


def end_process(status: int) -> int:
    """End the process with ``status`` after flushing its streams and running its exit handlers, without the
    interpreter's teardown (module docs); returns ``status`` only where the ordinary exit must run instead."""
    if not can_end_now() or not _flushed():
        return status
    atexit._run_exitfuncs()
    if not _flushed() or not _flush_c_streams():  # a stream that has since closed: the ordinary exit reports it
        return status
    os._exit(status)
