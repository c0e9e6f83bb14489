"""Interactive 3D viewer of a placement result, in the browser (viser).

``baseplace view [RESULT.json]`` serves a three.js scene over HTTP and websocket: the point cloud
(coloured by height), the planar regions (one colour each, at their plane heights), the OSRM heat
map (reachability summed over orientations, viridis, zeros hidden), the robot with its URDF meshes
at the placement's base pose and joint values, the target and the base path.

The result JSON (``baseplace demo``'s ``out/demo.json``, or ``baseplace place --json``'s object)
gives the robot, the placement and the path; the rest comes from a *view data* file the JSON names
under the key ``"view_data"``: a path relative to the JSON's directory (or absolute) to an ``.npz``
written by :func:`save_view_data`. Producers make it with :func:`view_data_from` in one call::

    data = view_data_from(terrain, result.osrm, points, robot_name)
    save_view_data(out_dir / "demo_view.npz", data)
    obj["view_data"] = "demo_view.npz"

Result JSON fields read (both layouts are accepted):

* demo: ``"placement": {"base_pose": 4x4, "joints": {name: value}}``, ``"path": {"poses": (N, 3)}``,
  ``"target": "x y z roll pitch yaw"``;
* place: ``"placements": [{"base_pose", "joints": [{name: value}, ...], "path"?}]``,
  ``"targets": [...]``; the first placement is shown with the robot, the others as frames.

The server binds to 127.0.0.1 unless told otherwise; it exposes the scene to whoever can reach
the port.
"""

from __future__ import annotations

import contextlib
import errno
import io
import itertools
import json
import math
import socket
import sys
import time
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError
from baseplace.files import atomic_write

if TYPE_CHECKING:
    import viser

    from baseplace.placement.osrm import OSRM
    from baseplace.robots.spec import RobotSpec
    from baseplace.terrain.pipeline import Terrain

DEFAULT_RESULT = Path("out") / "demo.json"
"""What ``baseplace view`` shows without an argument: the demo's result."""
VIEW_DATA_VERSION = 1
MAX_POINTS = 200_000
"""Clouds are subsampled to at most this many points for the browser."""
MAX_CELLS = 400_000
"""Region and heat-map meshes are drawn on a coarser grid when they would have more cells."""

REGION_LIFT = 0.03
"""Regions are drawn this far above their planes [m], above most of a 25 mm-noise cloud's points."""
HEATMAP_LIFT = 0.045
PATH_LIFT = 0.08

_KEYS = ("version", "robot", "points", "origin", "resolution", "labels", "heights", "planes", "osrm")


@dataclass(frozen=True)
class ViewData:
    """What the viewer needs besides the result JSON.

    Attributes:
        robot: robot name or robot-file path, as :class:`baseplace.robots.model.Robot` takes it.
        points: (N, 3) float32 cloud [m], subsampled to at most :data:`MAX_POINTS`.
        origin: (x, y) of the lower-left corner of height-map cell (0, 0) [m].
        resolution: height-map cell edge [m].
        labels: (H, W) int16 region id per cell (rows along y), -1 where none.
        heights: (H, W) float32 surface height per cell [m]: the region's plane at the cell
            centre where there is a region, else the height map, NaN where unknown.
        planes: (R, 4) float64 region planes ``(nx, ny, nz, d)`` with ``n . p + d = 0``.
        osrm: (H, W) float32 OSRM summed over orientations; zero where nothing is reachable.
    """

    robot: str
    points: NDArray[np.float32]
    origin: tuple[float, float]
    resolution: float
    labels: NDArray[np.int16]
    heights: NDArray[np.float32]
    planes: NDArray[np.float64]
    osrm: NDArray[np.float32]

    def __post_init__(self) -> None:
        shape = self.labels.shape
        if self.points.ndim != 2 or self.points.shape[1] != 3:
            raise InputError(f"view data: points must be (N, 3), got {self.points.shape}")
        if len(shape) != 2 or self.heights.shape != shape or self.osrm.shape != shape:
            raise InputError(
                f"view data: labels {shape}, heights {self.heights.shape} and osrm {self.osrm.shape} "
                "must be the same (H, W) grid"
            )
        if self.planes.ndim != 2 or self.planes.shape[1] != 4:
            raise InputError(f"view data: planes must be (R, 4), got {self.planes.shape}")
        if shape[0] * shape[1] and int(self.labels.max(initial=-1)) >= len(self.planes):
            raise InputError(f"view data: a label exceeds the {len(self.planes)} region planes")
        if not (math.isfinite(self.resolution) and self.resolution > 0):
            raise InputError(f"view data: resolution must be positive, got {self.resolution}")
        if not self.robot:
            raise InputError("view data: no robot name")


