"""Point clouds in and out: PCD, PLY, NPY, OctoMap ``.bt`` and XYZ text.

A :class:`Cloud` holds finite points only; loaders drop NaN/inf rows (organized sensors mark
missing depth that way) and raise :class:`~baseplace.errors.InputError` with one line for every
problem a user can cause: an unknown suffix, a missing, truncated or corrupt file, or a cloud with
no finite point left. Writes are atomic (temporary file in the target directory, then
``os.replace``). :func:`load_transform` parses the sensor-to-world transform given next to a cloud.
"""

from __future__ import annotations

import dataclasses
import io
import itertools
import re
import struct
import warnings
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, BinaryIO, TextIO

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError, brief, choices
from baseplace.files import atomic_write
from baseplace.guards import check_alloc, check_input_file

FloatArray = NDArray[np.float64]
ColorArray = NDArray[np.uint8]

MAX_OCTOMAP_POINTS = 20_000_000
"""Most finest-resolution voxel centres a ``.bt`` file may expand to (about 0.5 GB of points)."""

_ORTHONORMAL_TOL = 1e-6
_BT_HEADER = b"# Octomap OcTree binary file"


@dataclass(frozen=True, eq=False)
class Cloud:
    """Points in some frame (the sensor's, or the world's after :meth:`transformed`).

    Attributes:
        points: (N, 3) float64 [m], finite only (loaders drop NaN/inf rows).
        colors: (N, 3) uint8 RGB per point, or None.
        source: where the points came from (a path), for messages.
        width: columns of the organized layout of the original file (before dropping non-finite
            rows), or None when the file was not organized.
        height: rows of that layout, or None.
    """

    points: FloatArray
    colors: ColorArray | None = None
    source: str = ""
    width: int | None = None
    height: int | None = None

    def __post_init__(self) -> None:
        points = np.asarray(self.points, dtype=np.float64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise InputError(f"cloud points must have shape (N, 3), got {points.shape}")
        if not np.isfinite(points).all():
            raise InputError("cloud points must be finite; drop NaN/inf rows first (load_cloud does)")
        object.__setattr__(self, "points", points)
        if self.colors is not None:
            colors = np.asarray(self.colors)
            if colors.shape != points.shape or colors.dtype != np.uint8:
                raise InputError(
                    f"cloud colors must be uint8 of shape {points.shape}, got {colors.dtype} {colors.shape}"
                )
            object.__setattr__(self, "colors", colors)

    def __len__(self) -> int:
        return len(self.points)

    def __array__(self, dtype: Any = None, copy: bool | None = None) -> FloatArray:
        """The (N, 3) points, so that every function taking points (ArrayLike) takes a Cloud too."""
        points = self.points if dtype is None else self.points.astype(dtype, copy=False)
        return points.copy() if copy else points

    def transformed(self, T_world_sensor: ArrayLike) -> Cloud:
        """The same cloud in the world frame: ``p_world = T_world_sensor @ p_sensor``.

        Args:
            T_world_sensor: (4, 4) homogeneous transform with last row ``0 0 0 1``.

        Returns:
            A new cloud with transformed points; colors, source and layout are kept.
        """
        T = np.asarray(T_world_sensor, dtype=np.float64)
        if T.shape != (4, 4) or not np.isfinite(T).all():
            raise InputError(f"T_world_sensor must be a finite (4, 4) matrix, got shape {T.shape}")
        if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=_ORTHONORMAL_TOL):
            raise InputError(f"T_world_sensor must have last row 0 0 0 1, got {_fmt(T[3])}")
        return dataclasses.replace(self, points=self.points @ T[:3, :3].T + T[:3, 3])


