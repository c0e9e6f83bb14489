"""What a recording may make the bag reader allocate before a message is decoded.

``rosbags`` inflates a compressed chunk whole (ROS 1 bz2/lz4, MCAP lz4/zstd) and its MCAP reader
holds every chunk whose time range covers the message being read. A 6 kB chunk can inflate to
gigabytes, so the size each chunk declares (ROS 1 chunk headers carry ``size``, MCAP chunk
indexes ``uncompressed_size``) is checked against the memory cap before it is read, and the
chunk is inflated by a decompressor that stops at that size, so the declaration cannot lie.
A rosbag2 directory compressed per message has no declared sizes: each message is inflated up to
the memory cap; one compressed per file is inflated into a temporary folder, up to its free space.
"""

from __future__ import annotations

import bz2
import shutil
import struct
import tempfile
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any

from baseplace.errors import InputError
from baseplace.guards import check_alloc, memory_cap_bytes

TF_MESSAGE_BYTES_PER_TRANSFORM = 1000
"""Memory one transform of a tf2_msgs/TFMessage takes once ``rosbags`` decodes it (about 925 bytes)."""


def _codec(name: str) -> Callable[[], Any] | None:
    """The incremental decompressor of ``name`` (each has ``decompress(data, max_length)``, ``eof``, ``unused_data``)."""
    if name == "bz2":
        return bz2.BZ2Decompressor
    if name == "lz4":
        import lz4.frame

        return lz4.frame.LZ4FrameDecompressor
    if name == "zstd":
        return _zstd_module().ZstdDecompressor
    return None


def inflate(data: bytes, codec: str, size: int, what: str = "chunk", declared: bool = True) -> bytes:
    """``data`` decompressed by ``codec`` (bz2, lz4 or zstd frames), refused past ``size`` bytes.

    Args:
        data: the compressed bytes: one frame or stream after another.
        codec: ``bz2``, ``lz4`` or ``zstd``.
        size: the most bytes it may inflate to.
        what: what is inflated, for the messages ("chunk", "message").
        declared: ``size`` is what the recording declares (beyond it the file is corrupt); else the
            memory cap, for data that declares no size.

    Raises:
        InputError: ``size`` is over the memory cap, or the data inflates beyond ``size``.
    """
    check_alloc(
        size, f"a decompressed {codec} {what}" if what != "chunk" else "a decompressed chunk", "the recording"
    )
    make = _codec(codec)
    if make is None:
        raise InputError(f"the recording: unknown chunk compression {codec!r}; valid: bz2, lz4, zstd")
    parts: list[bytes] = []
    total, rest = 0, data
    while rest:  # one frame or stream after another, as the one-shot decompressors read them
        d = make()
        part = d.decompress(rest, max_length=size + 1 - total)
        total += len(part)
        parts.append(part)
        if total > size:
            raise InputError(
                f"the recording: a {codec} {what} inflates beyond the {size} bytes its header declares; "
                "the file is corrupt"
                if declared
                else f"a {codec} {what} of the recording inflates over the limit of {size / 1e6:.0f} MB "
                "(raise BASEPLACE_MAX_MEMORY_MB to allow it)"
            )
        if not d.eof:
            break  # truncated: the reader's own checks name it
        rest = d.unused_data
    return parts[0] if len(parts) == 1 else b"".join(parts)


def bound_mcap_decompression() -> None:
    """Make ``rosbags``' MCAP reader inflate each chunk through :func:`inflate` (checked, bounded).

    Its decompressors receive the size the chunk declares and must return exactly that many bytes
    (the reader checks), so the bounded ones change nothing for a valid file.
    """
    from rosbags.rosbag2 import storage_mcap

    for name in ("lz4", "zstd"):
        storage_mcap.DECOMPRESSORS[name] = partial(_inflate_mcap, codec=name)


def _inflate_mcap(data: bytes, size: int, codec: str) -> bytes:
    return inflate(data, codec, size)


TEMPORARY_RESERVE = 1 << 30
"""Bytes of the temporary folder a file-compressed recording must leave free."""


def temporary_space() -> int:
    """Bytes a file-compressed recording may inflate to in the temporary folder (its free space less a reserve)."""
    return max(0, shutil.disk_usage(tempfile.gettempdir()).free - TEMPORARY_RESERVE)


class _BoundedZstdStream:
    """A zstd stream read as ``shutil.copyfileobj`` reads it, refused past ``limit`` bytes out."""

    def __init__(self, stream: Any, limit: int) -> None:
        self._stream, self._limit, self._total = stream, limit, 0

    def read(self, size: int = -1) -> bytes:
        part: bytes = self._stream.read(self._limit + 1 - self._total if size < 0 else size)
        self._total += len(part)
        if self._total > self._limit:
            raise InputError(
                f"a zstd file of the recording inflates beyond the {self._limit} bytes free in the temporary "
                f"folder {tempfile.gettempdir()} (less {TEMPORARY_RESERVE >> 20} MB kept free)"
            )
        return part

    def __enter__(self) -> _BoundedZstdStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stream.close()


