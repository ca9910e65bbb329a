"""The caps on what a loader reads, inflates or decodes, in one place.

- :func:`input_limit`: the most bytes any one input file, inflated member or decoded array may hold: the
  environment variable ``POLYJAX_MAX_INPUT_MB`` (MiB), 4096 by default. Every loader checks the sizes a file
  declares (its length on disk, a header's dimensions, a zip member's size) against it before reading.
- :data:`NETWORK_BYTES`: one neural-BRDF network (``<material>.h5``, about 4 KB of weights in a ~20 KB file):
  16 MiB, or the input limit if smaller.
- :data:`MAX_DEFLATE_RATIO`: deflate inflates at most 1032-fold (RFC 1951's longest match per 2 bits), so a PNG
  or a zip member declaring more than that times its compressed size is refused before it is inflated.
- :data:`JSON_MAX_DIGITS`: an integer in a JSON file (a saved model, a manifest, a scene) has at most 40 digits.
"""

from __future__ import annotations

import os

from .._errors import InputError

LIMIT_ENV = "POLYJAX_MAX_INPUT_MB"
DEFAULT_LIMIT_MB = 4096
NETWORK_BYTES = 16 * 2**20
MAX_DEFLATE_RATIO = 1032
JSON_MAX_DIGITS = 40


def input_limit() -> int:
    """The byte cap of one input file, inflated member or decoded array (``POLYJAX_MAX_INPUT_MB``, MiB)."""
    text = os.environ.get(LIMIT_ENV, "").strip()
    if not text:
        return DEFAULT_LIMIT_MB * 2**20
    try:
        mb = float(text)
    except ValueError:
        mb = -1.0
    if not mb > 0 or mb != mb or mb == float("inf"):
        raise InputError(f"{LIMIT_ENV}: expected a positive number of MiB, found {text!r}")
    return int(mb * 2**20)


def network_limit() -> int:
    """The byte cap of one neural-BRDF network file: :data:`NETWORK_BYTES` or the input limit if smaller."""
    return min(NETWORK_BYTES, input_limit())


def describe(nbytes: int) -> str:
    """``nbytes`` in words (``"12.0 MiB (12582912 bytes)"``)."""
    return f"{nbytes / 2**20:.1f} MiB ({nbytes} bytes)"
