"""The ``polyjax`` command line: :func:`main` (the console script and ``python -m polyjax``)."""

from ._main import main

__all__ = ["main"]
