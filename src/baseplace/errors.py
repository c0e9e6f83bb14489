"""The one exception hierarchy of baseplace.

Every error a user can cause derives from :class:`BaseplaceError`; its message is one line that
names what is wrong and, where there is a finite set, the valid choices. The CLI maps
:class:`InputError` to exit code 2 and :class:`NothingFoundError` to exit code 3.
"""

from __future__ import annotations

import reprlib
from collections.abc import Iterable


class BaseplaceError(Exception):
    """Root of every error baseplace raises on purpose."""

    exit_code = 2


class InputError(BaseplaceError, ValueError):
    """Bad input: a malformed file, an unknown name, a value out of range (CLI exit 2)."""

    exit_code = 2


class NothingFoundError(BaseplaceError):
    """The computation ran but found nothing, e.g. no reachable placement (CLI exit 3)."""

    exit_code = 3


def brief(value: object, limit: int = 60) -> str:
    """``repr(value)`` cut to about ``limit`` characters, for error messages about file contents.

    ``reprlib`` never expands more than a few items per level, so a YAML alias bomb (a tiny file
    standing for a huge nested list) cannot blow up a message.
    """
    r = reprlib.Repr()
    r.maxstring = r.maxother = limit
    r.maxlist = r.maxtuple = r.maxdict = r.maxset = 6
    r.maxlevel = 3
    text = r.repr(value)
    return text if len(text) <= limit + 10 else text[:limit] + "..."


def choices(valid: Iterable[str], limit: int = 12) -> str:
    """Format a list of valid choices for an error message, shortening long lists."""
    items = sorted(set(valid))
    shown = ", ".join(items[:limit])
    if len(items) > limit:
        shown += f", ... ({len(items)} in all)"
    return shown


def unknown(kind: str, name: str, valid: Iterable[str], owner: str | None = None) -> InputError:
    """Build the standard "unknown X 'name' [of owner]; valid: ..." error."""
    of = f" of {owner}" if owner else ""
    return InputError(f"unknown {kind} {name!r}{of}; valid: {choices(valid)}")