def load_cloud(path: str | Path) -> Cloud:
    """Read a point cloud, keeping its finite points.

    Formats by suffix: ``.pcd`` (ascii, binary, binary_compressed; colors from ``rgb``/``rgba``
    packed fields or ``r g b``), ``.ply`` (vertex ``x y z``, colors from ``red green blue``),
    ``.npy`` (numeric (N, >=3) array, first 3 columns), ``.bt`` (OctoMap: centres of occupied
    voxels at the finest resolution; a pruned leaf is expanded into all its finest sub-voxels so
    the density is uniform), ``.xyz``/``.txt`` (whitespace or comma separated text, first 3
    columns, ``#`` comments).

    Args:
        path: the file.

    Returns:
        The cloud in the file's frame, ``source`` set to ``path``.

    Raises:
        InputError: unknown suffix, missing, truncated or corrupt file, or no finite point.
    """
    path = check_input_file(path, "cloud", _READERS)
    reader = _READERS[path.suffix.lower()]
    try:
        _check_declared_size(path)  # before the format library allocates what the header declares
        points, colors, layout = reader(path)
    except InputError:
        raise
    except Exception as exc:  # the format libraries raise anything from ValueError to TypeError
        raise InputError(f"cannot read cloud {path}: truncated or corrupt file ({_brief(exc)})") from None
    keep = np.isfinite(points).all(axis=1)
    if not keep.any():
        raise InputError(f"cloud {path} has no finite points ({len(points)} points, all NaN/inf or none)")
    width, height = layout if layout is not None else (None, None)
    return Cloud(
        np.ascontiguousarray(points[keep]),
        None if colors is None else np.ascontiguousarray(colors[keep]),
        str(path),
        width,
        height,
    )


def save_cloud(cloud: Cloud, path: str | Path) -> None:
    """Write ``cloud`` atomically; nothing is left behind on failure.

    Formats by suffix: ``.ply`` (binary little endian, float64 ``x y z``, uchar
    ``red green blue`` when the cloud has colors), ``.pcd`` (binary, float32 ``x y z`` and a packed
    float ``rgb`` as PCL writes it), ``.npy`` ((N, 3) float64 points; colors are not stored).

    Raises:
        InputError: unknown suffix or missing directory.
    """
    path = Path(path)
    writer = _WRITERS.get(path.suffix.lower())
    if writer is None:
        raise InputError(
            f"cannot write cloud {path}: unknown suffix {path.suffix!r}; valid: {choices(_WRITERS)}"
        )
    with atomic_write(path, "cloud") as tmp, tmp.open("wb") as f:
        writer(cloud, f)


def load_transform(spec: str) -> FloatArray:
    """Parse a sensor-to-world transform given as a file or as an up vector.

    Args:
        spec: a path to a text file holding ``T_world_sensor`` (16 numbers row by row, whitespace
            or comma separated, ``#`` comments), or ``"ux uy uz"``: the sensor-frame direction
            that points up in the world (see :func:`up_vector_transform`).

    Returns:
        ``T_world_sensor``, shape (4, 4).

    Raises:
        InputError: a missing file, not 16 numbers, a block that is not a proper rotation
            (orthonormal within 1e-6, det +1), a last row other than ``0 0 0 1``, or a bad up
            vector.
    """
    try:
        path = Path(spec.strip()).expanduser()
        is_file = path.is_file()
    except (OSError, RuntimeError, ValueError):  # a name too long for a path, "~user" of no user, NUL
        is_file = False
    if is_file:
        return _read_transform_file(path)
    numbers = _floats(spec.replace(",", " ").split())
    if numbers is None:
        raise InputError(
            f"transform {brief(spec)} is neither an existing file nor an up vector; give a path to a "
            "4x4 matrix file (T_world_sensor) or 3 numbers 'ux uy uz'"
        )
    if len(numbers) != 3:
        raise InputError(
            f"an up vector needs 3 numbers 'ux uy uz', got {len(numbers)} in {brief(spec)} "
            "(a 4x4 matrix goes in a file)"
        )
    return up_vector_transform(numbers)


def up_vector_transform(up: ArrayLike) -> FloatArray:
    """The minimal rotation that maps the sensor-frame ``up`` onto world +z.

    Args:
        up: (3,) direction in the sensor frame that points up in the world; any non-zero length.
            ``0 0 -1`` gives a 180 deg rotation about x.

    Returns:
        ``T_world_sensor``, (4, 4), rotation only (zero translation).
    """
    try:
        u = np.asarray(up, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"an up vector needs 3 numbers 'ux uy uz', got {up!r}") from None
    if u.shape != (3,):
        raise InputError(f"an up vector needs 3 numbers 'ux uy uz', got shape {u.shape}")
    if not np.isfinite(u).all():
        raise InputError(f"the up vector must be finite, got {_fmt(u)}")
    scale = float(np.abs(u).max())
    if scale == 0.0:
        raise InputError("the up vector must be non-zero, got 0 0 0")
    u = u / scale  # no overflow or underflow in the norm for any finite magnitude
    ux, uy, uz = u / np.linalg.norm(u)
    sin = float(np.hypot(ux, uy))  # |u x z|
    if sin == 0.0:
        R = np.eye(3) if uz > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        # Rodrigues about the unit axis u x z with sin = |u x z|, cos = u . z; stable near -z too.
        K = np.array([[0.0, 0.0, -ux], [0.0, 0.0, -uy], [ux, uy, 0.0]]) / sin
        R = np.eye(3) + sin * K + (1.0 - uz) * (K @ K)
    T = np.eye(4)
    T[:3, :3] = R
    return T


