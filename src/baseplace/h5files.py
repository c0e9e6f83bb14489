"""The HDF5 conventions shared by baseplace's files: maps, surface maps and build checkpoints.

No file of ours holds a variable-length string, and no loader reads one. HDF5 keeps those in its
global heap, and HDF5 2.0 never returns, holding the GIL, from reading one whose heap collection
is corrupt: a single flipped byte hangs the process (found by fuzzing, tests/test_fuzz.py). So the
JSON texts are uint8 datasets, whose bytes go into the file's SHA-256 with the arrays, and the
short attributes (format name, checksum) are fixed-length ASCII. Files of format version 1 kept
their texts in variable-length string attributes; they are refused with a request to rebuild.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

import h5py
import numpy as np

from baseplace.errors import InputError
from baseplace.guards import check_alloc

CORRUPT_FILE_ERRORS = (
    OSError,
    KeyError,
    ValueError,
    TypeError,
    IndexError,
    AttributeError,
    RecursionError,
    MemoryError,
    RuntimeError,  # h5py raises it for some damaged link tables
)
"""What reading a damaged HDF5 file can raise; loaders turn these into one InputError."""

MAX_TEXT = 16 * 2**20  # bytes: far beyond any header, small enough to read without care


def digest(*parts: np.ndarray | bytes) -> str:
    """SHA-256 (hex) over the raw bytes of ``parts`` in order."""
    h = hashlib.sha256()
    for part in parts:
        h.update(part if isinstance(part, bytes) else np.ascontiguousarray(part).tobytes())
    return h.hexdigest()


def write_header(f: h5py.File, fmt: str, version: int) -> None:
    """Set the ``format`` (fixed-length ASCII) and ``format_version`` attributes."""
    f.attrs["format"] = short_text(fmt)
    f.attrs["format_version"] = version


def read_header(f: h5py.File, path: Path, fmt: str, version: int, what: str, remedy: str) -> None:
    """Raise InputError unless ``f`` is a ``fmt`` file of format ``version``.

    Args:
        f: the open file.
        path: its path, for messages.
        fmt: the expected ``format`` attribute.
        version: the format version this baseplace writes and reads.
        what: the kind of file, for messages ("reachability map").
        remedy: what to do with a file of an older format ("rebuild it with build-map").
    """
    check_self_contained(f, path)
    stored = f.attrs.get("format_version")
    if attr_text(f.attrs, "format") != fmt:
        if stored == 1 and _is_variable_string(f.attrs, "format"):
            raise InputError(f"{path} is a {what} of format version 1, from an older baseplace; {remedy}")
        raise InputError(f"{path} is not a baseplace {what}")
    stored = int(stored)
    if stored > version:
        raise InputError(
            f"{path} has {what} format version {stored}, newer than this baseplace reads ({version}); "
            "upgrade baseplace"
        )
    if stored < version:
        raise InputError(f"{path} is a {what} of format version {stored}, from an older baseplace; {remedy}")


DEFLATE_MAX_RATIO = 1100.0
"""Most bytes one byte of gzip (deflate) data can expand to (1032:1, with room for chunk headers)."""


def read_array(f: h5py.File, name: str, path: Path) -> np.ndarray:
    """Read the numeric dataset ``name``, its declared size checked before anything is allocated.

    A dataset's shape is only declared: HDF5 returns the fill value for chunks never written, so
    a file of a few kB can declare terabytes. The size must fit what the file's bytes can hold
    (raw, or gzip at its maximum ratio) and the memory cap (:func:`baseplace.guards.check_alloc`).

    Raises:
        KeyError: no such dataset.
        ValueError: not a numeric dataset.
        InputError: the declared size is beyond the file or the cap.
    """
    data = _local_dataset(f, name, path)
    if not (data.dtype.kind in "iuf" and data.dtype.itemsize <= 8):
        raise ValueError(f"{name} is not a numeric dataset")
    ratio = DEFLATE_MAX_RATIO if data.compression is not None else 1.0
    n_bytes = float(np.prod(data.shape, dtype=float)) * data.dtype.itemsize
    check_alloc(n_bytes, f"dataset {name!r}", path, path.stat().st_size, ratio)
    return np.asarray(data[()])


MAX_LINKS = 1000
"""Most links a file of ours may hold (a terrain cache entry, the largest, has about 30)."""


def check_self_contained(f: h5py.File, path: Path) -> None:
    """Raise InputError unless every object of ``f`` lives inside the file.

    Soft and external links, datasets stored in external files (an HDF5 external file list) and
    virtual datasets are refused: HDF5 would open the files they name (another HDF5 file, any
    path, a FIFO that blocks) when the object is read. Only link and creation-property metadata
    is read here; no data, and no link is followed.
    """
    found: list[tuple[str, str]] = []

    def visit(name: str, link: h5py.HardLink | h5py.SoftLink | h5py.ExternalLink) -> bool | None:
        found.append((name, "" if isinstance(link, h5py.HardLink) else type(link).__name__))
        return len(found) > MAX_LINKS or None  # a true value stops the walk

    f.visititems_links(visit)
    if len(found) > MAX_LINKS:
        raise InputError(f"{path} holds more than {MAX_LINKS} HDF5 objects; baseplace files hold a few dozen")
    for name, kind in found:
        if kind:
            raise InputError(
                f"{path}: {name!r} is an HDF5 {kind}; baseplace reads no links (the file is not ours)"
            )
        _check_storage(f[name], name, path)


def _local_dataset(f: h5py.File, name: str, path: Path) -> h5py.Dataset:
    """The dataset ``name`` reached by a hard link, its data stored inside the file."""
    link = f.get(name, getlink=True)
    if link is None:
        raise KeyError(name)
    if not isinstance(link, h5py.HardLink):
        raise InputError(f"{path}: {name!r} is an HDF5 {type(link).__name__}; baseplace reads no links")
    data = f[name]
    if not isinstance(data, h5py.Dataset):
        raise ValueError(f"{name} is not a dataset")
    _check_storage(data, name, path)
    return data


def _check_storage(obj: h5py.Dataset | h5py.Group | h5py.Datatype, name: str, path: Path) -> None:
    if not isinstance(obj, h5py.Dataset):
        return
    dcpl = obj.id.get_create_plist()
    if dcpl.get_layout() == h5py.h5d.VIRTUAL:
        raise InputError(f"{path}: dataset {name!r} is virtual (its data lies in other files); refused")
    if dcpl.get_external_count():
        raise InputError(
            f"{path}: dataset {name!r} keeps its data in external files (HDF5 external storage); refused"
        )


def write_text(f: h5py.File, name: str, text: str) -> bytes:
    """Store ``text`` (UTF-8) as the uint8 dataset ``name``; returns its bytes for the digest."""
    data = text.encode()
    f.create_dataset(name, data=np.frombuffer(data, dtype=np.uint8))
    return data


def read_text(f: h5py.File, name: str) -> bytes:
    """The bytes of the text ``name``.

    Raises:
        KeyError: no such text.
        ValueError: ``name`` is not a 1-D uint8 dataset of at most :data:`MAX_TEXT` bytes.
    """
    data = _local_dataset(f, name, Path(f.filename))
    if not (data.dtype == np.uint8 and data.ndim == 1):
        raise ValueError(f"{name} is not a text")
    if data.shape[0] > MAX_TEXT:
        raise ValueError(f"{name} is too long")
    return bytes(data[()].tobytes())


def short_text(text: str) -> np.bytes_:
    """A short ASCII attribute value (format name, checksum), stored inline at a fixed length."""
    return np.bytes_(text.encode("ascii"))


def attr_text(attrs: h5py.AttributeManager, name: str) -> str | None:
    """The fixed-length string attribute ``name`` as text; None if absent or of another type.

    A variable-length string is never read (see the module docstring).
    """
    if name not in attrs:
        return None
    dtype = attrs.get_id(name).dtype
    if dtype.kind != "S":
        return None
    value = attrs[name]
    return value.decode("ascii", errors="replace") if isinstance(value, bytes) else None


def _is_variable_string(attrs: h5py.AttributeManager, name: str) -> bool:
    if name not in attrs:
        return False
    info = h5py.check_string_dtype(attrs.get_id(name).dtype)
    return info is not None and info.length is None
