"""A one-line progress display on a terminal for long command-line work: the stage and the elapsed seconds, updated
in place.

:class:`progress_line` writes ``polyjax: <what>: 12 s, compiling (3 programs ready)`` or ``polyjax: <what>: 40 s,
running`` on stderr, rewritten every second, once the block has run ``after`` seconds (default 3,
``$POLYJAX_PROGRESS_SECS``), and erases it at the end; only when the stream is a terminal (quiet in pipes, logs and
tests), and never with ``POLYJAX_PROGRESS=off``.

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
        import jax.monitoring

        jax.monitoring.register_event_duration_secs_listener(_on_duration)
        _LISTENING.append(True)


def stage(ready_before: int) -> str:
    """``compiling (k programs ready)`` while JAX's last event was a trace or a lowering (``k`` compiled or loaded
    since the count was ``ready_before``), else ``running``."""
    if _EVENTS["last"] == "build":
        k = _EVENTS["ready"] - ready_before
        return f"compiling ({k} program{'' if k == 1 else 's'} ready)"
    return "running"


class progress_line:
    """Context manager showing the stage and elapsed time of the block on a terminal (module docstring)."""

    def __init__(self, what: str, after: float | None = None, interval: float = 1.0, stream=None):
        self.what = what
        self.after = float(os.environ.get("POLYJAX_PROGRESS_SECS", 3.0)) if after is None else float(after)
        self.interval = float(interval)
        self.stream = sys.stderr if stream is None else stream
        self._done = threading.Event()
        self._thread: threading.Thread | None = None
        self._shown = False

    def _enabled(self) -> bool:
        off = os.environ.get("POLYJAX_PROGRESS", "").strip().lower() in ("off", "0", "no", "false")
        isatty = getattr(self.stream, "isatty", None)
        return not off and callable(isatty) and bool(isatty())

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

    def __enter__(self):
        if self._enabled():
            _listen()
            self._thread = threading.Thread(target=self._run, daemon=True)
            self._thread.start()
        return self

    def __exit__(self, *exc):
        self._done.set()
        if self._thread is not None:
            self._thread.join()
            if self._shown:  # erase the line
                self.stream.write("\r\033[K")
                self.stream.flush()
        return False