# --- readers: path -> (points (N, 3) float64 possibly non-finite, colors or None, (width, height)) ---

_Layout = tuple[int, int] | None
_Raw = tuple[FloatArray, ColorArray | None, _Layout]


def _read_pcd(path: Path) -> _Raw:
    from pypcd4 import PointCloud

    pc = PointCloud.from_path(path)
    meta = pc.metadata
    data = np.atleast_1d(pc.pc_data)
    if len(data) != meta.points or meta.width * meta.height != meta.points:
        raise InputError(
            f"cannot read cloud {path}: header says {meta.points} points "
            f"({meta.width} x {meta.height}), data holds {len(data)}; the file is truncated or corrupt"
        )
    names = data.dtype.names or ()
    missing = [f for f in "xyz" if f not in names]
    if missing:
        raise InputError(f"PCD {path} has no field {', '.join(missing)}; fields: {', '.join(meta.fields)}")
    points = np.column_stack([data[f].astype(np.float64) for f in "xyz"])
    layout = (meta.width, meta.height) if meta.height > 1 else None
    return points, _pcd_colors(data, names), layout


def _pcd_colors(data: np.ndarray, names: tuple[str, ...]) -> ColorArray | None:
    for name in ("rgb", "rgba"):
        if name in names:
            column = np.ascontiguousarray(data[name])
            if column.dtype == np.float32:  # PCL packs 0x00RRGGBB into the bits of a float
                packed = column.view(np.uint32)
            elif column.dtype.kind in "iu":
                packed = column.astype(np.uint32)
            else:
                return None
            shifts = np.array([16, 8, 0], dtype=np.uint32)
            return ((packed[:, None] >> shifts) & 0xFF).astype(np.uint8)
    if all(c in names for c in "rgb"):
        return _to_uint8(np.column_stack([data[c] for c in "rgb"]))
    return None


def _read_ply(path: Path) -> _Raw:
    # Only the vertex element is read, by numpy from the header's layout: plyfile reads every
    # element, a Python object per list row (8 MB of empty faces cost it 1.2 GB).
    fmt, elements, offset = _ply_header(path)
    names = [name for name, _, _ in elements]
    if "vertex" not in names:
        raise InputError(f"PLY {path} has no 'vertex' element; elements: {', '.join(names) or 'none'}")
    before = elements[: names.index("vertex")]
    _, count, properties = elements[len(before)]
    lists = [name for name, kind in properties if not isinstance(kind, str)]
    if lists:
        raise InputError(
            f"PLY {path} vertices have list properties ({', '.join(lists)}); only scalars are read"
        )
    order = {"binary_little_endian": "<", "binary_big_endian": ">"}.get(fmt, "=")
    dtype = np.dtype([(name, order + kind) for name, kind in properties if isinstance(kind, str)])
    fields = dtype.names or ()
    check_alloc(count * float(dtype.itemsize), "vertex data", path, path.stat().st_size - offset,
                _PER_FILE_BYTE["ascii" if fmt == "ascii" else "binary"])  # fmt: skip
    check_alloc(count * (dtype.itemsize + _BYTES_PER_POINT), "points", path)
    with path.open("rb") as f:
        f.seek(offset)
        if fmt == "ascii":
            vertex = _ply_ascii_rows(f, before, dtype, count, path)
        else:
            f.seek(sum(n * _ply_row_bytes(props, path) for _, n, props in before), io.SEEK_CUR)
            vertex = np.fromfile(f, dtype=dtype, count=count)
    if len(vertex) != count:
        raise InputError(
            f"cannot read cloud {path}: header says {count} vertices, data holds {len(vertex)}; "
            "the file is truncated or corrupt"
        )
    missing = [f for f in "xyz" if f not in fields]
    if missing:
        raise InputError(f"PLY {path} vertices have no {', '.join(missing)}; properties: {', '.join(fields)}")
    points = np.column_stack([vertex[f].astype(np.float64) for f in "xyz"])
    rgb = ("red", "green", "blue")
    colors = _to_uint8(np.column_stack([vertex[c] for c in rgb])) if all(c in fields for c in rgb) else None
    return points, colors, None


