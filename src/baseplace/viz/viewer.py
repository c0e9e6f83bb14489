"""Interactive 3D viewer of any baseplace result, in the browser (viser).

``baseplace view RESULT.json`` serves a three.js scene over HTTP and websocket. It reads the
``--json`` object of ``place``, ``candidates``, ``surface-map``, ``surface-sample``, ``navigate``,
``segment`` or ``demo`` (:mod:`baseplace.viz.result_view`) and the inputs that object names (cloud,
occupancy grid, surface map, robot), and draws them (:mod:`baseplace.viz.view_scene`):

* place / demo: the cloud (grey-blue by height) and its planar regions, the robot with its URDF
  meshes at the first placement's base pose and joint values, its reaching motion (the TCP's path,
  translucent copies at the start and pre-grasp configurations, a slider and Play button over the
  joint waypoints), the other placements as frames, targets and base paths;
* candidates: the occupancy grid, the cloud if any, the object, the ranked candidates (arrows, best
  darkest) with the robot and its motion at the best one, the rejected positions and the path;
* surface-map / surface-sample: the surface map's R_S heat map, the working surface, the samples
  (arrows) and the robot at the best one;
* navigate: the cloud, its regions, the path and the robot at the goal;
* segment: the cloud and the regions and borders of the JSON;
* point: the image with the hand's landmarks, the finger's line and the objects' image boxes (on the
  camera's frustum in the scene and in the panel), the objects' 3D boxes (the pointed-at one gold),
  the finger's 3D ray and, with a grid, the candidates to pick the object up as for candidates.

The demo's result also names a *view data* file (key ``"view_data"``, relative to the JSON's
directory or absolute): an ``.npz`` written by :func:`save_view_data` with the segmented scene and
the OSRM heat map, made in one call::

    data = view_data_from(terrain, result.osrm, points, robot_name)
    save_view_data(out_dir / "demo_view.npz", data)
    obj["view_data"] = "demo_view.npz"

The server binds to 127.0.0.1 unless told otherwise; it exposes the scene to whoever can reach
the port. A result is data: every string it carries (an error, a robot name, a file name) reaches
the page as text (:func:`markdown_text`), never as HTML or a link.
"""

from __future__ import annotations

import contextlib
import errno
import html
import io
import itertools
import math
import socket
import string
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
from baseplace.geometry.poses import yaw_of

if TYPE_CHECKING:
    import viser

    from baseplace.placement.osrm import OSRM
    from baseplace.robots.spec import RobotSpec
    from baseplace.terrain.pipeline import Terrain
    from baseplace.viz.result_view import ResultView
    from baseplace.viz.view_scene import SceneInputs

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


