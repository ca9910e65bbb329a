"""JAX's persistent compilation cache: compile a program once per machine, not once per process.

A polyjax fit runs in well under a millisecond once compiled, but compiling it takes seconds. JAX can keep the
compiled programs on disk and load them in later processes (a program is found again when its shapes, dtypes,
static arguments and JAX version are the same). The command line turns this on by default; API users call
:func:`enable_compilation_cache` once. Importing polyjax never changes JAX's settings.
"""

from __future__ import annotations

import logging
import os
import threading
from pathlib import Path

import jax
import jax.monitoring

from .._errors import InputError
from .._files import make_cache_folder, mark_cache_folder, trusted, untrusted_reason

#: environment variable naming the cache folder; empty, ``off``, ``0``, ``no`` or ``false`` disables the cache
CACHE_ENV = "POLYJAX_CACHE"
_OFF = ("", "off", "0", "no", "false", "none")


def cache_disabled_by_env() -> bool:
    """True when ``$POLYJAX_CACHE`` is set to an off value (empty, ``off``, ``0``, ``no``, ``false``, ``none``)."""
    value = os.environ.get(CACHE_ENV)
    return value is not None and value.strip().lower() in _OFF


def default_cache_dir() -> Path:
    """The cache folder: ``$POLYJAX_CACHE`` if it names one, else ``$XDG_CACHE_HOME/polyjax/jax``
    (``~/.cache/polyjax/jax`` when ``XDG_CACHE_HOME`` is unset)."""
    value = os.environ.get(CACHE_ENV)
    if value is not None and value.strip().lower() not in _OFF:
        return Path(value).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "polyjax" / "jax"


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path:
    """Turn on JAX's persistent compilation cache for this process (every jitted program, polyjax's or not).

    Every compiled program is written, however small or quick to compile (JAX's defaults skip programs that
    compile in under a second, which are most of polyjax's): the thresholds
    ``jax_persistent_cache_min_compile_time_secs`` and ``jax_persistent_cache_min_entry_size_bytes`` are set to
    0 and -1. Later processes with the same shapes, options and JAX version load the programs instead of
    compiling them (a warm ``polyjax fit`` takes about 0.4 of a cold one: ``benchmarks/bench_latency_cli.py``).
    Tracing and lowering still run in every process (the cache is keyed by the lowered program).

    JAX loads native programs from this folder, so it is used only when it belongs to the current user and neither
    group nor others may write it (:func:`polyjax._files.trusted`); otherwise a warning names the folder and the
    reason, and JAX's persistent cache stays off (programs are compiled afresh). A folder created here has mode
    ``0700`` and polyjax's marker (:data:`polyjax._files.MARKER`): only a marked folder is ever trimmed or cleared,
    and only of polyjax's and JAX's own entries (:mod:`polyjax.cli._cache`). The default folder, whose name is
    polyjax's, is marked when found without the marker (made by an older polyjax).

    Args:
        path: the cache folder; default :func:`default_cache_dir` (``$POLYJAX_CACHE`` or
            ``$XDG_CACHE_HOME/polyjax/jax``). Created if missing.

    Returns:
        The folder in use (also when it may not be trusted: JAX's cache is then off).

    Raises:
        InputError: ``path`` exists and is not a folder, or cannot be created.
    """
    folder = Path(path).expanduser() if path is not None else default_cache_dir()
    if folder.exists() and not folder.is_dir():
        raise InputError(f"cache folder {str(folder)!r}: exists and is not a folder")
    try:
        make_cache_folder(folder)
        if path is None and folder == default_cache_dir() and untrusted_reason(folder) is None:
            mark_cache_folder(folder)
    except OSError as e:
        raise InputError(f"cache folder {str(folder)!r}: cannot be created ({e.strerror or e})") from None
    if not trusted(folder, what="JAX's persistent compilation cache"):
        jax.config.update("jax_enable_compilation_cache", False)
        return folder
    _watch_use()
    jax.config.update("jax_enable_compilation_cache", True)  # in case a process turned JAX's cache off before
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    try:  # a cache already initialised (a program compiled before this call) keeps its old folder otherwise
        from jax._src import compilation_cache  # private JAX API: imported only to reset an initialised cache

        if compilation_cache.is_initialized():
            compilation_cache.reset_cache()
    except (ImportError, AttributeError):  # pragma: no cover - private API moved; the settings above still apply
        pass
    return folder


_used = {"requests": 0, "writes": 0}
_watching = False


