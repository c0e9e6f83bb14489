"""Collision objects given by hand beside the cloud: boxes, vertical cylinders, meshes (issue 29).

MoveIt's users add collision objects to the planning scene beside what the camera saw: a table
the scan missed, a keep-out zone, a CAD model of a machine. Here each ``--obstacle`` becomes a coal
geometry with a world pose (:class:`Obstacle`); the collision model every check shares
(:class:`~baseplace.world.environment.Environment`) holds it next to the cloud's voxels, so the
verification, the reaching motion, the robustness score and ``explain`` see the true shape, and
a contact with it is reported as ``obstacle box#0`` (the obstacle's kind and its place among the
``--obstacle`` options, counted from 0).

A mesh file is data from someone else (docs/security.md): its size and the faces it declares are
checked before any parser allocates them, no file it names (an OBJ's material library) is opened,
and its triangles must be finite and index its vertices. A mesh is its surface: coal finds a link
that crosses a triangle, not one wholly inside a closed mesh (give a box for a solid).
"""

from __future__ import annotations

import hashlib
import math
import struct
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import coal
import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError, brief
from baseplace.geometry.poses import YAW_LIMIT, FloatArray, check_angles, pose_from_xyz_rpy
from baseplace.guards import check_alloc

OBSTACLE_FORMS = (
    '"box X Y Z SX SY SZ [YAW]" (centre, full sizes), "cylinder X Y Z RADIUS HEIGHT" (centre, axis '
    "vertical) [m, rad] or a mesh file PATH.stl|.obj|.ply in world coordinates [m]"
)
"""The valid forms of an obstacle, for help texts and error messages."""

MESH_SUFFIXES = (".stl", ".obj", ".ply")
MAX_OBSTACLES = 64
"""Obstacles one query may have."""
MAX_SIZE = 100.0
"""Largest box size, cylinder radius or height, and mesh extent [m]."""
MAX_MESH_BYTES = 64 << 20
"""Largest mesh file [bytes]."""
MAX_MESH_FACES = 1_000_000
"""Largest number of triangles of a mesh obstacle (a TIAGo link has a few thousand)."""
MESH_BYTES_PER_FACE = 1500
"""Memory one triangle takes while loading [bytes]: the parser's arrays, trimesh's and coal's tree
(measured: a binary STL of 327,680 triangles grows the CLI's peak by 390 MB, 1,200 bytes each)."""
MESH_BYTES_PER_TEXT_BYTE = 40.0
"""Most memory one byte of a text mesh (OBJ, ASCII STL or PLY) stands for while it is parsed."""
TARGET_CLEARANCE = 0.01
"""A target's grasp point must lie this far [m] outside every obstacle."""


@dataclass(frozen=True, eq=False)
class Obstacle:
    """One collision object in the world frame.

    Attributes:
        name: ``<kind>#<k>``, k its place among the obstacles given (from 0), e.g. ``box#0``.
        kind: "box", "cylinder" or "mesh".
        geometry: the coal shape in its own frame (a box or cylinder centred on its origin, a
            cylinder's axis along z; a mesh's triangles in world coordinates).
        T_world_obstacle: (4, 4) pose of that frame in the world.
        spec: the obstacle as given (the text or the file's path).
        digest: a hash of the shape and pose, for caches of collision models.
    """

    name: str
    kind: str
    geometry: coal.CollisionGeometry
    T_world_obstacle: FloatArray
    spec: str
    digest: str

    @property
    def label(self) -> str:
        """What a contact report names as touched: ``obstacle box#0``."""
        return f"obstacle {self.name}"

    def distance(self, p_world: ArrayLike) -> float:
        """Distance [m] of the point (3,) from the obstacle: negative inside a box or cylinder.

        A mesh is its surface: the distance from its nearest triangle, inside or out.
        """
        T = self.T_world_obstacle
        point = coal.Sphere(1e-6)
        at = coal.Transform3s(np.eye(3), np.asarray(p_world, dtype=float).reshape(3))
        result = coal.DistanceResult()
        return float(coal.distance(point, at, self.geometry, coal.Transform3s(T[:3, :3], T[:3, 3]),
                                   coal.DistanceRequest(), result))  # fmt: skip

    def to_json(self) -> dict[str, Any]:
        """Name, kind and the spec as given."""
        return {"name": self.name, "kind": self.kind, "spec": self.spec}


def obstacles_key(obstacles: Sequence[Obstacle]) -> str:
    """One digest of the obstacles, in order ("" for none): a key for cached collision models."""
    if not obstacles:
        return ""
    return hashlib.sha256("|".join(o.digest for o in obstacles).encode()).hexdigest()[:24]


def parse_obstacles(specs: Sequence[str] | None, what: str = "--obstacle") -> tuple[Obstacle, ...]:
    """Every ``--obstacle`` (see :data:`OBSTACLE_FORMS`), named by its kind and place.

    Raises:
        InputError: a malformed spec or a refused mesh file, one line naming the valid forms.
    """
    specs = list(specs or [])
    if len(specs) > MAX_OBSTACLES:
        raise InputError(f"{what}: {len(specs)} obstacles given, at most {MAX_OBSTACLES}")
    return tuple(parse_obstacle(spec, k, what) for k, spec in enumerate(specs))


