"""Guards against hostile or unlucky input: names, sizes declared by files, output paths.

Files are data, never code (docs/security.md). This module holds the three checks every entry
point shares:

- :func:`check_name`: robot and arm names are conservative identifiers, so they can never
  reach generated code or a file path as anything but a plain word.
- :func:`check_alloc`: a loader asks before it allocates an array whose size a file declares;
  the size must fit both a limit derived from the file's own size and a global cap
  (``$BASEPLACE_MAX_MEMORY_MB``, default 4096 MB).
- :func:`check_output_path`: an output path is checked (length, component length, type,
  writability, suffix) before any work is done.

Files read whole have their size checked before they are read (:func:`check_file_size`); the
small YAML and TOML documents (robot files, map YAMLs, CameraInfo) are read by one function,
:func:`read_document`, that does so and turns every parser error into one line.
"""

from __future__ import annotations

import os
import re
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from baseplace.errors import InputError, brief

NAME_PATTERN = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,63}")
"""Robot and arm names: a letter, then up to 63 letters, digits, ``_`` or ``-``."""


def check_name(value: str, what: str, source: str = "robot spec") -> str:
    """Return ``value`` if it is a conservative identifier (:data:`NAME_PATTERN`), else raise.

    Raises:
        InputError: one line naming the rule; the bad value is shown shortened and escaped.
    """
    if not isinstance(value, str) or NAME_PATTERN.fullmatch(value) is None:
        raise InputError(
            f"{source}: {what} {brief(value, 40)} is not a valid name; use a letter followed by "
            "at most 63 letters, digits, '_' or '-'"
        )
    return value


DEFAULT_MAX_MEMORY_MB = 4096


def memory_cap_bytes() -> int:
    """The most bytes one loaded array may take: ``$BASEPLACE_MAX_MEMORY_MB`` (default 4096 MB)."""
    text = os.environ.get("BASEPLACE_MAX_MEMORY_MB")
    if text:
        try:
            mb = float(text)
        except ValueError:
            raise InputError(f"BASEPLACE_MAX_MEMORY_MB must be a number of megabytes, got {text!r}") from None
        if mb > 0:
            return int(mb * 2**20)
    return DEFAULT_MAX_MEMORY_MB * 2**20


def check_alloc(
    n_bytes: float, what: str, source: object, file_bytes: int | None = None, per_file_byte: float = 0.0
) -> None:
    """Raise unless an allocation of ``n_bytes`` that a file declares is plausible and affordable.

    Args:
        n_bytes: bytes the loader is about to allocate.
        what: what it is, for the message ("points", "grid cells").
        source: the file, for the message.
        file_bytes: the size of the file that declares it; with ``per_file_byte`` > 0, at most
            ``per_file_byte * file_bytes`` (+ 1 MB) may be allocated (an uncompressed format
            cannot hold more than its bytes).
        per_file_byte: the most bytes one byte of the file can stand for (0: no such limit).

    Raises:
        InputError: the size is negative, beyond what the file can hold, or beyond the cap.
    """
    if not n_bytes >= 0:
        raise InputError(f"{source}: declared size of {what} is negative or not a number")
    if file_bytes is not None and per_file_byte > 0 and n_bytes > per_file_byte * file_bytes + 2**20:
        raise InputError(
            f"{source}: declares {what} of {n_bytes / 1e6:.3g} MB, more than its {file_bytes} bytes can hold; "
            "the file is truncated or corrupt"
        )
    cap = memory_cap_bytes()
    if n_bytes > cap:
        raise InputError(
            f"{source}: {what} would take {n_bytes / 1e6:.3g} MB, over the limit of {cap / 1e6:.0f} MB "
            "(raise BASEPLACE_MAX_MEMORY_MB to allow it)"
        )


