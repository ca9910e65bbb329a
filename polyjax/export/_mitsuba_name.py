"""The name of a Mitsuba plugin: a Python identifier, checked before it is registered or written into a file."""

from __future__ import annotations

import keyword

from .._errors import InputError


def check_plugin_name(name, flag: str = "name") -> str:
    """``name`` when it is a Python identifier (letters, digits and ``_``, not starting with a digit, not a keyword):
    the names Mitsuba's plugin registry and scene files use, and nothing a generated file could run.

    Raises:
        InputError: naming ``flag`` and the name found.
    """
    if not isinstance(name, str) or not name.isidentifier() or keyword.iskeyword(name) or not name.isascii():
        raise InputError(f"{flag}: expected a Mitsuba plugin name (letters, digits and _, not starting with a digit), "
                         f"found {name!r}")
    return name


__all__ = ["check_plugin_name"]