def view_data_from(
    terrain: Terrain,
    osrm: OSRM | ArrayLike | None,
    points: ArrayLike,
    robot_name: str,
    max_points: int = MAX_POINTS,
    seed: int = 0,
) -> ViewData:
    """The view data of a segmented scene and its OSRM.

    Args:
        terrain: the segmented scene (its height map and regions).
        osrm: the OSRM over ``terrain``'s segmentation, or its (H, W) summed grid, or None (no heat map).
        points: (N, 3) world cloud [m]; a random subset of ``max_points`` is kept.
        robot_name: robot name or robot-file path (what ``Robot()`` takes).
        max_points: most cloud points kept.
        seed: seed of the subsampling.
    """
    seg = terrain.segmentation
    hmap = seg.hmap
    pts = np.asarray(points, dtype=np.float32).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    if len(pts) > max_points:
        keep = np.sort(np.random.default_rng(seed).choice(len(pts), max_points, replace=False))
        pts = pts[keep]
    heights = np.asarray(hmap.raw, dtype=np.float64).copy()
    X, Y = hmap.cell_centres()
    for region in seg.regions:
        sel = seg.labels == region.id
        heights[sel] = region.height_at(np.c_[X[sel], Y[sel]])
    planes = np.array([[*r.normal, r.d] for r in seg.regions], dtype=np.float64).reshape(-1, 4)
    if osrm is None:
        summed = np.zeros(hmap.shape, dtype=np.float32)
    elif hasattr(osrm, "summed"):
        summed = np.asarray(osrm.summed, dtype=np.float32)
    else:
        summed = np.asarray(osrm, dtype=np.float32)
    if summed.shape != hmap.shape:
        raise InputError(f"the OSRM grid {summed.shape} is not the segmentation's {hmap.shape}")
    return ViewData(
        robot=robot_name,
        points=np.ascontiguousarray(pts),
        origin=(float(hmap.origin[0]), float(hmap.origin[1])),
        resolution=float(hmap.resolution),
        labels=seg.labels.astype(np.int16),
        heights=heights.astype(np.float32),
        planes=planes,
        osrm=np.nan_to_num(summed, nan=0.0).astype(np.float32),
    )


def save_view_data(path: str | Path, data: ViewData) -> None:
    """Write ``data`` to ``path`` as a compressed ``.npz`` (atomically; no pickled objects).

    Raises:
        InputError: the directory does not exist.
    """
    path = Path(path)
    with atomic_write(path, "view data") as tmp, open(tmp, "wb") as fh:
        np.savez_compressed(
            fh,
            version=np.array(VIEW_DATA_VERSION, dtype=np.int64),
            robot=np.array(data.robot),
            points=data.points.astype(np.float32),
            origin=np.array(data.origin, dtype=np.float64),
            resolution=np.array(data.resolution, dtype=np.float64),
            labels=data.labels.astype(np.int16),
            heights=data.heights.astype(np.float32),
            planes=data.planes.astype(np.float64),
            osrm=data.osrm.astype(np.float32),
        )


