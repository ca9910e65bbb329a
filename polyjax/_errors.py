"""Exception classes raised by polyjax.

Every error raised on bad input is a :class:`PolyjaxError`, raised in Python before any
JAX code runs, and its message names the offending file or argument, what was expected and
what was found.
"""

from __future__ import annotations


class PolyjaxError(Exception):
    """Base class of every error polyjax raises on purpose."""


class InputError(PolyjaxError, ValueError):
    """An argument has the wrong shape, dtype or content (e.g. NaN values)."""


class DataNotFoundError(PolyjaxError, FileNotFoundError):
    """The data root or a file inside it is missing."""


class DataFormatError(PolyjaxError, ValueError):
    """A data file exists but does not have the expected format.

    Attributes:
        path: the file.
        expected: what the reader expected.
        found: what it found instead.
    """

    def __init__(self, path, expected: str, found: str):
        self.path = str(path)
        self.expected = expected
        self.found = found
        super().__init__(f"{self.path}: expected {expected}, found {found}")


class UnknownNameError(PolyjaxError, KeyError):
    """A name (material, sample, variable set, model) is not known."""

    def __str__(self) -> str:  # KeyError quotes its message otherwise
        return str(self.args[0]) if self.args else ""


class FitError(PolyjaxError, RuntimeError):
    """A fit could not produce a meaningful result (rank deficiency, no samples)."""
