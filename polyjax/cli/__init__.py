"""The ``polyjax`` command line: :func:`main` (the console script and ``python -m polyjax``) and its parser,
:func:`build_parser`."""

from ._main import build_parser, main

__all__ = ["build_parser", "main"]