def load_view_data(path: str | Path) -> ViewData:
    """Read view data written by :func:`save_view_data`.

    Raises:
        InputError: the file is missing, not a view-data ``.npz`` or of another version.
    """
    path = Path(path)
    if not path.is_file():
        raise InputError(f"view data {path} does not exist")
    try:
        with np.load(path, allow_pickle=False) as npz:
            missing = [k for k in _KEYS if k not in npz.files]
            if missing:
                raise InputError(
                    f"view data {path} lacks {missing}; rewrite it with this version of baseplace"
                )
            arrays = {k: npz[k] for k in _KEYS}
    except InputError:
        raise
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"cannot read view data {path}: {first}") from None
    if int(arrays["version"]) != VIEW_DATA_VERSION:
        raise InputError(
            f"view data {path} has version {int(arrays['version'])}, this baseplace reads {VIEW_DATA_VERSION}"
        )
    if arrays["robot"].dtype.kind != "U" or arrays["origin"].shape != (2,):
        raise InputError(f"view data {path} is malformed (robot name or origin)")
    return ViewData(
        robot=str(arrays["robot"]),
        points=arrays["points"].astype(np.float32),
        origin=(float(arrays["origin"][0]), float(arrays["origin"][1])),
        resolution=float(arrays["resolution"]),
        labels=arrays["labels"].astype(np.int16),
        heights=arrays["heights"].astype(np.float32),
        planes=arrays["planes"].astype(np.float64),
        osrm=arrays["osrm"].astype(np.float32),
    )


# ----------------------------------------------------------------------------------------------
# The result JSON


@dataclass(frozen=True)
class ResultScene:
    """What the viewer draws from a result JSON.

    Attributes:
        robot: the robot's name in the JSON, if any (the view data's robot is loaded).
        base_poses: (4, 4) world poses of the base frame; the first gets the robot's meshes.
        joints: joint name -> value of the first placement (other joints: the spec's reference).
        paths: (N, 3) base paths (x, y, yaw).
        targets: (4, 4) target poses.
        view_data: path of the view data file.
    """

    robot: str | None
    base_poses: list[NDArray[np.float64]]
    joints: dict[str, float]
    paths: list[NDArray[np.float64]]
    targets: list[NDArray[np.float64]]
    view_data: Path


def _matrix(value: Any, shape: tuple[int, ...], what: str, source: Path) -> NDArray[np.float64]:
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{source}: {what} is not numeric") from None
    if arr.ndim != len(shape) or any(s not in (-1, a) for s, a in zip(shape, arr.shape, strict=True)):
        raise InputError(f"{source}: {what} must have shape {shape}, got {arr.shape}")
    if not np.isfinite(arr).all():
        raise InputError(f"{source}: {what} has non-finite values")
    return arr


def _joints(value: Any, source: Path) -> dict[str, float]:
    if isinstance(value, list):  # place: one configuration per target; show the first
        value = value[0] if value else {}
    if not isinstance(value, dict) or not all(
        isinstance(k, str) and isinstance(v, (int, float)) for k, v in value.items()
    ):
        raise InputError(f"{source}: placement joints must be an object of joint name -> number")
    return {k: float(v) for k, v in value.items()}


def read_result(path: Path) -> ResultScene:
    """Parse what the viewer needs from a demo or place result JSON.

    Raises:
        InputError: the file is missing or malformed, or names no view data.
    """
    from baseplace.geometry.poses import parse_pose6

    if not path.is_file():
        hint = "; run `baseplace demo` first" if path == DEFAULT_RESULT else ""
        raise InputError(f"result {path} does not exist{hint}")
    try:
        obj = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"cannot read result {path}: {exc}") from None
    if not isinstance(obj, dict):
        raise InputError(f"{path}: expected a JSON object, got {type(obj).__name__}")
    rel = obj.get("view_data")
    if not isinstance(rel, str) or not rel:
        redo = "rerun `baseplace demo`" if "placement" in obj else "rerun the command that wrote it"
        raise InputError(
            f"{path} names no view data (key 'view_data'); {redo} with this version of baseplace"
        )
    view_data = Path(rel) if Path(rel).is_absolute() else path.parent / rel

    robot = obj.get("robot")
    if isinstance(robot, dict):
        robot = robot.get("name")
    robot = robot if isinstance(robot, str) else None

    if "placement" in obj:
        placements = [obj["placement"]]
    elif "placements" in obj:
        placements = obj["placements"]
    else:
        raise InputError(f"{path}: no 'placement' or 'placements'")
    if not isinstance(placements, list) or not all(isinstance(p, dict) for p in placements):
        raise InputError(f"{path}: placements must be objects")
    base_poses, paths = [], []
    for i, p in enumerate(placements):
        base_poses.append(_matrix(p.get("base_pose"), (4, 4), f"placement {i} base_pose", path))
        if isinstance(p.get("path"), dict):
            paths.append(_matrix(p["path"].get("poses"), (-1, 3), f"placement {i} path poses", path))
    joints = _joints(placements[0].get("joints", {}), path) if placements else {}
    if isinstance(obj.get("path"), dict):
        paths.append(_matrix(obj["path"].get("poses"), (-1, 3), "path poses", path))
    texts = obj.get("targets", [obj["target"]] if "target" in obj else [])
    targets = []
    for t in texts if isinstance(texts, list) else []:
        if isinstance(t, str):
            try:
                targets.append(parse_pose6(t))
            except InputError:
                pass  # a target the viewer cannot parse is left out, not an error
    return ResultScene(robot, base_poses, joints, paths, targets, view_data)