def _camera(server: viser.ViserServer, view: ResultView, inputs: SceneInputs, layers: dict[str, Any]) -> None:
    """Look at the robot (or the result's poses) from behind the path's start, high enough to see the map."""
    from baseplace.viz.view_scene import ground

    robot_pose = layers.get("robot_pose")
    focus = [robot_pose[:3, 3]] if robot_pose is not None else []
    # with a robot, frame it and what it reaches for; paths may lead far away
    extent = [] if focus else [np.c_[p[:, :2], ground(inputs, p[:, :2])] for p in view.paths]
    extent += [np.c_[view.candidates[:, :2], np.zeros(len(view.candidates))]] if len(view.candidates) else []
    extent += [T[None, :3, 3] for T in [rp.T_world_base for rp in view.robots[1:]]]
    extent += [T[None, :3, 3] for T in view.targets]
    if view.pointing is not None:
        extent += [view.pointing.world_boxes.reshape(-1, 3)]
        if inputs.T_world_camera is not None:
            extent.append(inputs.T_world_camera[None, :3, 3])
    if view.object_xyz is not None:
        extent.append(view.object_xyz[None])
    if inputs.surface is not None:
        extent.append(
            np.c_[inputs.surface.polygon, np.full(len(inputs.surface.polygon), inputs.surface.height)]
        )
    for region in view.regions:
        extent += [np.c_[ext, np.zeros(len(ext))] for ext, _ in region.polygons]
    pts = np.concatenate([np.atleast_2d(f) for f in focus + extent]) if focus or extent else np.zeros((0, 3))
    if not len(pts):
        if inputs.data is not None:
            h, w = inputs.data.labels.shape
            o, res = inputs.data.origin, inputs.data.resolution
            pts = np.array([[o[0], o[1], 0.0], [o[0] + w * res, o[1] + h * res, 0.0]])
        elif len(inputs.points):
            pts = np.percentile(inputs.points, [5, 95], axis=0)
        elif inputs.grid is not None:
            g = inputs.grid
            pts = np.array([[*g.origin[:2], 0.0], [g.origin[0] + g.width * g.resolution,
                                                   g.origin[1] + g.height * g.resolution, 0.0]])  # fmt: skip
        else:
            pts = np.zeros((1, 3))
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
    size = max(float(np.ptp(pts[:, :2], axis=0).max()) if len(pts) > 1 else 3.0, 2.2 if focus else 3.0)
    look = centre if not focus else 0.65 * centre + 0.35 * focus[0]
    direction = np.array([-0.55, -0.75, 0.65])
    if view.paths and len(view.paths[0]) >= 2 and focus:
        d = view.paths[0][0, :2] - focus[0][:2]
        if np.hypot(*d) > 1e-6:
            d = d / np.hypot(*d)
            side = np.array([-d[1], d[0]])
            horiz = 0.75 * d + 0.55 * side
            direction = np.array([horiz[0], horiz[1], 0.75])
    if view.pointing is not None and inputs.T_world_camera is not None and len(view.pointing.world_boxes):
        # from the side of the line camera -> objects: the frame, the objects and the robot side by side
        d = view.pointing.world_boxes.mean(axis=(0, 1))[:2] - inputs.T_world_camera[:2, 3]
        d = d / max(float(np.hypot(*d)), 1e-6)
        horiz = -0.35 * d + 0.9 * np.array([-d[1], d[0]])
        direction = np.array([horiz[0], horiz[1], 0.8])
    direction /= np.linalg.norm(direction)
    server.initial_camera.look_at = np.asarray(look, dtype=np.float64)
    server.initial_camera.position = np.asarray(look + direction * 1.05 * size, dtype=np.float64)


def markdown_text(text: str) -> str:
    """``text`` as markdown that shows it literally, on one line.

    viser's markdown passes raw HTML through (``<iframe srcdoc=...>`` would run), and markdown
    makes links, emphasis and code of punctuation: HTML's special characters become entities
    (:func:`html.escape`), every other ASCII punctuation is backslash-escaped (CommonMark's
    escapes: no link, image, autolink, emphasis, code or table), and line breaks and other
    control characters become spaces.
    """
    out = []
    for c in " ".join(text.split()):
        if c in "&<>\"'":
            out.append(html.escape(c))
        elif c in string.punctuation:
            out.append("\\" + c)
        else:
            out.append(c if c.isprintable() else " ")
    return "".join(out)