def check_grid_size(
    count: float,
    bytes_each: float,
    what: str,
    remedy: str,
    unit: str = "cells",
    reserved_bytes: float = 0.0,
    max_count: float = float("inf"),
) -> None:
    """Refuse a grid of ``count`` cells (or voxels) sized by the user before it is allocated.

    The limit is what ``$BASEPLACE_MAX_MEMORY_MB``, less ``reserved_bytes``, holds at the grid's
    measured ``bytes_each`` (and at most ``max_count``).

    Args:
        count: cells (or voxels) the grid will hold.
        bytes_each: measured peak bytes per cell.
        what: the grid with its size, as the message starts ("a height map of 10 x 20 = 200 cells").
        remedy: what the user can change.
        unit: what a cell is called in the message.
        reserved_bytes: bytes of the cap already taken by what is built beside the grid.
        max_count: a fixed upper limit of cells, whatever the cap.

    Raises:
        InputError: one line: ``what``, the limit, the bytes per cell, the cap and ``remedy``.
    """
    cap = memory_cap_bytes()
    limit = int(max(0.0, min(max_count, (cap - reserved_bytes) / bytes_each)))
    if count > limit:
        raise InputError(
            f"{what} is over the limit of {limit:.3g} {unit} ({bytes_each:.0f} bytes each within "
            f"BASEPLACE_MAX_MEMORY_MB={cap / 2**20:.0f}); {remedy}"
        )


MAX_PATH_BYTES = 4095
MAX_COMPONENT_BYTES = 255


def check_path_length(text: str | os.PathLike[str], what: str) -> str:
    """Return the path as text if it is not empty, holds no NUL and fits the OS limits.

    Raises:
        InputError: the path is over 4095 bytes, a component over 255 bytes, empty or has a NUL.
    """
    raw = os.fspath(text)
    if not raw or "\x00" in raw:
        raise InputError(f"{what} must be a file path, got {brief(raw, 40)}")
    encoded = os.fsencode(raw)
    if len(encoded) > MAX_PATH_BYTES:
        raise InputError(f"{what} path is {len(encoded)} bytes long; the limit is {MAX_PATH_BYTES}")
    for part in Path(raw).parts:
        if len(os.fsencode(part)) > MAX_COMPONENT_BYTES:
            raise InputError(
                f"{what}: the path component {brief(part, 40)} is {len(os.fsencode(part))} bytes long; "
                f"the limit is {MAX_COMPONENT_BYTES}"
            )
    return raw


def check_input_file(path: str | os.PathLike[str], what: str, suffixes: Iterable[str]) -> Path:
    """``path`` as a file to read as ``what``: a suffix among ``suffixes`` (any case) and an existing file.

    Nothing is read; the path is shortened in the messages (it may come from a request).

    Raises:
        InputError: one line: a path the OS cannot take (:func:`check_path_length`), an unknown
            suffix (with the valid ones), or no such file.
    """
    p = Path(check_path_length(path, what))
    valid = sorted(suffixes)
    if p.suffix.lower() not in valid:
        raise InputError(
            f"cannot read {what} {brief(str(p), 200)}: unknown suffix {p.suffix!r}; valid: {', '.join(valid)}"
        )
    if not p.is_file():
        raise InputError(f"{what} file {brief(str(p), 200)} does not exist")
    return p


def _size_text(limit: int) -> str:
    return f"{limit >> 20} MB" if limit >= 1 << 20 else f"{limit >> 10} KiB"


def check_file_size(path: Path, what: str, limit: int, usual: str = "") -> None:
    """Refuse the file ``what`` ("URDF", "map YAML") over ``limit`` bytes before it is read.

    ``usual`` says, in the message, what such a file usually holds.

    Raises:
        InputError: one line with the size and the limit, or why the file cannot be read.
    """
    try:
        size = path.stat().st_size
    except OSError as exc:
        raise InputError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if size > limit:
        hint = f"; {usual}" if usual else ""
        raise InputError(f"{what} {path} is {size} bytes; the limit is {limit} ({_size_text(limit)}){hint}")