class _BoundedZstd:
    """The two calls of the ``zstd`` module that ``rosbags``' rosbag2 reader makes, bounded."""

    @staticmethod
    def decompress(data: bytes) -> bytes:
        """Inflated as :func:`inflate` does: at the size the first frame declares, else up to the cap."""
        zstd = _zstd_module()
        try:
            declared = zstd.get_frame_info(data).decompressed_size
        except zstd.ZstdError:
            raise InputError(
                "a zstd message of the recording is not a zstd frame; the file is corrupt"
            ) from None
        if declared is not None and len(data) == zstd.get_frame_size(data):  # one frame that says its size
            return inflate(data, "zstd", declared, "message")
        return inflate(data, "zstd", memory_cap_bytes(), "message", declared=False)

    @staticmethod
    def open(file: Any, mode: str = "rb") -> _BoundedZstdStream:
        zstd = _zstd_module()
        return _BoundedZstdStream(zstd.open(file, mode), temporary_space())


def _zstd_module() -> Any:
    try:
        from compression import zstd
    except ImportError:
        from backports import zstd
    return zstd


def bound_rosbag2_decompression() -> None:
    """Make ``rosbags``' rosbag2 reader inflate zstd messages and files through bounded decompressors."""
    from rosbags.rosbag2 import reader

    reader.zstd = _BoundedZstd  # type: ignore[assignment]


def check_chunks(reader: Any, path: Path) -> None:
    """Check the decompressed size of every chunk of an opened ``AnyReader`` before any is read.

    ROS 1: each chunk's declared ``size`` against the cap, and its decompressor replaced by one
    bounded by that size. MCAP: the most bytes of chunks whose time ranges overlap (the reader
    inflates them all at once) against the cap.

    Raises:
        InputError: a chunk, or overlapping chunks together, over the memory cap.
    """
    from rosbags.rosbag1 import Reader as Reader1
    from rosbags.rosbag1.reader import Header, RecordType
    from rosbags.rosbag2.storage_mcap import McapReader

    for sub in reader.readers:
        if isinstance(sub, Reader1):
            bio = sub.bio
            assert bio is not None  # open
            for pos, chunk in list(sub.chunks.items()):
                bio.seek(pos)
                header = Header.read(bio, RecordType.CHUNK)
                codec, size = header.get_string("compression"), header.get_uint32("size")
                if codec != "none":
                    check_alloc(size, "a decompressed chunk", f"bag {path}")
                    sub.chunks[pos] = chunk._replace(decompressor=partial(inflate, codec=codec, size=size))
            continue
        # a rosbag2 directory's reader holds one storage per file
        for storage in getattr(sub.storage, "storages", [sub.storage]):
            if isinstance(storage, McapReader):
                events = sorted(
                    [(c.message_start_time, 0, c.uncompressed_size) for c in storage.chunks]
                    + [(c.message_end_time, 1, -c.uncompressed_size) for c in storage.chunks]
                )
                held = most = 0
                for _, _, change in events:
                    held += change
                    most = max(most, held)
                check_alloc(most, "decompressed chunks read at once", f"bag {path}")


def tf_message_count(raw: bytes, ros2: bool) -> int:
    """The number of transforms a serialized tf2_msgs/TFMessage declares, read before decoding it.

    ROS 1: a little-endian uint32 first; ROS 2 (CDR): after the 4-byte encapsulation header, in
    the byte order its second byte names.
    """
    if ros2:
        if len(raw) < 8:
            return 0
        return int(struct.unpack_from("<I" if raw[1] & 1 else ">I", raw, 4)[0])
    return int(struct.unpack_from("<I", raw, 0)[0]) if len(raw) >= 4 else 0


def check_tf_message(raw: bytes, ros2: bool, recorded: int, max_transforms: int, where: str) -> int:
    """The number of transforms of a TFMessage, refused before ``rosbags`` decodes it if too many.

    Raises:
        InputError: the ``recorded`` transforms and this message's exceed ``max_transforms``, or
            decoding it would exceed the memory cap.
    """
    n = tf_message_count(raw, ros2)
    if recorded + n > max_transforms:
        raise InputError(
            f"{where}: more than {max_transforms} transforms on /tf and /tf_static; the limit is {max_transforms}"
        )
    if n > 1000:  # a robot's tree, a few hundred transforms, decodes to under a megabyte
        check_alloc(n * TF_MESSAGE_BYTES_PER_TRANSFORM, f"a tf message of {n} transforms", where)
    return n
