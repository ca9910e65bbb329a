"""Ctrl-C for the whole of polyjax: one flag that long loops check between their blocks, and the command line's
handler that sets it.

The command line (:func:`install`) replaces Python's SIGINT handler: the first Ctrl-C sets the flag and raises
:class:`Interrupted` in the main thread at its next Python step (after the XLA call under way returns: long loops run
in blocks of a second or two and call :func:`check_interrupt` between them, which also stops worker threads). A
watchdog thread learns of the signal at once, even while the main thread waits inside one long XLA call (through
:func:`signal.set_wakeup_fd`): if the process has not ended :data:`GRACE_S` seconds later, it removes what the
command left half made (:func:`forget_outputs`' records), prints ``interrupted`` and ends the process with status
130. A second Ctrl-C ends it at once the same way. A Ctrl-C that lands where Python cannot raise (a garbage
collector's callback, a ``__del__``) sets the flag without a word (:func:`_unraisable`).
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from pathlib import Path

from .._files import remove_temporary_files

#: seconds the watchdog gives the main thread to stop by itself after Ctrl-C
GRACE_S = 1.5
#: the exit status of a process ended by SIGINT (128 + 2)
EXIT_STATUS = 130

_FLAG = threading.Event()
_DONE = threading.Lock()
_OUTPUTS: list[tuple[Path, bool]] = []


class Interrupted(KeyboardInterrupt):
    """Ctrl-C: the work stopped at a block boundary (a ``KeyboardInterrupt``: no ``except Exception`` catches it)."""


def interrupted() -> bool:
    """True once Ctrl-C was pressed in a process whose handler is :func:`install`'s."""
    return _FLAG.is_set()


def check_interrupt() -> None:
    """Raise :class:`Interrupted` if Ctrl-C was pressed: called by long loops between their blocks."""
    if _FLAG.is_set():
        raise Interrupted()


def watch_output(path) -> None:
    """Record an output path of the command (a file or a folder) and whether it existed: :func:`clean_up` removes
    what the command made of it and left unfinished (a folder it created and left empty); the temporary files of
    writes under way are removed by the writer's own record (:func:`polyjax._files.remove_temporary_files`)."""
    p = Path(path)
    _OUTPUTS.append((p, p.exists()))


def clean_up() -> None:
    """Remove the unfinished outputs: the temporary files of writes under way, and the recorded folders
    (:func:`watch_output`) this process created and left empty."""
    remove_temporary_files()
    for p, existed in _OUTPUTS:
        if not existed and p.is_dir() and not any(p.iterdir()):
            p.rmdir()


def finish(stream=None) -> int:
    """Clean up and print ``interrupted`` once per process (the main thread or the watchdog, whichever is first);
    returns :data:`EXIT_STATUS`."""
    if _DONE.acquire(blocking=False):
        clean_up()
        print("interrupted", file=stream or sys.stderr, flush=True)
    return EXIT_STATUS


def _handler(signum, frame) -> None:
    if _FLAG.is_set():  # a second Ctrl-C: at once
        finish()
        os._exit(EXIT_STATUS)
    _FLAG.set()
    raise Interrupted()


def _unraisable(previous):
    """``sys.unraisablehook`` that drops :class:`Interrupted`: Ctrl-C lands where Python cannot raise (a garbage
    collector callback such as JAX's, a ``__del__``), which Python reports as "Exception ignored" with a traceback.
    The flag is set all the same, so the work stops at its next check or the watchdog ends it; anything else goes
    to ``previous``."""

    def hook(unraisable):
        if isinstance(unraisable.exc_value, Interrupted):
            return
        previous(unraisable)

    return hook


def _watchdog(fd: int) -> None:
    while True:
        try:
            data = os.read(fd, 64)
        except OSError:
            return
        if signal.SIGINT in data:
            break
    deadline = time.monotonic() + GRACE_S
    while time.monotonic() < deadline:
        time.sleep(0.05)
    finish()  # the main thread did not end in time (one long call): end the process here
    os._exit(EXIT_STATUS)


def install() -> None:
    """The command line's SIGINT handling (module docs); in the main thread only, else nothing."""
    if threading.current_thread() is not threading.main_thread():
        return
    r, w = os.pipe()
    os.set_blocking(w, False)
    signal.set_wakeup_fd(w, warn_on_full_buffer=False)
    signal.signal(signal.SIGINT, _handler)
    sys.unraisablehook = _unraisable(sys.unraisablehook)
    threading.Thread(target=_watchdog, args=(r,), daemon=True, name="polyjax-interrupt").start()
