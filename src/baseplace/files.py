"""Atomic file writes: a crash or an error never leaves a half-written file under the final name.

A full disk (``ENOSPC``), a full quota (``EDQUOT``) or a file over the size limit (``EFBIG``)
while writing is an :class:`OutputError` (one line, CLI exit 2): the previous file under the name
is untouched and the temporary file is gone. HDF5 files are built in memory and written as bytes
(:func:`atomic_hdf5`): HDF5 failing to write its own file leaves its library in a state that
crashes the process later (a segfault at exit), so it never writes to the disk itself.
"""

from __future__ import annotations

import contextlib
import errno
import fcntl
import glob
import io
import os
import shutil
import tempfile
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from baseplace.errors import BaseplaceError, InputError

if TYPE_CHECKING:
    import h5py

DISK_FULL = frozenset({errno.ENOSPC, errno.EDQUOT, errno.EFBIG})
"""The errnos of a write that cannot fit: no space left, quota exceeded, file too large."""


class OutputError(BaseplaceError):
    """An output does not fit: the disk or the quota is full, or the file is too large (CLI exit 2).

    The previous file under the output's name is untouched and no temporary file is left.
    """

    exit_code = 2

    def __init__(self, message: str, reason: str) -> None:
        super().__init__(message)
        self.reason = reason
        """Why, without the file's name: ``No space left on device (ENOSPC)``."""


class CacheSkipped(UserWarning):
    """A cache entry was not stored (its disk is full); the result it would have cached is unaffected."""


MAP_FILE = "map file"
"""What :func:`existing_file` calls a reachability map (``reachability.storage.load_map``)."""
SURFACE_MAP_FILE = "surface map"
"""... and a surface map (``placement.surface_storage.load_surface_map``)."""


def existing_file(path: str | Path, what: str) -> Path:
    """``path``, checked to be a file before ``what`` (e.g. "map file") is read from it.

    Front ends call it before the reader's imports, so that a mistyped name is refused at once.

    Raises:
        InputError: ``{what} {path} does not exist``.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{what} {path} does not exist")
    return path


def is_disk_full(exc: BaseException) -> bool:
    """Whether ``exc`` is a write that ran out of space, quota or file size (:data:`DISK_FULL`)."""
    return isinstance(exc, OSError) and exc.errno in DISK_FULL


def disk_full_reason(exc: OSError) -> str:
    """``No space left on device (ENOSPC)``: one line, whatever the library put in the message."""
    code = exc.errno if exc.errno is not None else 0
    return f"{os.strerror(code)} ({errno.errorcode.get(code, code)})"


def full_disk_error(path: str | Path, what: str, exc: OSError, existed: bool) -> OutputError:
    """The :class:`OutputError` of writing ``what`` to ``path`` when ``exc`` (:func:`is_disk_full`) stopped it."""
    return _full(Path(path), what, disk_full_reason(exc), existed)


@contextlib.contextmanager
def staged_directory(path: str | Path, what: str = "file") -> Iterator[Path]:
    """A fresh temporary directory beside ``path`` for writers that make their own files, removed after.

    Move the finished output into place from it (``os.replace``: same file system). A full disk
    while the block runs is an :class:`OutputError`.

    Raises:
        InputError: the directory of ``path`` does not exist.
        OutputError: the disk is full.
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"cannot write {what} {path}: directory {directory} does not exist")
    existed = path.exists()
    staged: Path | None = None
    try:
        staged = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory))
        yield staged
    except OSError as exc:
        if is_disk_full(exc):
            raise full_disk_error(path, what, exc, existed) from None
        raise
    finally:
        if staged is not None:
            shutil.rmtree(staged, ignore_errors=True)


def _full(path: Path, what: str, reason: str, existed: bool) -> OutputError:
    kept = f"the previous {path.name} is unchanged" if existed else "nothing was written"
    return OutputError(
        f"cannot write {what} {path}: {reason}; {kept}; free some space or write elsewhere", reason
    )


def cache_root() -> Path:
    """The per-user cache: ``$BASEPLACE_CACHE`` or ``~/.cache/baseplace``.

    It holds the generated FK kernels (``kernels/``), the default reachability maps (``maps/``),
    the segmented terrains (``terrain/``) and arrays derived from the robots' geometry
    (``fields/``, :mod:`baseplace.world.array_cache`); create its folders with :func:`private_dir`.
    """
    return Path(
        os.environ.get("BASEPLACE_CACHE") or os.path.join(os.path.expanduser("~"), ".cache", "baseplace")
    )