# ----------------------------------------------------------------------------------------------
# Geometry for the browser


def _colormap(name: str, values: NDArray[np.floating]) -> NDArray[np.uint8]:
    from matplotlib import colormaps

    rgba = colormaps[name](np.clip(values, 0.0, 1.0))
    return (np.asarray(rgba)[:, :3] * 255).round().astype(np.uint8)


def _stride(n_cells: int) -> int:
    return max(1, math.ceil(math.sqrt(n_cells / MAX_CELLS)))


def cell_quads(
    data: ViewData, rows: NDArray[np.int64], cols: NDArray[np.int64], lift: float, stride: int = 1
) -> tuple[NDArray[np.float32], NDArray[np.uint32]]:
    """One horizontal-footprint quad per cell on its region's plane, ``lift`` above it.

    Cells without a region sit flat at their height. ``stride`` > 1 draws cells that many times
    larger (the caller picks every stride-th cell).

    Returns:
        (4 N, 3) vertices and (2 N, 3) faces, counter-clockwise seen from above.
    """
    res = data.resolution * stride
    x0 = data.origin[0] + cols * data.resolution
    y0 = data.origin[1] + rows * data.resolution
    cx = np.stack([x0, x0 + res, x0 + res, x0], axis=1)
    cy = np.stack([y0, y0, y0 + res, y0 + res], axis=1)
    label = data.labels[rows, cols].astype(np.int64)
    z = np.repeat(np.nan_to_num(data.heights[rows, cols], nan=0.0).astype(np.float64)[:, None], 4, axis=1)
    has = label >= 0
    if has.any() and len(data.planes):
        pl = data.planes[label[has]]
        z[has] = -(pl[:, 3:4] + pl[:, 0:1] * cx[has] + pl[:, 1:2] * cy[has]) / pl[:, 2:3]
    verts = np.stack([cx, cy, z + lift], axis=2).reshape(-1, 3).astype(np.float32)
    base = (np.arange(len(rows), dtype=np.uint32) * 4)[:, None]
    faces = (base + np.array([0, 1, 2, 0, 2, 3], dtype=np.uint32)).reshape(-1, 3)
    return verts, faces


def _cells(mask: NDArray[np.bool_]) -> tuple[NDArray[np.int64], NDArray[np.int64], int]:
    stride = _stride(int(mask.sum()))
    sub = np.zeros_like(mask)
    sub[::stride, ::stride] = mask[::stride, ::stride]
    rows, cols = np.nonzero(sub)
    return rows.astype(np.int64), cols.astype(np.int64), stride


def height_at(data: ViewData, xy: NDArray[np.float64]) -> NDArray[np.float64]:
    """Surface height [m] under points (N, 2): the region plane, else the height map, else 0."""
    col = np.floor((xy[:, 0] - data.origin[0]) / data.resolution).astype(np.int64)
    row = np.floor((xy[:, 1] - data.origin[1]) / data.resolution).astype(np.int64)
    h, w = data.labels.shape
    inside = (row >= 0) & (row < h) & (col >= 0) & (col < w)
    out = np.zeros(len(xy))
    r, c = row[inside], col[inside]
    label = data.labels[r, c].astype(np.int64)
    z = np.nan_to_num(data.heights[r, c].astype(np.float64), nan=0.0)
    has = label >= 0
    if has.any():
        pl = data.planes[label[has]]
        pts = xy[inside][has]
        z[has] = -(pl[:, 3] + pl[:, 0] * pts[:, 0] + pl[:, 1] * pts[:, 1]) / pl[:, 2]
    out[inside] = z
    return out