def read_document(path: Path, what: str, limit: int, usual: str = "") -> Any:
    """The parsed contents of a small YAML or TOML file (``.toml`` is TOML, any other suffix YAML).

    The size is checked first (:func:`check_file_size`): PyYAML's pure-Python parser takes about
    a second a megabyte, and nests as deep as the text does.

    Raises:
        InputError: one line: the file cannot be read, is over ``limit`` bytes, is not UTF-8
            text, or does not parse (with the line and column where the parser gives them).
    """
    check_file_size(path, what, limit, usual)
    try:
        raw = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise InputError(f"cannot parse {what} {path}: not UTF-8 text") from None
    except OSError as exc:
        raise InputError(f"cannot read {what} {path}: {exc.strerror or exc}") from None
    if path.suffix.lower() == ".toml":
        try:
            import tomllib
        except ModuleNotFoundError:  # Python 3.10
            import tomli as tomllib  # type: ignore[no-redef]
        try:
            return tomllib.loads(raw)
        except tomllib.TOMLDecodeError as exc:
            raise InputError(f"cannot parse {what} {path}: {str(exc).strip() or 'not TOML'}") from None
        except RecursionError:
            raise InputError(f"cannot parse {what} {path}: nested too deeply") from None
    import yaml

    try:
        return yaml.safe_load(raw)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        at = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = " ".join(str(exc.problem or exc.context).split())[:160]
        raise InputError(f"cannot parse {what} {path}{at}: {problem}") from None
    except yaml.YAMLError as exc:
        raise InputError(f"cannot parse {what} {path}: {' '.join(str(exc).split())[:160]}") from None
    except RecursionError:
        raise InputError(f"cannot parse {what} {path}: nested too deeply") from None


def check_output_path(
    text: str | os.PathLike[str], what: str = "--out", suffixes: Iterable[str] | None = None
) -> Path:
    """Check an output file path before any work is done; returns it as a Path.

    Checks: total length (4095 bytes) and every component (255 bytes), no NUL, suffix among
    ``suffixes`` (case-insensitive; None: any), the path is not an existing directory, its
    directory exists, is a directory and is writable.

    Raises:
        InputError: one line naming the problem.
    """
    raw = check_path_length(text, what)
    path = Path(raw)
    # temporary files are named ".NAME.XXXXXXXX.tmp" and checkpoints "NAME.partial": keep room
    if len(os.fsencode(path.name)) > MAX_COMPONENT_BYTES - 24:
        raise InputError(
            f"{what}: the file name is {len(os.fsencode(path.name))} bytes long; "
            f"the limit is {MAX_COMPONENT_BYTES - 24} (room for temporary files beside it)"
        )
    if suffixes is not None:
        valid = sorted(suffixes)
        if path.suffix.lower() not in valid:
            raise InputError(f"{what} {brief(raw, 60)} has suffix {path.suffix!r}; valid: {', '.join(valid)}")
    if path.is_dir():
        raise InputError(f"{what} {brief(raw, 60)} is a directory; give a file path")
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"{what} directory {brief(str(directory), 60)} does not exist")
    if not os.access(directory, os.W_OK | os.X_OK):
        raise InputError(f"{what} directory {brief(str(directory), 60)} is not writable")
    if path.exists() and not path.is_file():
        raise InputError(f"{what} {brief(raw, 60)} exists and is not a regular file")
    return path


def check_output_dir(text: str | os.PathLike[str], what: str = "--out") -> Path:
    """Check an output directory before any work is done, and create it; returns it as a Path.

    Checks: the path's length (as :func:`check_path_length`), it is a directory or does not exist yet,
    and its nearest existing folder is a writable directory.

    Raises:
        InputError: one line naming the problem.
    """
    path = Path(check_path_length(text, what))
    if path.exists() and not path.is_dir():
        raise InputError(f"{what} {brief(str(path), 60)} exists and is not a directory")
    existing = path
    while not existing.exists() and existing != existing.parent:
        existing = existing.parent
    if not existing.is_dir():
        raise InputError(f"{what} {brief(str(path), 60)}: {brief(str(existing), 60)} is not a directory")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise InputError(f"{what} directory {brief(str(existing), 60)} is not writable")
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputError(f"{what} {brief(str(path), 60)} cannot be created: {exc.strerror}") from None
    return path