def private_dir(directory: Path) -> Path:
    """Create ``directory`` (mode 0700) if needed; refuse one that others could write into.

    For the per-user cache's folders (:func:`cache_root`). Whoever can write the kernel cache can
    run code in every build (numba's cache holds compiled code), so it must belong to this user and
    be writable by nobody else.

    Raises:
        InputError: the directory cannot be created or belongs to another user.
        OutputError: no room on its disk for the directory.
    """
    try:
        directory.mkdir(mode=0o700, parents=True, exist_ok=True)
        st = directory.stat()
    except OSError as exc:
        if is_disk_full(exc):
            reason = disk_full_reason(exc)
            raise OutputError(f"cannot create cache directory {directory}: {reason}", reason) from None
        raise InputError(f"cannot create cache directory {directory}: {exc.strerror}") from None
    if st.st_uid != os.getuid():
        raise InputError(
            f"cache directory {directory} belongs to another user; "
            "set BASEPLACE_CACHE to a directory of your own"
        )
    if st.st_mode & 0o022:
        os.chmod(directory, 0o700)  # ours, but others could write into it: close it first
    return directory


def skip_cache_entry(what: str, directory: str | Path, exc: BaseException) -> None:
    """Warn in one line that a cache entry was not stored in ``directory`` because of ``exc``.

    For the caches (maps, segmentations, kernels): a full disk there costs the next run the
    work, never this run its result.
    """
    if isinstance(exc, OutputError):
        reason = exc.reason
    elif isinstance(exc, OSError):
        reason = disk_full_reason(exc) if is_disk_full(exc) else exc.strerror or str(exc)
    else:
        reason = str(exc)
    warnings.warn(f"{what} not cached in {directory}: {reason}; the result is not affected", CacheSkipped,
                  stacklevel=2)  # fmt: skip


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
        OutputError: the temporary file cannot be created, or the disk, the quota or the file
            size limit is reached while writing (:data:`DISK_FULL`); ``path`` is left as it was.
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(f"cannot write {what} {path}: directory {directory} does not exist")
    existed = path.exists()
    try:
        fd, name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        reason = disk_full_reason(exc) if is_disk_full(exc) else exc.strerror or str(exc)
        raise _full(path, what, reason, existed) from None
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        os.chmod(tmp, 0o666 & ~_umask())
        _fsync(tmp)  # the bytes are on disk before the name points at them
        os.replace(tmp, path)
        _fsync(directory)  # and the rename is on disk before the caller deletes anything
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        if is_disk_full(exc):
            raise _full(path, what, disk_full_reason(exc), existed) from None
        raise
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def check_free_space(path: str | Path, n_bytes: int, what: str = "file") -> None:
    """Refuse, before writing, a file of ``n_bytes`` that the disk under ``path`` cannot hold.

    A quota is not visible here: :func:`atomic_write` still turns a write that fails into an
    :class:`OutputError`.

    Raises:
        OutputError: the file system has less than ``n_bytes`` free (for this user: root may
            use the blocks reserved for it).
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    try:
        st = os.statvfs(directory)
    except OSError:
        return  # no answer: the write itself will tell
    free = (st.f_bfree if os.geteuid() == 0 else st.f_bavail) * st.f_frsize
    if n_bytes > free:
        reason = f"it needs {_size(n_bytes)} and {directory} has {_size(free)} free"
        raise _full(path, what, reason, path.exists())


def _size(n: int) -> str:
    return f"{n / 1e6:.1f} MB" if n >= 1_000_000 else f"{n / 1e3:.1f} kB"


def write_bytes(path: str | Path, data: bytes | memoryview, what: str = "file") -> None:
    """Write ``data`` to ``path`` atomically, refused first if the disk cannot hold it.

    Raises:
        OutputError: as :func:`check_free_space` and :func:`atomic_write`.
    """
    view = memoryview(data)
    check_free_space(path, view.nbytes, what)
    with atomic_write(path, what) as tmp, open(tmp, "wb") as f:
        f.write(view)


@contextlib.contextmanager
def atomic_hdf5(path: str | Path, what: str = "file") -> Iterator[h5py.File]:
    """An HDF5 file open for writing, built in memory and written to ``path`` atomically when the block ends.

    The image costs memory as large as the file; in return HDF5 never meets a full disk (which
    it survives badly), the size is known before a byte is written, and a file that cannot fit
    is refused (:func:`write_bytes`). An exception in the block writes nothing.

    Raises:
        OutputError: as :func:`write_bytes`.
    """
    import h5py

    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        yield f
    with buffer.getbuffer() as image:
        write_bytes(path, image, what)


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