def densify(poses: NDArray[np.float64], step: float = 0.05) -> NDArray[np.float64]:
    """The (x, y) polyline through base poses (N, 3), with a point at least every ``step`` metres."""
    xy = poses[:, :2]
    if len(xy) < 2:
        return xy.copy()
    out = [xy[:1]]
    for a, b in itertools.pairwise(xy):
        n = max(1, math.ceil(float(np.hypot(*(b - a))) / step))
        t = np.arange(1, n + 1)[:, None] / n
        out.append(a + t * (b - a))
    return np.concatenate(out)


def joint_configuration(spec: RobotSpec, joints: dict[str, float], names: list[str]) -> dict[str, float]:
    """Values of the URDF's actuated joints ``names``: the placement's, else the spec's reference, else 0."""
    return {n: float(joints.get(n, spec.reference.get(n, 0.0))) for n in names}


def _package_handler(spec: RobotSpec) -> Any:
    """A yourdfpy ``filename_handler`` (called as ``handler(fname=...)``) for the spec's mesh URIs."""
    urdf_dir = spec.urdf.parent

    def handler(fname: str) -> str:
        if fname.startswith("package://"):
            rest = fname[len("package://") :]
            for d in spec.package_dirs:
                if (Path(d) / rest).is_file():
                    return str(Path(d) / rest)
            tail = rest.split("/", 1)[1] if "/" in rest else rest  # package name dropped
            for d in (*spec.package_dirs, urdf_dir, urdf_dir.parent):
                if (Path(d) / tail).is_file():
                    return str(Path(d) / tail)
            return fname
        if fname.startswith("file://"):
            return fname[len("file://") :]
        p = Path(fname)
        return str(p if p.is_absolute() else urdf_dir / p)

    return handler


def _orthonormal(R: NDArray[np.float64]) -> NDArray[np.float64]:
    u, _, vt = np.linalg.svd(R)
    out = u @ vt
    if np.linalg.det(out) < 0:
        u[:, -1] *= -1
        out = u @ vt
    return np.asarray(out)


# ----------------------------------------------------------------------------------------------
# The server


def _check_port(host: str, port: int) -> None:
    """Raise a one-line InputError if ``host:port`` cannot be bound (in use, bad host)."""
    if not (0 <= port <= 65535):
        raise InputError(f"--port must be between 0 and 65535, got {port}")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise InputError(f"cannot serve on host {host!r}: {exc.strerror}") from None
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server will
        try:
            sock.bind(address)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise InputError(f"port {port} on {host} is in use; pick another with --port") from None
            raise InputError(f"cannot serve on {host}:{port}: {exc.strerror or exc}") from None


