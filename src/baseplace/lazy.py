"""Imported on first use: a package's public names (PEP 562), a numba kernel; importing costs none of them."""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from typing import Any


def lazy_getattr(package: str, names: Mapping[str, str], namespace: dict[str, Any]) -> Callable[[str], Any]:
    """A module ``__getattr__`` for ``package``: ``names`` maps each public name to its module.

    The first lookup imports the module and keeps the value in ``namespace`` (the package's
    ``globals()``), so later lookups are plain attributes; any other name is an AttributeError.
    """

    def __getattr__(name: str) -> Any:
        module = names.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        namespace[name] = value
        return value

    return __getattr__


def lazy_njit(fn: Callable[..., Any]) -> Callable[..., Any]:
    """``fn`` compiled by numba (``cache=True``) at its first call; numba is imported then, not before."""
    compiled: list[Callable[..., Any]] = []

    def call(*args: Any) -> Any:
        if not compiled:
            import numba as nb

            compiled.append(nb.njit(cache=True)(fn))
        return compiled[0](*args)

    call.__doc__ = fn.__doc__
    return call