def _read_npy(path: Path) -> _Raw:
    array = np.load(path, allow_pickle=False)
    if (
        not isinstance(array, np.ndarray)
        or array.ndim != 2
        or array.shape[1] < 3
        or array.dtype.kind not in "fiu"
    ):
        shape = getattr(array, "shape", "?")
        raise InputError(
            f"{path} must hold a numeric (N, 3) or (N, >=3) array of points, got shape {shape} "
            f"dtype {getattr(array, 'dtype', type(array).__name__)}"
        )
    return array[:, :3].astype(np.float64), None, None


def _read_xyz(path: Path) -> _Raw:
    # Read in blocks of lines, the points so far checked against the cap after each block: the
    # text's size says little about the count (a line may hold one point or a comment).
    blocks = []
    n_points = 0
    with path.open("r", encoding="utf-8") as f:
        lines = _text_lines(f, path)
        while block_lines := [line.replace(",", " ") for line in itertools.islice(lines, _TEXT_BLOCK_LINES)]:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore", UserWarning)  # "input contained no data": reported below
                block = np.loadtxt(block_lines, comments="#", usecols=(0, 1, 2), ndmin=2, dtype=np.float64)
            n_points += len(block)
            check_alloc(n_points * _BYTES_PER_POINT, "points", path)
            blocks.append(block)
    return (np.concatenate(blocks) if blocks else np.empty((0, 3))), None, None


def _text_lines(f: TextIO, path: Path) -> Iterator[str]:
    """The lines of a text file, each at most :data:`_MAX_TEXT_LINE` characters."""
    while line := f.readline(_MAX_TEXT_LINE + 1):
        if len(line) > _MAX_TEXT_LINE:
            raise InputError(f"cannot read cloud {path}: a line is longer than {_MAX_TEXT_LINE} characters")
        yield line


def _read_bt(path: Path) -> _Raw:
    import pyoctomap

    resolution = _check_bt(path)
    tree = pyoctomap.OcTree(resolution)
    if not tree.readBinary(str(path)):
        raise InputError(f"cannot read OctoMap {path}: octomap rejected the file")
    max_depth = tree.getTreeDepth()
    centres: list[list[float]] = []
    depths: list[int] = []
    for leaf in tree.begin_leafs():
        node = leaf.current_node
        if node is not None and tree.isNodeOccupied(node):
            centres.append(leaf.getCoordinate())
            depths.append(leaf.getDepth())
    if not centres:
        return np.empty((0, 3)), None, None
    sides = 2 ** (max_depth - np.asarray(depths, dtype=np.int64))
    total = int(np.sum(sides**3))
    if total > MAX_OCTOMAP_POINTS:
        raise InputError(
            f"OctoMap {path} expands to {total} voxels at {resolution} m, more than {MAX_OCTOMAP_POINTS}"
        )
    centre = np.asarray(centres, dtype=np.float64)
    parts = []
    for side in np.unique(sides):
        offsets = (np.indices((side, side, side)).reshape(3, -1).T - (side - 1) / 2.0) * resolution
        parts.append((centre[sides == side][:, None, :] + offsets[None]).reshape(-1, 3))
    # octomap keeps coordinates in float32; snap to the exact voxel centres (k + 1/2) * resolution
    points = (np.floor(np.concatenate(parts) / resolution) + 0.5) * resolution
    return points, None, None


