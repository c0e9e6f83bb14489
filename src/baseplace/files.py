"""Atomic file writes: a crash or an error never leaves a half-written file under the final name."""

from __future__ import annotations

import contextlib
import fcntl
import glob
import os
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path

from baseplace.errors import InputError


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextlib.contextmanager
def atomic_write(path: str | Path, what: str = "file") -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success it replaces ``path``, on error it vanishes.

    The finished file gets the permissions a plain ``open(path, "w")`` would (0666 less the umask).

    Raises:
        InputError: the target directory does not exist.
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"cannot write {what} {path}: directory {directory} does not exist")
    fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        _fsync(tmp)  # the bytes are on disk before the name points at them
        os.replace(tmp, path)
        _fsync(directory)  # and the rename is on disk before the caller deletes anything
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    except OSError:  # pragma: no cover - some file systems cannot fsync a directory
        pass
    finally:
        os.close(fd)


def remove_stray_temporaries(path: str | Path) -> int:
    """Delete the temporary files a killed :func:`atomic_write` to ``path`` left; returns how many.

    Call it only while holding :func:`output_lock` of ``path``: another process's write in
    progress has a temporary file of the same pattern.
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    n = 0
    for stray in directory.glob(f".{glob.escape(path.name)}.*.tmp"):
        stray.unlink(missing_ok=True)
        n += 1
    return n


@contextlib.contextmanager
def output_lock(path: str | Path, wait: Callable[[], None] | None = None) -> Iterator[None]:
    """Hold an exclusive lock on the output ``path`` (a ``.NAME.lock`` file beside it).

    Two processes writing the same output (two builds to one ``--out``, two cache builds of one
    map) take turns: the second blocks until the first is done. ``wait`` is called once if the
    lock is held by another process, before blocking. The lock dies with its process, even on
    SIGKILL; the holder deletes the lock file on release, and a process that locked a file
    deleted meanwhile starts over, so the deletion cannot let two holders in.

    Raises:
        InputError: the lock file cannot be created (e.g. the directory does not exist).
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    lock = directory / f".{path.name}.lock"
    waited = False
    while True:
        try:
            fd = os.open(lock, os.O_RDWR | os.O_CREAT, 0o666 & ~_umask())
        except OSError as exc:
            raise InputError(f"cannot lock {path}: {exc.strerror} ({directory})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            if wait is not None and not waited:
                wait()
            waited = True
            fcntl.flock(fd, fcntl.LOCK_EX)
        try:
            same = os.stat(lock).st_ino == os.fstat(fd).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)  # the holder before us deleted this lock file: lock the new one
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(lock)
        os.close(fd)