def _gui(server: viser.ViserServer, layers: dict[str, Any], view: ResultView, robot: str | None) -> None:
    """Checkboxes that show and hide each layer, and a line about the result."""
    groups = {
        "Point cloud": [layers.get("cloud")],
        "Occupancy grid": [layers.get("occupancy")],
        "Planar regions": layers.get("regions", []),
        "OSRM heat map": [layers.get("heatmap")],
        "Surface map": layers.get("surface_map", []),
        "Robot": [layers.get("robot")],
        "Candidates": layers.get("candidates", []),
        "Rejected": [layers.get("rejected")],
        "Path": layers.get("paths", []),
        "Camera image": [layers.get("camera")],
        "Objects": [*layers.get("objects", []), layers.get("ray")],
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
    text = f"**{markdown_text(view.command)}**: {markdown_text(view.summary)}"
    T = layers.get("robot_pose")
    if T is not None:
        yaw = math.degrees(yaw_of(T))
        text += (
            f"; **{markdown_text(str(robot))}** at x = {T[0, 3]:.2f} m, y = {T[1, 3]:.2f} m, "
            f"z = {T[2, 3]:.2f} m, yaw = {yaw:.0f}°"
        )
    server.gui.add_markdown(text)


def _robot_to_draw(view: ResultView, inputs: SceneInputs) -> str | None:
    """The robot name or file to draw: the result's, else the view data's; None when nothing needs one."""
    robot = view.robot or (inputs.data.robot if view.inputs.view_data is not None and inputs.data else None)
    if view.robots and robot is None:
        raise InputError(
            f"{view.source} ({view.command} result) names no robot; rerun it with this version of baseplace"
        )
    return robot


def open_view(
    result_json: str | Path, given: dict[str, Any] | None = None
) -> tuple[ResultView, SceneInputs, str | None]:
    """Read a result and load the inputs it names (what :func:`serve` shows), without a server.

    Args:
        result_json: the result.
        given: input files given to the viewer in place of the result's (see
            :func:`baseplace.viz.result_view.read_result`).

    Raises:
        InputError: the result is not one the viewer shows, or an input is missing or malformed.
    """
    from baseplace.viz.result_view import read_result
    from baseplace.viz.view_scene import load_inputs

    view = read_result(result_json, given=given)
    robot = view.robot
    # segment the cloud for the regions and ground heights, unless the result carries its own
    segment = view.kind in ("place", "navigate") and view.inputs.view_data is None
    inputs = load_inputs(view, robot or "", segment)
    return view, inputs, _robot_to_draw(view, inputs)


def serve(
    result_json: str | Path | None = None,
    host: str = "127.0.0.1",
    port: int = 8080,
    block: bool = True,
    given: dict[str, Any] | None = None,
) -> viser.ViserServer:
    """Serve the 3D view of a result JSON (the demo's ``out/demo.json`` if None).

    Args:
        result_json: the ``--json`` object of place, candidates, surface-map, surface-sample,
            navigate, segment or demo, saved to a file; the inputs it names are read too.
        host: interface to bind; 127.0.0.1 (this machine only) unless told otherwise.
        port: TCP port; 0 picks a free one (see ``server.get_port()``).
        block: wait until Ctrl-C, then stop the server; False returns the running server at once
            (call ``.stop()`` on it); its scene layers are in ``server.baseplace_layers``.
        given: input files given to the viewer in place of the result's: ``cloud`` and
            ``transform`` (lists), ``floor``, ``occupancy``, ``surface_map``, ``robot``.

    Returns:
        The viser server (already stopped when ``block`` is True).

    Raises:
        InputError: the result is missing, not a result or malformed, an input it names is
            missing, the URDF does not load, or the port is in use.
    """
    import viser

    from baseplace.viz.view_scene import build_scene

    path = DEFAULT_RESULT if result_json is None else Path(result_json)
    if result_json is None and not path.is_file():
        raise InputError(f"result {path} does not exist; run `baseplace demo` first, or give a result JSON")
    view, inputs, robot = open_view(path, given)
    _check_port(host, port)
    with contextlib.redirect_stdout(io.StringIO()):  # viser's banner; serve prints its own line
        server = viser.ViserServer(host=host, port=port, label="baseplace", verbose=False)
    if port != 0 and server.get_port() != port:  # viser moves on to the next free port silently
        server.stop()
        raise InputError(f"port {port} on {host} is in use; pick another with --port")
    try:
        layers = build_scene(server, view, inputs, robot)
        _camera(server, view, inputs, layers)
        _gui(server, layers, view, robot)
        server.baseplace_layers = layers
    except BaseException:
        server.stop()
        raise
    if not block:
        return server
    shown = f"[{host}]" if ":" in host else host
    print(f"baseplace view: http://{shown}:{server.get_port()}/ ({path}, {view.command} result); Ctrl-C to stop",
          file=sys.stderr)  # fmt: skip
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
    return server
