"""One exception class per kind of bad data file; all are :class:`polyjax.DataFormatError` (or
:class:`polyjax.UnknownNameError`) subclasses, raised in Python before any JAX code runs.

Each message names the file, what the reader expected and what it found.
"""

from __future__ import annotations

from .._errors import DataFormatError, UnknownNameError


class EmptyFileError(DataFormatError):
    """The file has no content (0 bytes, or only comments and blank lines)."""


class TruncatedFileError(DataFormatError):
    """The file ends before the data its header announces (e.g. a partial download)."""


class HeaderError(DataFormatError):
    """The header is present but wrong (bad dimensions, wavelengths, counts)."""


class WrongFormatError(DataFormatError):
    """The file is of another format (e.g. text given to the MERL binary reader)."""


class NonFiniteValueError(DataFormatError):
    """The file holds NaN or infinite values."""


class UnknownMaterialError(UnknownNameError):
    """A material name that the dataset does not have."""