def parse_obstacle(spec: str, index: int = 0, what: str = "--obstacle") -> Obstacle:
    """One obstacle from its spec (see :data:`OBSTACLE_FORMS`); ``index`` names it (``box#<index>``)."""
    if not isinstance(spec, str) or not spec.strip():
        raise InputError(f"{what}: expected {OBSTACLE_FORMS}, got {brief(spec, 80)}")
    words = spec.replace(",", " ").split()
    kind = words[0].lower()
    if kind in ("box", "cylinder"):
        counts = (7, 8) if kind == "box" else (6,)
        if len(words) not in counts:
            raise InputError(f"{what} {brief(spec, 80)}: expected {OBSTACLE_FORMS}")
        try:
            values = [float(w) for w in words[1:]]
        except ValueError:
            raise InputError(f"{what} {brief(spec, 80)}: not numbers; expected {OBSTACLE_FORMS}") from None
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"{what} {brief(spec, 80)}: NaN or infinity; expected {OBSTACLE_FORMS}")
        sizes = values[3:6] if kind == "box" else values[3:5]
        if not all(0 < v <= MAX_SIZE for v in sizes):
            raise InputError(f"{what} {brief(spec, 80)}: sizes must be > 0 and <= {MAX_SIZE:g} m")
        yaw = values[6] if len(values) == 7 else 0.0
        try:
            check_angles([yaw], (YAW_LIMIT,))
        except InputError as exc:
            raise InputError(f"{what} {brief(spec, 80)}: box {exc}") from None
        T = np.asarray(pose_from_xyz_rpy([*values[:3], 0.0, 0.0, yaw]), dtype=float)
        geometry: coal.CollisionGeometry = coal.Box(*sizes) if kind == "box" else coal.Cylinder(*sizes)
        digest = _digest(kind, np.array(values, dtype=float))
        return Obstacle(f"{kind}#{index}", kind, geometry, T, spec, digest)
    if len(words) >= 1 and Path(spec.strip()).suffix.lower() in MESH_SUFFIXES:
        vertices, faces = load_mesh(Path(spec.strip()), what)
        bvh = coal.BVHModelOBBRSS()
        bvh.beginModel(len(faces), len(vertices))
        bvh.addVertices(vertices)
        bvh.addTriangles(faces)
        bvh.endModel()
        return Obstacle(
            f"mesh#{index}", "mesh", bvh, np.eye(4), spec.strip(), _digest("mesh", vertices, faces)
        )
    raise InputError(f"{what} {brief(spec, 80)}: expected {OBSTACLE_FORMS}")


def _digest(kind: str, *arrays: np.ndarray) -> str:
    h = hashlib.sha256(kind.encode())
    for a in arrays:
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()[:24]


def load_mesh(path: Path, what: str = "--obstacle") -> tuple[FloatArray, np.ndarray]:
    """A mesh file's vertices (V, 3) [m] and triangles (F, 3), its sizes checked before parsing.

    Raises:
        InputError: a missing, oversized or malformed file, or one whose declared triangles its
            bytes cannot hold (:func:`declared_faces`).
    """
    source = f"{what} {path}"
    if not path.is_file():
        raise InputError(f"{source}: no such file")
    size = path.stat().st_size
    if size > MAX_MESH_BYTES:
        raise InputError(
            f"{source}: {size} bytes, more than the {MAX_MESH_BYTES >> 20} MB a mesh obstacle may have"
        )
    suffix = path.suffix.lower()
    declared, text = declared_faces(path, size, source)
    if declared is not None and declared > MAX_MESH_FACES:
        raise InputError(
            f"{source}: declares {declared} triangles, more than the {MAX_MESH_FACES} a mesh obstacle "
            "may have; simplify it"
        )
    check_alloc((declared or 0) * MESH_BYTES_PER_FACE, "mesh triangles", source)
    if text:
        check_alloc(size * MESH_BYTES_PER_TEXT_BYTE, "mesh text", source)
    import trimesh

    try:
        with path.open("rb") as f:  # a file object and no resolver: an OBJ's mtllib is never opened
            mesh = trimesh.load_mesh(f, file_type=suffix[1:], process=False, skip_materials=True)
        vertices = np.asarray(mesh.vertices, dtype=np.float64)
        faces = np.asarray(mesh.faces, dtype=np.int64)
    except InputError:
        raise
    except Exception as exc:  # trimesh raises many kinds on malformed files
        raise InputError(
            f"{source}: cannot read the mesh: {brief(str(exc).splitlines()[0] if str(exc) else exc)}"
        ) from None
    if faces.ndim != 2 or faces.shape[1] != 3 or len(faces) == 0:
        raise InputError(f"{source}: no triangles")
    if len(faces) > MAX_MESH_FACES:
        raise InputError(
            f"{source}: {len(faces)} triangles, more than the {MAX_MESH_FACES} a mesh obstacle may have"
        )
    if vertices.ndim != 2 or vertices.shape[1] != 3 or not np.all(np.isfinite(vertices)):
        raise InputError(f"{source}: vertices must be finite x y z")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise InputError(f"{source}: a triangle indexes a vertex the file does not have")
    if np.abs(vertices).max() > 10 * MAX_SIZE:
        raise InputError(
            f"{source}: vertices beyond {10 * MAX_SIZE:g} m of the origin; is it in millimetres?"
        )
    return vertices, faces


