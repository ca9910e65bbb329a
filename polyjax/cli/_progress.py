"""What the command line shows while it works: a line when a block is still compiling (:class:`compile_notice`) and
a one-line display of the elapsed time on a terminal (:class:`progress_line`), both background watchers of one
block (:class:`_Watcher`).

progress_line writes ``polyjax: <what>: 12 s, compiling (3 programs ready)`` or ``polyjax: <what>: 40 s, running``
on stderr, rewritten every second, once the block has run ``after`` seconds (default 3, ``$POLYJAX_PROGRESS_SECS``),
and erases it at the end; only when the stream is a terminal (quiet in pipes, logs and tests), and never with
``POLYJAX_PROGRESS=off``.

The stage is what can be known without touching the fit: JAX reports the end of every trace, lowering and compile
(or load from the compilation cache) of a program (:mod:`jax.monitoring`), so the block is ``compiling`` while the
last of these was a trace or a lowering (XLA compiles next), with the number of programs compiled or loaded so
far, and ``running`` otherwise (a loaded saved program runs without any of these). Within the run no fraction of
starts or steps done is shown: a fit is one compiled program (the multi-start kernel one loop of jobs), and a
count from inside it would need a host callback in every step, which syncs the device with Python each time and,
worse, makes the program one that JAX neither keeps in its compilation cache nor serialises as a saved program, so
every later process would compile it again.
"""

from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

import jax.monitoring

from .._cache.compilation import cache_misses, listen_for_misses

#: what JAX reported last, and how many programs it compiled or loaded, in this process (:func:`_listen`)
_EVENTS = {"last": None, "ready": 0}
_LISTENING: list[bool] = []
_BUILD = ("/jax/core/compile/jaxpr_trace_duration", "/jax/core/compile/jaxpr_to_mlir_module_duration")
_READY = "/jax/core/compile/backend_compile_duration"


def _on_duration(event: str, duration: float, **_) -> None:
    if event in _BUILD:
        _EVENTS["last"] = "build"
    elif event == _READY:
        _EVENTS["last"] = "ready"
        _EVENTS["ready"] += 1


def _listen() -> None:
    """Follow JAX's trace, lowering and compile events from now on (once per process; a few Python calls each)."""
    if not _LISTENING:
        jax.monitoring.register_event_duration_secs_listener(_on_duration)
        _LISTENING.append(True)


def stage(ready_before: int) -> str:
    """``compiling (k programs ready)`` while JAX's last event was a trace or a lowering (``k`` compiled or loaded
    since the count was ``ready_before``), else ``running``."""
    if _EVENTS["last"] == "build":
        k = _EVENTS["ready"] - ready_before
        return f"compiling ({k} program{'' if k == 1 else 's'} ready)"
    return "running"


class _Watcher:
    """Context manager: :meth:`_run` in a daemon thread while the block runs (when :meth:`_enabled`); the thread is
    told to stop (``self._done``) and joined at the end, then :meth:`_finish`."""

    def __init__(self):
        self._done = threading.Event()
        self._thread: threading.Thread | None = None

    def _enabled(self) -> bool:
        return True

    def _run(self) -> None:
        raise NotImplementedError

    def _finish(self) -> None:
        pass

    def __enter__(self):
        if self._enabled():
            self._thread = threading.Thread(target=self._run, daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc):
        self._done.set()
        if self._thread is not None:
            self._thread.join()
            self._finish()
        return False


class progress_line(_Watcher):
    """Context manager showing the stage and elapsed time of the block on a terminal (module docstring)."""

    def __init__(self, what: str, after: float | None = None, interval: float = 1.0, stream=None):
        super().__init__()
        self.what = what
        self.after = float(os.environ.get("POLYJAX_PROGRESS_SECS", 3.0)) if after is None else float(after)
        self.interval = float(interval)
        self.stream = sys.stderr if stream is None else stream
        self._shown = False

    def _enabled(self) -> bool:
        off = os.environ.get("POLYJAX_PROGRESS", "").strip().lower() in ("off", "0", "no", "false")
        isatty = getattr(self.stream, "isatty", None)
        if off or not callable(isatty) or not isatty():
            return False
        _listen()
        return True

    def _run(self) -> None:
        t0, ready = time.perf_counter(), _EVENTS["ready"]
        if self._done.wait(self.after):
            return
        while True:
            self._shown = True
            self.stream.write(f"\rpolyjax: {self.what}: {time.perf_counter() - t0:.0f} s, {stage(ready)}\033[K")
            self.stream.flush()
            if self._done.wait(self.interval):
                return

    def _finish(self) -> None:
        if self._shown:  # erase the line
            self.stream.write("\r\033[K")
            self.stream.flush()


class compile_notice(_Watcher):
    """Context manager: one line on stderr when the block is still compiling after ``delay`` seconds.

    The command line wraps its fits in it, so that the seconds JAX spends compiling a program for new shapes are
    not silence. With the cache on, the line appears only while a program that the cache did not hold is being
    compiled: after JAX's cache has missed a program (it logs the miss, then compiles), never while it merely reads
    programs it holds (a warm run that is slow, or loads large programs, stays quiet); with the cache off, whenever
    the block takes longer than ``delay`` (default 1 s, ``$POLYJAX_COMPILE_NOTICE_SECS``): every program is then
    compiled. At most one line per process.
    """

    printed = False

    def __init__(self, what: str, cache: Path | None, delay: float | None = None, stream=None):
        super().__init__()
        self.what, self.cache = what, cache
        self.delay = float(os.environ.get("POLYJAX_COMPILE_NOTICE_SECS", 1.0)) if delay is None else float(delay)
        self.stream = stream

    def _enabled(self) -> bool:
        if compile_notice.printed:
            return False
        if self.cache is not None:
            listen_for_misses()
        return True

    def _compiling(self) -> bool:
        return self.cache is None or cache_misses() > 0

    def _run(self) -> None:
        if self._done.wait(self.delay):
            return
        while not compile_notice.printed:
            if self._compiling():
                self._say()
                return
            if self._done.wait(0.1):
                return

    def _say(self) -> None:
        compile_notice.printed = True
        where = (f"kept in {self.cache} for later runs" if self.cache is not None
                 else "the compilation cache is off, so every process compiles again")
        stream = self.stream if self.stream is not None else sys.stderr
        print(f"polyjax: compiling {self.what} for these shapes and options (once per machine; {where}) ...",
              file=stream, flush=True)