def _check_bt(path: Path) -> float:
    """Validate a ``.bt`` header and node stream; returns the resolution [m].

    octomap prints to stderr and may read garbage on bad input, so the stream is checked first:
    each inner node is two bytes of 2-bit child codes (1 free leaf, 2 occupied leaf, 3 inner,
    0 none) in depth-first order, so a complete stream has one record per inner node and
    ``size`` = 1 + the number of children.
    """
    check_alloc(path.stat().st_size * 6.0, "the OctoMap node stream", path)  # 4 codes per byte below
    blob = path.read_bytes()
    if not blob.startswith(_BT_HEADER):
        raise InputError(
            f"{path} is not an OctoMap binary file (.bt): first line is not {_BT_HEADER.decode()!r}"
        )
    match = re.search(rb"\ndata\n", blob)
    if match is None:
        raise InputError(f"cannot read OctoMap {path}: the header has no 'data' line; truncated or corrupt")
    header = {}
    for line in blob[: match.start()].decode("ascii", "replace").splitlines()[1:]:
        words = line.split()
        if len(words) == 2 and not line.startswith("#"):
            header[words[0]] = words[1]
    if header.get("id") != "OcTree":
        raise InputError(
            f"OctoMap {path} holds a {header.get('id', 'unknown')!r} tree; only 'OcTree' is read"
        )
    size, resolution = int(header["size"]), float(header["res"])
    if not resolution > 0:
        raise InputError(f"OctoMap {path} has resolution {resolution}; it must be positive")
    stream = np.frombuffer(blob, dtype=np.uint8, offset=match.end())
    codes = (stream[:, None] >> np.array([0, 2, 4, 6], dtype=np.uint8)) & 3
    n_records = len(stream) // 2
    n_inner = int(np.count_nonzero(codes == 3))
    n_nodes = 1 + int(np.count_nonzero(codes)) if size else 0
    if len(stream) % 2 or (size and n_records != 1 + n_inner) or n_nodes != size:
        raise InputError(
            f"cannot read OctoMap {path}: header says {size} nodes, the data does not match; "
            "truncated or corrupt"
        )
    _check_bt_nodes(path, codes, n_nodes)
    return resolution