def build_scene(server: viser.ViserServer, scene: ResultScene, data: ViewData) -> dict[str, Any]:
    """Add the cloud, regions, heat map, robot, targets and paths to ``server``'s scene.

    Returns:
        name -> scene handle(s) of each layer (for the GUI toggles and tests).
    """
    import viser.transforms as vtf
    import yourdfpy
    from viser.extras import ViserUrdf

    from baseplace.robots.spec import load_spec
    from baseplace.robots.urdf import robot_urdf

    api = server.scene
    api.set_up_direction("+z")
    layers: dict[str, Any] = {}

    pts = data.points
    if len(pts):
        lo, hi = np.percentile(pts[:, 2], [2, 98])
        shade = 0.3 + 0.5 * np.clip((pts[:, 2] - lo) / max(float(hi - lo), 1e-6), 0.0, 1.0)
        colors = _colormap("bone", shade)  # grey-blue by height: colour is kept for regions and heat map
        layers["cloud"] = api.add_point_cloud(
            "/cloud", pts, colors, point_size=0.015, point_shape="rounded", precision="float32"
        )

    regions = []
    palette = _colormap("tab20", (np.arange(20) + 0.5) / 20)
    rows, cols, stride = _cells(data.labels >= 0)
    for rid in range(len(data.planes)):
        sel = data.labels[rows, cols] == rid
        if not sel.any():
            continue
        verts, faces = cell_quads(data, rows[sel], cols[sel], REGION_LIFT, stride)
        r, g, b = (int(c) for c in palette[(2 * rid + rid // 10) % 20])
        regions.append(
            api.add_mesh_simple(
                f"/regions/region_{rid}", verts, faces, color=(r, g, b), opacity=0.8, side="double",
                cast_shadow=False, receive_shadow=False,
            )
        )  # fmt: skip
    layers["regions"] = regions

    vmax = float(data.osrm.max(initial=0.0))
    if vmax > 0:
        import trimesh

        rows, cols, stride = _cells(data.osrm > 0)
        verts, faces = cell_quads(data, rows, cols, HEATMAP_LIFT, stride)
        rgb = _colormap("viridis", data.osrm[rows, cols] / vmax)
        rgba = np.repeat(np.c_[rgb, np.full(len(rgb), 255, dtype=np.uint8)], 4, axis=0)
        mesh = trimesh.Trimesh(verts, faces, vertex_colors=rgba, process=False)
        layers["heatmap"] = api.add_mesh_trimesh("/heatmap", mesh, cast_shadow=False, receive_shadow=False)

    for i, T in enumerate(scene.targets):
        layers[f"target_{i}"] = api.add_frame(
            f"/targets/target_{i}", wxyz=vtf.SO3.from_matrix(_orthonormal(T[:3, :3])).wxyz,
            position=T[:3, 3], axes_length=0.15, axes_radius=0.012,
        )  # fmt: skip

    paths: list[Any] = []
    for i, poses in enumerate(scene.paths):
        xy = densify(poses)
        if len(xy) < 2:
            continue
        p3 = np.c_[xy, height_at(data, xy) + PATH_LIFT]
        segs = np.stack([p3[:-1], p3[1:]], axis=1).astype(np.float32)
        paths.append(
            api.add_line_segments(
                f"/paths/path_{i}", segs, colors=(255, 120, 0), thickness=4.0, thickness_units="screen"
            )
        )
        paths.append(
            api.add_icosphere(f"/paths/start_{i}", radius=0.07, color=(255, 120, 0), position=tuple(p3[0]))
        )
    layers["paths"] = paths

    robot_name = scene.robot or data.robot
    spec = load_spec(data.robot)  # the view data's name or robot-file path, which Robot() takes
    for i, T in enumerate(scene.base_poses[1:], start=1):
        layers[f"placement_{i}"] = api.add_frame(
            f"/placements/placement_{i}", wxyz=vtf.SO3.from_matrix(_orthonormal(T[:3, :3])).wxyz,
            position=T[:3, 3], axes_length=0.3, axes_radius=0.015,
        )  # fmt: skip
    if scene.base_poses:
        from baseplace.robots.collision import check_mesh_paths

        check_mesh_paths(spec)  # meshes only from the robot's package folders (docs/security.md)
        try:
            urdf = yourdfpy.URDF.load(  # the robot file's URDF: meshes resolved, a mounted arm on its base
                io.StringIO(robot_urdf(spec).xml), build_scene_graph=True, load_meshes=True,
                filename_handler=_package_handler(spec),
            )  # fmt: skip
        except InputError:
            raise
        except Exception as exc:  # yourdfpy raises bare ValueError, KeyError, OSError, lxml errors
            raise InputError(f"cannot load the URDF {spec.urdf} of robot {spec.name!r}: {exc}") from None
        cfg = joint_configuration(spec, scene.joints, list(urdf.actuated_joint_names))
        urdf.update_cfg(cfg)
        if spec.base_frame in urdf.link_map:
            T_root_base = np.asarray(urdf.get_transform(spec.base_frame, urdf.base_link), dtype=np.float64)
        else:
            T_root_base = np.eye(4)
        T = scene.base_poses[0] @ np.linalg.inv(T_root_base)
        frame = api.add_frame(
            "/robot",
            wxyz=vtf.SO3.from_matrix(_orthonormal(T[:3, :3])).wxyz,
            position=T[:3, 3],
            show_axes=False,
        )
        viser_urdf = ViserUrdf(server, urdf, root_node_name="/robot")
        viser_urdf.update_cfg(np.array([cfg[n] for n in urdf.actuated_joint_names]))
        layers["robot"] = frame
        layers["urdf"] = viser_urdf

    _camera(server, scene, data)
    _gui(server, layers, scene, robot_name)
    return layers


def _camera(server: viser.ViserServer, scene: ResultScene, data: ViewData) -> None:
    """Look at the placement from behind the path's start, high enough to see the heat map."""
    focus = [T[:3, 3] for T in scene.base_poses[:1]]
    extent = [np.c_[p[:, :2], height_at(data, p[:, :2])] for p in scene.paths]
    pts = np.concatenate([np.atleast_2d(f) for f in focus + extent]) if focus or extent else None
    if pts is None or not len(pts):
        h, w = data.labels.shape
        centre = np.array(
            [data.origin[0] + w * data.resolution / 2, data.origin[1] + h * data.resolution / 2, 0.0]
        )
        size = max(h, w) * data.resolution
    else:
        centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
        size = float(np.ptp(pts[:, :2], axis=0).max()) if len(pts) > 1 else 3.0
    size = max(size, 3.0)
    look = centre if not focus else 0.65 * centre + 0.35 * focus[0]
    direction = np.array([-0.55, -0.75, 0.65])
    if scene.paths and len(scene.paths[0]) >= 2 and focus:
        d = scene.paths[0][0, :2] - focus[0][:2]
        if np.hypot(*d) > 1e-6:
            d = d / np.hypot(*d)
            side = np.array([-d[1], d[0]])
            horiz = 0.75 * d + 0.55 * side
            direction = np.array([horiz[0], horiz[1], 0.75])
    direction /= np.linalg.norm(direction)
    server.initial_camera.look_at = np.asarray(look, dtype=np.float64)
    server.initial_camera.position = np.asarray(look + direction * 1.05 * size, dtype=np.float64)


def _gui(server: viser.ViserServer, layers: dict[str, Any], scene: ResultScene, robot: str) -> None:
    """Checkboxes that show and hide each layer, and a line about the placement."""
    groups = {
        "Point cloud": [layers.get("cloud")],
        "Planar regions": layers.get("regions", []),
        "OSRM heat map": [layers.get("heatmap")],
        "Robot": [layers.get("robot")],
        "Path": layers.get("paths", []),
    }
    for label, handles in groups.items():
        handles = [h for h in handles if h is not None]
        if not handles:
            continue
        box = server.gui.add_checkbox(label, initial_value=True)

        def toggle(_: Any, box: Any = box, handles: list[Any] = handles) -> None:
            for h in handles:
                h.visible = box.value

        box.on_update(toggle)
    if scene.base_poses:
        T = scene.base_poses[0]
        yaw = math.degrees(math.atan2(T[1, 0], T[0, 0]))
        server.gui.add_markdown(
            f"**{robot}** at x = {T[0, 3]:.2f} m, y = {T[1, 3]:.2f} m, z = {T[2, 3]:.2f} m, yaw = {yaw:.0f}°"
        )


def serve(
    result_json: Path | None = None,
    host: str = "127.0.0.1",
    port: int = 8080,
    block: bool = True,
) -> viser.ViserServer:
    """Serve the 3D view of a result JSON (the demo's ``out/demo.json`` if None).

    Args:
        result_json: a demo or place result naming its view data (key ``"view_data"``).
        host: interface to bind; 127.0.0.1 (this machine only) unless told otherwise.
        port: TCP port; 0 picks a free one (see ``server.get_port()``).
        block: wait until Ctrl-C, then stop the server; False returns the running server at once
            (call ``.stop()`` on it).

    Returns:
        The viser server (already stopped when ``block`` is True).

    Raises:
        InputError: the result or its view data is missing or malformed, the URDF does not load,
            or the port is in use.
    """
    import viser

    path = DEFAULT_RESULT if result_json is None else Path(result_json)
    scene = read_result(path)
    data = load_view_data(scene.view_data)
    _check_port(host, port)
    with contextlib.redirect_stdout(io.StringIO()):  # viser's banner; serve prints its own line
        server = viser.ViserServer(host=host, port=port, label="baseplace", verbose=False)
    if port != 0 and server.get_port() != port:  # viser moves on to the next free port silently
        server.stop()
        raise InputError(f"port {port} on {host} is in use; pick another with --port")
    try:
        build_scene(server, scene, data)
    except BaseException:
        server.stop()
        raise
    if not block:
        return server
    shown = f"[{host}]" if ":" in host else host
    print(f"baseplace view: http://{shown}:{server.get_port()}/ ({path}); Ctrl-C to stop", file=sys.stderr)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
    return server