def _watch_use() -> None:
    """Count the look-ups of JAX's persistent cache (idempotent): :func:`cache_used` then says whether any ran."""
    global _watching
    if not _watching:
        def on_event(event: str, **_) -> None:
            if event == "/jax/compilation_cache/compile_requests_use_cache":
                _used["requests"] += 1

        jax.monitoring.register_event_listener(on_event)
        _watching = True


def note_cache_write() -> None:
    """Record that polyjax wrote into the cache folder (a saved program, a geometry): :func:`cache_used`."""
    _used["writes"] += 1


def cache_uses() -> int:
    """How many times this process looked up JAX's persistent cache (after :func:`enable_compilation_cache`) or wrote
    a polyjax entry into the cache folder: a run during which it did not grow never opened the cache, and has nothing
    to trim."""
    return _used["requests"] + _used["writes"]


_counts = {"requests": 0, "answered": 0, "misses": 0}
_listening = False
#: the line JAX's compiler logs (at DEBUG) when the persistent cache does not hold a program, just before compiling it
_MISS = "PERSISTENT COMPILATION CACHE MISS"


class _MissCounter(logging.Filter):
    """Counts JAX's persistent-cache misses from its compiler's log, passing on only the records the logger would
    have emitted at its level before (so no one's log gets JAX's DEBUG lines)."""

    def __init__(self, level: int):
        super().__init__()
        self.level = level

    def filter(self, record: logging.LogRecord) -> bool:
        if record.msg.startswith(_MISS) if isinstance(record.msg, str) else False:
            _counts["misses"] += 1
        return record.levelno >= self.level


def _listen() -> None:
    """Count the persistent cache's look-ups, their outcomes (a hit, or a compiled program written) and its misses
    (JAX logs each one before it compiles the program: the one sure sign that something is being compiled)."""
    global _listening
    if _listening:
        return

    def on_event(event: str, **_) -> None:
        if event == "/jax/compilation_cache/compile_requests_use_cache":
            _counts["requests"] += 1
        elif event in ("/jax/compilation_cache/cache_hits", "/jax/compilation_cache/cache_misses"):
            _counts["answered"] += 1

    jax.monitoring.register_event_listener(on_event)
    log = logging.getLogger("jax._src.compiler")
    log.addFilter(_MissCounter(log.getEffectiveLevel()))
    log.setLevel(min(log.getEffectiveLevel(), logging.DEBUG))
    _listening = True


def listen_for_misses() -> None:
    """Start counting the persistent cache's misses (idempotent): :func:`cache_misses` then reports them."""
    _listen()


def cache_misses() -> int:
    """How many programs JAX's persistent cache did not hold since :func:`listen_for_misses` (each one compiled)."""
    return _counts["misses"]


_SAVING = threading.Lock()


def compile_for_saving(fn, arrays, name: str, compiler_options: dict | None = None):
    """``jax.jit(fn)`` lowered for ``arrays`` and compiled afresh, never through JAX's persistent compilation cache:
    the executable of a saved program, to be serialised (:mod:`polyjax._fit.saved`, ``baselines``' own).

    In this JAX an executable that the persistent cache loaded does not serialise whole: written and loaded again
    in a later process it fails when run (``NOT_FOUND: Function ..._kernel not found``), as it did in every
    ``polyjax fit`` and ``baselines.fit`` once the saved file was gone (a cleared folder, a new source stamp) while
    JAX's cache kept the program. So the program is named ``name`` (unique to the saved program's key, which JAX's
    cache key then includes: no entry of another polyjax version matches it) and is not written into JAX's cache
    (the minimum compile time for writing is raised while it compiles; the saved file is its persistent form).

    Args:
        fn: the program; ``arrays``: its arguments (concrete, or ``jax.ShapeDtypeStruct``).
        name: the program's name, letters, digits and ``_``.
        compiler_options: XLA's options; an XLA that refuses them compiles with its defaults.

    Returns:
        The compiled executable (:class:`jax.stages.Compiled`). Lowering raises what tracing ``fn`` raises.
    """

    def program(*args):
        return fn(*args)

    program.__name__ = program.__qualname__ = name
    lowered = jax.jit(program).lower(*arrays)
    with _SAVING:
        before = jax.config.jax_persistent_cache_min_compile_time_secs
        jax.config.update("jax_persistent_cache_min_compile_time_secs", float("inf"))
        try:
            if compiler_options:
                try:
                    return lowered.compile(compiler_options)
                except Exception:  # noqa: BLE001 - an XLA that no longer knows an option: its defaults
                    pass
            return lowered.compile()
        finally:
            jax.config.update("jax_persistent_cache_min_compile_time_secs", before)