_MAX_HEADER_BYTES = 2**20
"""Most bytes a PCD or PLY header may take, comments included (real headers take under 1 kB)."""
_MAX_PCD_COLUMNS = 10_000
"""Most values per PCD point (sum of COUNT): pypcd4 makes one numpy field per value; PCL's widest
descriptor (ShapeContext1980) has 1989."""
_BYTES_PER_POINT = 72.0
"""Memory per point beyond the file's own data: three float64 coordinates in up to three copies
(the reader's, load_cloud's finite rows, a temporary)."""
# Bytes in memory per byte of file, at most: binary data is stored as it is held; an ASCII value
# takes at least 2 bytes ("0 ") and at most 8 in memory; LZF (PCD binary_compressed) expands at
# most 88:1 (a 3-byte back reference copies 264 bytes).
_PER_FILE_BYTE = {"binary": 1.0, "ascii": 4.0, "binary_compressed": 110.0}
_PLY_TYPES = {"char": "i1", "uchar": "u1", "int8": "i1", "uint8": "u1", "short": "i2", "ushort": "u2",
              "int16": "i2", "uint16": "u2", "int": "i4", "uint": "u4", "int32": "i4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}  # fmt: skip
_TEXT_BLOCK_LINES = 100_000
_MAX_TEXT_LINE = 65536
# a PLY property: (name, numpy type code) or (name, (length code, value code)) for a list
_PlyProperty = tuple[str, "str | tuple[str, str]"]
_PlyElement = tuple[str, int, list[_PlyProperty]]


def _check_declared_size(path: Path) -> None:
    """Refuse a cloud whose header declares more data than its file can hold, or than the cap.

    PCD (``FIELDS``/``SIZE``/``COUNT``/``POINTS``/``DATA`` and binary_compressed's sizes) and
    ``.npy`` headers declare their sizes; pypcd4 and numpy allocate them before reading. A 182-byte
    PCD with ``COUNT 1 1 1000000000`` must fail here, not after 10 GB. PLY, ``.bt`` and text are
    checked by their readers, which allocate nothing before their checks.

    Raises:
        InputError: the declared size does not fit the file or the memory cap (one line).
    """
    suffix = path.suffix.lower()
    if suffix == ".npy":
        _check_npy(path)
    elif suffix == ".pcd":
        _check_pcd(path)


def _check_npy(path: Path) -> None:
    with path.open("rb") as f:
        version = np.lib.format.read_magic(f)
        read = (
            np.lib.format.read_array_header_1_0 if version == (1, 0) else np.lib.format.read_array_header_2_0
        )
        shape, _, dtype = read(f)
    if dtype.hasobject:
        raise InputError(f"{path} holds Python objects ({dtype}); only numeric arrays are read (no pickle)")
    n_bytes = float(np.prod(shape, dtype=float)) * dtype.itemsize
    check_alloc(n_bytes, "the array", path, path.stat().st_size, 1.0)
    check_alloc(n_bytes / max(dtype.itemsize, 1) * 8 + n_bytes, "points", path)


def _check_pcd(path: Path) -> None:
    """Check a PCD header as pypcd4 will read it, before pypcd4 allocates what it declares.

    pypcd4 skips blank and ``#`` lines of any length, takes at most 10 other lines up to the one
    starting with ``DATA``, and parses them with its own :class:`pypcd4.MetaData`; so does this
    check, on a header of at most :data:`_MAX_HEADER_BYTES`. It then allocates one numpy field per
    value (sum of ``COUNT``), ``POINTS`` records of the summed ``SIZE x COUNT``, and for
    binary_compressed the uncompressed size written after the header.
    """
    from pypcd4 import MetaData

    file_bytes = path.stat().st_size
    lines: list[str] = []
    with path.open("rb") as f:
        while len(lines) < 10 and not (lines and lines[-1].startswith("DATA")):
            raw = f.readline(_MAX_HEADER_BYTES + 1 - f.tell())
            if f.tell() > _MAX_HEADER_BYTES:
                raise InputError(
                    f"cannot read cloud {path}: the PCD header is longer than {_MAX_HEADER_BYTES} bytes"
                )
            if not raw:
                break
            line = raw.decode("utf-8").strip()
            if line and not line.startswith("#"):
                lines.append(line)
        offset = f.tell()
        compressed_sizes = f.read(8)
    meta = MetaData.parse_header(lines)
    n = len(meta.fields)
    if min(len(meta.size), len(meta.type), len(meta.count)) < n:
        raise InputError(
            f"cannot read cloud {path}: the PCD header names {n} FIELDS but gives fewer SIZE, TYPE or COUNT"
        )
    if meta.width * meta.height != meta.points:
        raise InputError(
            f"cannot read cloud {path}: the PCD header says {meta.points} POINTS but WIDTH x HEIGHT is "
            f"{meta.width} x {meta.height}; the file is corrupt"
        )
    n_bytes = float(meta.points) * sum(s * c for s, c in zip(meta.size[:n], meta.count[:n], strict=False))
    data = meta.data.value if meta.data.value in ("ascii", "binary") else "binary_compressed"  # as pypcd4
    check_alloc(n_bytes, "point data", path, file_bytes - offset, _PER_FILE_BYTE[data])
    if data == "ascii" and _text_rows_over(path, offset, meta.points):
        raise InputError(  # numpy's loadtxt would read every row, however few the header declares
            f"cannot read cloud {path}: its ASCII data has more rows than the header's {meta.points} POINTS; "
            "the file is corrupt"
        )
    columns = sum(meta.count[:n])
    if columns > _MAX_PCD_COLUMNS:
        raise InputError(  # pypcd4 builds its dtype even for 0 points
            f"cannot read cloud {path}: the PCD header declares {columns} values per point (sum of COUNT); "
            f"the limit is {_MAX_PCD_COLUMNS}"
        )
    if data == "binary_compressed" and meta.points > 0:
        if len(compressed_sizes) < 8:
            raise InputError(
                f"cannot read cloud {path}: the compressed PCD data has no sizes; the file is truncated or corrupt"
            )
        compressed, uncompressed = struct.unpack("II", compressed_sizes)  # pypcd4 reads them so
        if uncompressed != n_bytes:
            raise InputError(
                f"cannot read cloud {path}: the compressed data says {uncompressed} bytes, the header's "
                f"points take {n_bytes:.0f}; the file is truncated or corrupt"
            )
        if compressed > file_bytes - offset - 8:
            raise InputError(
                f"cannot read cloud {path}: the compressed data says {compressed} bytes, the file holds "
                f"{file_bytes - offset - 8}; the file is truncated or corrupt"
            )
        check_alloc(n_bytes, "point data", path, compressed, _PER_FILE_BYTE[data])
    # pypcd4 holds the decompressed buffer, its records and one field's copy at once
    check_alloc(n_bytes * 3.0 + meta.points * _BYTES_PER_POINT, "points", path)


def _text_rows_over(path: Path, offset: int, limit: int) -> bool:
    """True when the text from ``offset`` on has more than ``limit`` rows as numpy's loadtxt counts them.

    Read in 1 MiB blocks: the line ends counted first; only when they exceed ``limit`` are the
    rows counted one by one, skipping blank lines and ``#`` comments as loadtxt does.
    """
    ends, last = 0, b"\n"
    with path.open("rb") as f:
        f.seek(offset)
        while block := f.read(2**20):
            ends += block.count(b"\n")
            last = block[-1:]
        if ends + (last != b"\n") <= limit:
            return False
        f.seek(offset)
        rows = 0
        for line in f:
            if line.split(b"#", 1)[0].strip():
                rows += 1
                if rows > limit:
                    return True
    return False


def _ply_header(path: Path) -> tuple[str, list[_PlyElement], int]:
    """Parse a PLY header of at most :data:`_MAX_HEADER_BYTES`: (format, elements, data offset).

    Lines end in LF, CR or CRLF; ``comment`` and ``obj_info`` lines are skipped.
    """
    with path.open("rb") as f:
        head = f.read(_MAX_HEADER_BYTES)
    end = re.search(rb"(?:^|[\r\n])end_header(?:\r\n|\r|\n)", head)
    if end is None:
        if len(head) == _MAX_HEADER_BYTES:
            raise InputError(
                f"cannot read cloud {path}: the PLY header is longer than {_MAX_HEADER_BYTES} bytes"
            )
        raise InputError(f"cannot read cloud {path}: the PLY header has no end_header; truncated or corrupt")
    lines = head[: end.start()].decode("ascii").splitlines()
    if not lines or lines[0] != "ply":
        raise InputError(f"{path} is not a PLY file: the first line is not 'ply'")
    fmt = ""
    elements: list[_PlyElement] = []
    for line in lines[1:]:
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) == 3 and words[2] == "1.0":
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements and len(words) == 3 and words[1] in _PLY_TYPES:
            elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
        elif (
            words[0] == "property" and elements and len(words) == 5 and words[1] == "list"
            and words[2] in _PLY_TYPES and words[3] in _PLY_TYPES
        ):  # fmt: skip
            elements[-1][2].append((words[4], (_PLY_TYPES[words[2]], _PLY_TYPES[words[3]])))
        else:
            raise InputError(f"cannot read cloud {path}: bad PLY header line {brief(line, 60)}")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise InputError(
            f"cannot read cloud {path}: PLY format {fmt or 'missing'!r}; valid: ascii, "
            "binary_little_endian, binary_big_endian (version 1.0)"
        )
    return fmt, elements, end.end()