def declared_faces(path: Path, size: int, source: str) -> tuple[int | None, bool]:
    """The triangles the file declares (None: it declares no count), and whether it is text.

    Binary STL: its header's count, which must match its size (84 + 50 bytes per triangle). PLY:
    every element's rows, each at least its properties' bytes (binary) or two characters per
    value (ASCII), must fit in the bytes after the header. OBJ and ASCII STL declare no count:
    their text's size bounds what parsing them takes.
    """
    suffix = path.suffix.lower()
    with path.open("rb") as f:
        head = f.read(1 << 20)
    if suffix == ".stl":
        if len(head) >= 84:
            (n,) = struct.unpack("<I", head[80:84])
            if 84 + 50 * n == size:
                return n, False
        if head.lstrip()[:5].lower() == b"solid":
            return None, True
        declared = struct.unpack("<I", head[80:84])[0] if len(head) >= 84 else 0
        raise InputError(
            f"{source}: binary STL declares {declared} triangles ({84 + 50 * declared} bytes) but has "
            f"{size} bytes; the file is truncated or corrupt"
        )
    if suffix == ".obj":
        return None, True
    return _ply_faces(head, size, source)


_PLY_BYTES = {"char": 1, "uchar": 1, "int8": 1, "uint8": 1, "short": 2, "ushort": 2, "int16": 2, "uint16": 2,
              "int": 4, "uint": 4, "int32": 4, "uint32": 4, "float": 4, "float32": 4, "double": 8, "float64": 8}  # fmt: skip


def _ply_faces(head: bytes, size: int, source: str) -> tuple[int, bool]:
    end = head.find(b"end_header")
    if not head.startswith(b"ply") or end < 0:
        raise InputError(f"{source}: not a PLY file, or a header over 1 MB")
    header_end = head.find(b"\n", end)
    data_bytes = size - (header_end + 1 if header_end >= 0 else len(head))
    fmt = ""
    elements: list[list[Any]] = []  # [name, count, min bytes per row, values per row]
    for raw in head[:end].decode("ascii", "replace").splitlines():
        words = raw.split()
        if not words:
            continue
        if words[0] == "format" and len(words) >= 2:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3:
            try:
                elements.append([words[1], int(words[2]), 0, 0])
            except ValueError:
                raise InputError(f"{source}: element {brief(words[1], 20)} has no count") from None
        elif words[0] == "property" and elements and len(words) >= 3:
            if words[1] == "list" and len(words) == 5:  # a list holds its count and at least 3 indices
                row = _PLY_BYTES.get(words[2], 0) + 3 * _PLY_BYTES.get(words[3], 0)
                elements[-1][2] += row
                elements[-1][3] += 4
            else:
                elements[-1][2] += _PLY_BYTES.get(words[1], 0)
                elements[-1][3] += 1
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise InputError(f"{source}: unknown PLY format {brief(fmt, 30)}")
    text = fmt == "ascii"
    needed = 0
    for _, count, row_bytes, values in elements:
        if count < 0:
            raise InputError(f"{source}: negative element count")
        needed += count * (2 * values if text else max(row_bytes, 1))
    faces = sum(e[1] for e in elements if e[0] == "face")
    if needed > data_bytes:
        raise InputError(
            f"{source}: declares {faces} triangles and {sum(e[1] for e in elements) - faces} other rows, "
            f"at least {needed} bytes, but has {data_bytes} bytes of data; the file is truncated or corrupt"
        )
    return faces, text


def check_clear_of(obstacles: Sequence[Obstacle], points: ArrayLike, labels: Sequence[str]) -> None:
    """Refuse a point (K, 3) [m] inside an obstacle or within :data:`TARGET_CLEARANCE` of it.

    The points are the targets' grasp points: an obstacle there collides with every grasp, from
    every base pose; refusing says so at once instead of after the whole search.
    """
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    for o in obstacles:
        for k, point in enumerate(p):
            d = o.distance(point)
            if d < TARGET_CLEARANCE:
                where = "inside" if d < 0 else f"{d:.3f} m from"
                raise InputError(
                    f"{labels[k]}: its grasp point {np.round(point, 3).tolist()} lies {where} {o.label} "
                    f"({o.spec if o.kind == 'mesh' else brief(o.spec, 80)}); every grasp there would touch it: "
                    "move the obstacle or the target"
                )
