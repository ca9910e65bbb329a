"""A one-line progress display on a terminal for long command-line work: elapsed seconds, updated in place.

A fit is one compiled program, so there is no fraction done to show from outside it; what a user needs in a long
fit is to see that it is alive and how long it has taken. :class:`progress_line` writes ``polyjax: <what>: 12 s``
on stderr, rewritten every second, once the block has run ``after`` seconds (default 3,
``$POLYJAX_PROGRESS_SECS``), and erases it at the end; only when the stream is a terminal (quiet in pipes, logs and
tests), and never with ``POLYJAX_PROGRESS=off``.
"""

from __future__ import annotations

import os
import sys
import threading
import time


class progress_line:
    """Context manager showing the elapsed time of the block on a terminal (module docstring)."""

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
        t0 = time.perf_counter()
        if self._done.wait(self.after):
            return
        while True:
            self._shown = True
            self.stream.write(f"\rpolyjax: {self.what}: {time.perf_counter() - t0:.0f} s ")
            self.stream.flush()
            if self._done.wait(self.interval):
                return

    def __enter__(self):
        if self._enabled():
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