def _ply_row_bytes(properties: list[_PlyProperty], path: Path) -> int:
    """Bytes of one binary row of an element before the vertices (lists cannot be skipped unread)."""
    sizes = [np.dtype(kind).itemsize for _, kind in properties if isinstance(kind, str)]
    if len(sizes) < len(properties):
        raise InputError(
            f"cannot read cloud {path}: a PLY element with list properties comes before 'vertex'"
        )
    return sum(sizes)


def _ply_ascii_rows(
    f: BinaryIO, before: list[_PlyElement], dtype: np.dtype, count: int, path: Path
) -> np.ndarray:
    """The vertex rows of an ASCII PLY: one line per row of every element, vertices after ``before``."""
    lines = _text_lines(io.TextIOWrapper(f, encoding="ascii"), path)
    for _ in itertools.islice(lines, sum(n for _, n, _ in before)):
        pass
    with warnings.catch_warnings():  # an empty body is refused by the caller as "no points", not warned about
        warnings.filterwarnings("ignore", "loadtxt: input contained no data", UserWarning)
        return np.loadtxt(itertools.islice(lines, count), dtype=dtype, comments=None, ndmin=1)


def _check_bt_nodes(path: Path, codes: np.ndarray, n_nodes: int) -> None:
    """Refuse a tree whose nodes, as octomap builds them and the leaves are listed, exceed the cap.

    octomap takes about 42 bytes per node; listing an occupied leaf takes about 200 bytes of
    Python objects (both measured, rounded up).
    """
    occupied = int(np.count_nonzero(codes == 2))
    check_alloc(n_nodes * 48.0 + occupied * 256.0, f"the OctoMap's {n_nodes} nodes", path)


