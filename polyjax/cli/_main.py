"""The ``polyjax`` command line's dispatcher: the parser of the command named (each command is a module of this folder,
imported only when its command is parsed or run, so that ``polyjax fit`` loads none of render, export or svbrdf),
the compilation cache turned on, the command run, its errors printed, the cache folder trimmed.

The paper's reproduction is a script of the repository, not a command: ``python benchmarks/reproduce.py``.
"""

from __future__ import annotations

import argparse
import importlib
import sys

import jax

from .._cache.compilation import cache_disabled_by_env, cache_uses, enable_compilation_cache
from .._errors import InputError, PolyjaxError
from .._run import interrupt
from .._run.ending import end_process
from ._args import Parser, add_global_options
from ._cache import cache_cap_bytes, trim_cache

#: every command and the module of this folder that defines it (in the order of ``polyjax --help``)
COMMANDS = {"report": "_report", "fit": "_fit", "cache": "_cache", "render": "_render", "fit-images": "_fit_images",
            "fit-photos": "_photos", "relight": "_photos", "export": "_export", "svbrdf": "_svbrdf", "view": "_view"}


def _command_module(name: str):
    """The module of a command, imported on first use (the one lazy import of each command)."""
    return importlib.import_module(f".{name}", __package__)


def _command_of(argv: list[str]) -> str | None:
    """The command named in ``argv`` (the first positional argument after the global options), if any."""
    i = 0
    while i < len(argv):
        a = argv[i]
        if a in ("--data-root", "--cache-dir"):
            i += 2
            continue
        if a.startswith("-"):
            i += 1
            continue
        return a
    return None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The parser of ``command`` alone (only its module is imported: a shorter start for ``polyjax fit``), or of every
    command when ``command`` is None or not one of :data:`COMMANDS`."""
    p = Parser(prog="polyjax",
                                description="Fit polynomial (and baseline) BRDF models to measured data.")
    add_global_options(p)
    common = add_global_options(Parser(add_help=False), argparse.SUPPRESS)
    sub = p.add_subparsers(dest="command")
    modules = [COMMANDS[command]] if command in COMMANDS else list(dict.fromkeys(COMMANDS.values()))
    for name in modules:
        _command_module(name).add_parser(sub, common)
    return p


def _compilation_cache(args):
    """Turn on the persistent compilation cache unless ``--no-cache`` or ``POLYJAX_CACHE=off``; its folder, or None
    (also when the folder may not be trusted: then nothing is loaded from it or written to it, and it is not
    trimmed)."""
    if args.no_cache or (args.cache_dir is None and cache_disabled_by_env()):
        return None
    folder = enable_compilation_cache(args.cache_dir)
    return folder if jax.config.jax_enable_compilation_cache else None


def main(argv: list[str] | None = None) -> int:
    """Run the command line on ``argv`` (default ``sys.argv[1:]``); returns the exit status (2 on a polyjax error,
    130 on Ctrl-C: the program's own run, ``argv`` None, stops its work within a second or two, removes what it left
    half made, prints ``interrupted``: :mod:`polyjax._run.interrupt`).

    The program's own run (``argv`` None) then ends the process itself once the command has returned: its output
    flushed and its exit handlers run, without the interpreter's teardown (:mod:`polyjax._run.ending`: 0.3-0.4 s
    of CPU in every process that imported JAX); an exception, or a thread still running, takes Python's ordinary
    exit."""
    if argv is None:
        interrupt.install()
        return end_process(_run(None))
    return _run(argv)


def _run(argv: list[str] | None) -> int:
    """:func:`main`'s command run: the exit status."""
    jax.config.update("jax_enable_x64", True)
    argv = sys.argv[1:] if argv is None else list(argv)
    parser = build_parser(_command_of(argv))
    args = parser.parse_args(argv)
    if args.command is None:
        args.func = _command_module(COMMANDS["report"]).cmd_report
    uses, status = cache_uses(), 2
    for flag in ("out", "save"):  # what Ctrl-C may leave half made
        if isinstance(getattr(args, flag, None), str):
            interrupt.watch_output(getattr(args, flag))
    try:
        args.cache_in_use = None if args.command == "cache" else _compilation_cache(args)
        status = int(args.func(args) or 0)
        return status
    except PolyjaxError as e:
        print(f"polyjax: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # Ctrl-C (Interrupted, or Python's own where the handler is not installed)
        status = interrupt.finish()
        return status
    finally:  # a run that looked the cache up or wrote to it, or that ran to its end, opened it
        _trim(getattr(args, "cache_in_use", None), cache_uses() > uses or status == 0)


def _trim(folder, opened: bool) -> None:
    """The cache folder's size cap, applied after a run that used it (:mod:`polyjax.cli._cache`): not after a run that
    never opened it (``opened`` False: one that failed on its arguments, say), nor after Ctrl-C."""
    if folder is None or not opened or interrupt.interrupted():
        return
    try:
        trim_cache(folder, cache_cap_bytes())
    except InputError as e:
        print(f"polyjax: warning: cache not trimmed: {e}", file=sys.stderr)


if __name__ == "__main__":
    sys.exit(main())