_READERS: dict[str, Callable[[Path], _Raw]] = {
    ".pcd": _read_pcd,
    ".ply": _read_ply,
    ".npy": _read_npy,
    ".bt": _read_bt,
    ".xyz": _read_xyz,
    ".txt": _read_xyz,
}
CLOUD_SUFFIXES = tuple(_READERS)
"""The cloud file suffixes :func:`load_cloud` reads (any case)."""


# --- writers ---


def _write_ply(cloud: Cloud, f: BinaryIO) -> None:
    from plyfile import PlyData, PlyElement

    fields = [("x", "<f8"), ("y", "<f8"), ("z", "<f8")]
    if cloud.colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    vertex = np.empty(len(cloud.points), dtype=fields)
    for i, name in enumerate("xyz"):
        vertex[name] = cloud.points[:, i]
    if cloud.colors is not None:
        for i, name in enumerate(("red", "green", "blue")):
            vertex[name] = cloud.colors[:, i]
    PlyData([PlyElement.describe(vertex, "vertex")], text=False, byte_order="<").write(f)


def _write_pcd(cloud: Cloud, f: BinaryIO) -> None:
    from pypcd4 import Encoding, PointCloud

    columns = [cloud.points[:, i].astype(np.float32) for i in range(3)]
    fields = ["x", "y", "z"]
    if cloud.colors is not None:
        c = cloud.colors.astype(np.uint32)
        columns.append(((c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]).view(np.float32))
        fields.append("rgb")
    pc = PointCloud.from_points(columns, fields, [np.float32] * len(fields))
    pc.save(f, encoding=Encoding.BINARY)


def _write_npy(cloud: Cloud, f: BinaryIO) -> None:
    np.save(f, cloud.points, allow_pickle=False)


_WRITERS: dict[str, Callable[[Cloud, BinaryIO], None]] = {
    ".ply": _write_ply,
    ".pcd": _write_pcd,
    ".npy": _write_npy,
}


# --- helpers ---


def _read_transform_file(path: Path) -> FloatArray:
    try:
        text = path.read_text()
    except (OSError, UnicodeDecodeError) as exc:
        raise InputError(f"cannot read transform file {path} ({_brief(exc)})") from None
    body = " ".join(line.split("#", 1)[0] for line in text.splitlines())
    tokens = re.sub(r"[,;\[\]]", " ", body).split()
    numbers = _floats(tokens)
    if numbers is None:
        raise InputError(f"transform file {path} must hold only numbers (16, a 4x4 matrix row by row)")
    if len(numbers) != 16:
        raise InputError(f"transform file {path} holds {len(numbers)} numbers; a 4x4 matrix needs 16")
    T = np.asarray(numbers, dtype=np.float64).reshape(4, 4)
    if not np.isfinite(T).all():
        raise InputError(f"transform file {path} contains NaN or infinity")
    if not np.allclose(T[3], [0.0, 0.0, 0.0, 1.0], rtol=0.0, atol=_ORTHONORMAL_TOL):
        raise InputError(f"transform file {path}: the last row must be 0 0 0 1, got {_fmt(T[3])}")
    R = T[:3, :3]
    error = float(np.abs(R.T @ R - np.eye(3)).max())
    if error > _ORTHONORMAL_TOL:
        raise InputError(
            f"transform file {path}: the 3x3 block is not a rotation (max |R^T R - I| = {error:.2g}, "
            f"tolerance {_ORTHONORMAL_TOL:g}); give T_world_sensor without scale or shear"
        )
    if np.linalg.det(R) < 0:
        raise InputError(
            f"transform file {path}: the 3x3 block is a reflection (det -1); a rotation has det +1"
        )
    return T


def _floats(tokens: list[str]) -> list[float] | None:
    try:
        return [float(t) for t in tokens]
    except ValueError:
        return None


def _to_uint8(values: np.ndarray) -> ColorArray:
    """Colors as uint8: floats in [0, 1] are scaled by 255, everything is clipped to 0..255."""
    v = values.astype(np.float64)
    if values.dtype.kind == "f" and v.size and np.nanmax(v) <= 1.0:
        v = v * 255.0
    return np.clip(np.rint(np.nan_to_num(v)), 0, 255).astype(np.uint8)


def _brief(exc: BaseException) -> str:
    lines = str(exc).strip().splitlines()
    text = f"{type(exc).__name__}: {lines[0]}" if lines else type(exc).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def _fmt(values: ArrayLike) -> str:
    return " ".join(f"{v:g}" for v in np.asarray(values, dtype=np.float64).ravel())
