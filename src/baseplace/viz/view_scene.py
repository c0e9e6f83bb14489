"""The viewer's 3D scene of a result: its inputs loaded and every layer added to a viser server.

:func:`build_scene` draws a :class:`~baseplace.viz.result_view.ResultView` over the inputs it
names: the cloud (grey-blue by height) and its planar regions, the occupancy grid (an image on the
floor), the surface map's R_S heat map and working surface, then the result's own layers: the robot
with its URDF meshes at the first base pose and joint values, its reaching motion (the TCP's path,
translucent copies of the robot at the start and pre-grasp configurations, and a slider and Play
button that move the robot along the joint waypoints), other placements or candidates as arrows,
rejected positions, base paths, targets and the object. A ``point`` result adds its frame: the
image with the hand, the finger's line and the objects' image boxes on the camera's frustum (and in
the panel), the objects' 3D boxes (the selected one gold) and the finger's 3D ray.

Colours (the Chromium tests look for their hues): path orange, candidates green, rejected red,
the TCP's path magenta, motion copies sky blue, object cyan, working surface violet, pointed-at
object gold, the finger's ray blue.
"""

from __future__ import annotations

import io
import itertools
import math
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError
from baseplace.viz.result_view import FloatArray, Motion, ResultView
from baseplace.viz.view_data import (
    MAX_POINTS,
    ViewData,
    _cells,
    cell_quads,
    height_at,
    load_view_data,
    view_data_from,
)

if TYPE_CHECKING:
    import viser

    from baseplace.placement.surface_map import SurfaceMap
    from baseplace.robots.spec import RobotSpec
    from baseplace.world.occupancy import OccupancyGrid

PATH_RGB = (255, 120, 0)
CANDIDATE_RGB = (40, 180, 60)
REJECTED_RGB = (220, 30, 30)
TCP_RGB = (220, 40, 200)
GHOST_RGBA = (0.3, 0.62, 1.0, 0.35)
OBJECT_RGB = (0, 200, 210)
SURFACE_RGB = (150, 110, 230)
MARKER_LIFT = 0.1
"""Candidate and rejected positions are drawn this far above the ground [m]."""
MOTION_STEPS = 8
"""Straight joint-space segments between waypoints are drawn and played in this many steps."""
REGION_LIFT = 0.03
"""Regions are drawn this far above their planes [m], above most of a 25 mm-noise cloud's points."""
HEATMAP_LIFT = 0.045
PATH_LIFT = 0.08


@dataclass(frozen=True)
class SceneInputs:
    """The inputs of a result, loaded.

    Attributes:
        data: the segmented scene (cloud, regions, heights), from view data or the cloud; None
            without a cloud.
        points: (N, 3) float32 world cloud [m], subsampled; empty without a cloud.
        grid: the occupancy grid, if named.
        surface: the surface map, if named.
        image: (H, W, 3) a ``point`` result's RGB image, else None.
        T_world_camera: (4, 4) its camera's pose (OpenCV optical frame) [m], else None.
        fov_y: its camera's vertical field of view [rad], else None.
    """

    data: ViewData | None
    points: NDArray[np.float32]
    grid: OccupancyGrid | None
    surface: SurfaceMap | None
    image: NDArray[np.uint8] | None = None
    T_world_camera: FloatArray | None = None
    fov_y: float | None = None


def load_inputs(view: ResultView, robot_name: str, segment: bool) -> SceneInputs:
    """Load the files ``view`` names; segment the cloud when ``segment`` (regions and ground heights).

    Raises:
        InputError: an input does not load (the library's one-line reasons).
    """
    from baseplace.terrain.io import load_cloud, load_transform

    data = None
    points = np.zeros((0, 3), dtype=np.float32)
    if view.inputs.view_data is not None:
        data = load_view_data(view.inputs.view_data)
        points = data.points
    elif view.inputs.clouds:
        parts = []
        for path, spec in view.inputs.clouds:
            cloud = load_cloud(path)
            parts.append(cloud.transformed(load_transform(spec)).points if spec is not None else cloud.points)
        full = np.concatenate(parts).astype(np.float64)
        if view.inputs.floor is not None:
            from baseplace.placement.pipeline import with_floor

            full = with_floor(full, view.inputs.floor)
        if segment:
            from baseplace.terrain.pipeline import terrain_from_points

            data = view_data_from(terrain_from_points(full), None, full, robot_name)
            points = data.points
        else:
            if len(full) > MAX_POINTS:
                keep = np.sort(np.random.default_rng(0).choice(len(full), MAX_POINTS, replace=False))
                full = full[keep]
            points = full.astype(np.float32)
    grid = None
    if view.inputs.occupancy is not None:
        from baseplace.world.occupancy import load_occupancy

        grid = load_occupancy(view.inputs.occupancy)
    surface = None
    if view.inputs.surface_map is not None:
        from baseplace.placement.surface_storage import load_surface_map

        surface = load_surface_map(view.inputs.surface_map)
    if view.pointing is None:
        return SceneInputs(data, points, grid, surface)
    from baseplace.perception.rgbd import load_rgb, parse_intrinsics

    p = view.pointing
    if p.bag is not None:  # the frame the command read, from its recording (the same limits)
        from baseplace.io.bag import read_rgbd

        rgb_topic, depth_topic, info_topic, world_frame, which = p.bag_topics
        got = read_rgbd(p.bag, rgb_topic, depth_topic, info_topic, world_frame, which)
        image, K, T_world_camera = got.rgb, got.intrinsics, got.T_world_camera
    else:
        assert p.image is not None and p.intrinsics is not None
        image = load_rgb(p.image)  # the command's size and decompression limits
        K = parse_intrinsics(p.intrinsics)
        T_world_camera = load_transform(p.transform) if p.transform is not None else np.eye(4)
    return SceneInputs(
        data, points, grid, surface, image, T_world_camera, 2 * math.atan2(image.shape[0] / 2, K.fy)
    )


def _colormap(name: str, values: NDArray[np.floating]) -> NDArray[np.uint8]:
    from matplotlib import colormaps

    rgba = colormaps[name](np.clip(values, 0.0, 1.0))
    return (np.asarray(rgba)[:, :3] * 255).round().astype(np.uint8)


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


def _wxyz(T: FloatArray) -> NDArray[np.float64]:
    import viser.transforms as vtf

    return np.asarray(vtf.SO3.from_matrix(_orthonormal(T[:3, :3])).wxyz)


def _yaw_rotation(yaw: float) -> FloatArray:
    c, s = math.cos(yaw), math.sin(yaw)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def ground(inputs: SceneInputs, xy: FloatArray) -> FloatArray:
    """Height [m] of the ground under points (N, 2): the segmented scene's, else 0."""
    if inputs.data is not None:
        return height_at(inputs.data, np.asarray(xy, dtype=np.float64).reshape(-1, 2))
    return np.zeros(len(xy))


def occupancy_image(grid: OccupancyGrid) -> NDArray[np.uint8]:
    """(H, W, 3) RGB of an occupancy grid, top row first: free light, occupied dark, unknown grey."""
    v = grid.data.astype(np.int16)
    img = np.empty((*v.shape, 3), dtype=np.uint8)
    occ = np.clip(v, 0, 100)[..., None] / 100.0
    img[:] = np.round(np.array([236, 232, 222]) * (1 - occ) + np.array([45, 45, 50]) * occ).astype(np.uint8)
    img[v < 0] = (185, 185, 185)
    return np.ascontiguousarray(img[::-1])


def _add_grid(api: Any, grid: OccupancyGrid) -> Any:
    """The occupancy grid as an image on the floor (z = 0), rotated by its origin's yaw."""
    w, h = grid.width * grid.resolution, grid.height * grid.resolution
    R = _yaw_rotation(grid.origin[2])
    centre = np.array([*grid.origin[:2], 0.0]) + R @ np.array([w / 2, h / 2, 0.0])
    T = np.eye(4)
    T[:3, :3] = R
    return api.add_image(
        "/occupancy", occupancy_image(grid), w, h, format="png", wxyz=_wxyz(T), position=centre - [0, 0, 0.005],
        cast_shadow=False, receive_shadow=False,
    )  # fmt: skip


def _add_surface(api: Any, surface: SurfaceMap) -> list[Any]:
    """The surface map's R_S (best heading per cell, viridis) on the floor and its working surface."""
    import shapely
    import trimesh

    handles = []
    best = surface.values.max(axis=0)  # (NX, NY)
    i, j = np.nonzero(best > 0)
    if len(i):
        res = surface.resolution
        x0 = surface.origin[0] + i * res - res / 2
        y0 = surface.origin[1] + j * res - res / 2
        cx = np.stack([x0, x0 + res, x0 + res, x0], axis=1)
        cy = np.stack([y0, y0, y0 + res, y0 + res], axis=1)
        verts = np.stack([cx, cy, np.full_like(cx, 0.01)], axis=2).reshape(-1, 3).astype(np.float32)
        base = (np.arange(len(i), dtype=np.uint32) * 4)[:, None]
        faces = (base + np.array([0, 1, 2, 0, 2, 3], dtype=np.uint32)).reshape(-1, 3)
        rgb = _colormap("viridis", best[i, j] / max(float(best.max()), 1e-9))
        rgba = np.repeat(np.c_[rgb, np.full(len(rgb), 255, dtype=np.uint8)], 4, axis=0)
        mesh = trimesh.Trimesh(verts, faces, vertex_colors=rgba, process=False)
        handles.append(
            api.add_mesh_trimesh("/surface_map/heatmap", mesh, cast_shadow=False, receive_shadow=False)
        )
    poly = shapely.Polygon(surface.polygon)
    if poly.is_valid and poly.area > 0:
        v2, f = trimesh.creation.triangulate_polygon(poly, engine="earcut")
        verts = np.c_[v2, np.full(len(v2), surface.height)].astype(np.float32)
        handles.append(
            api.add_mesh_simple(
                "/surface_map/surface", verts, np.asarray(f, dtype=np.uint32), color=SURFACE_RGB, opacity=0.85,
                side="double", cast_shadow=False, receive_shadow=False,
            )
        )  # fmt: skip
    return handles


def _add_scene_data(api: Any, data: ViewData, points: NDArray[np.float32], layers: dict[str, Any]) -> None:
    """Cloud by height, planar regions and the heat map (as the demo's view)."""
    if len(points):
        lo, hi = np.percentile(points[:, 2], [2, 98])
        shade = 0.3 + 0.5 * np.clip((points[:, 2] - lo) / max(float(hi - lo), 1e-6), 0.0, 1.0)
        layers["cloud"] = api.add_point_cloud(
            "/cloud",
            points,
            _colormap("bone", shade),
            point_size=0.015,
            point_shape="rounded",
            precision="float32",
        )
    if data is None:
        return
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


def _add_json_regions(api: Any, view: ResultView) -> list[Any]:
    """The segment result's regions from their outlines in the JSON, on their planes, and the borders."""
    import shapely
    import trimesh

    handles = []
    palette = _colormap("tab20", (np.arange(20) + 0.5) / 20)
    for region in view.regions:
        n = region.plane
        for k, (ext, holes) in enumerate(region.polygons):
            poly = shapely.Polygon(ext, holes)
            if not poly.is_valid or poly.area <= 0:
                poly = poly.buffer(0)
            polys = list(poly.geoms) if poly.geom_type == "MultiPolygon" else [poly]
            for m, part in enumerate(p for p in polys if p.area > 0):
                v2, f = trimesh.creation.triangulate_polygon(part, engine="earcut")
                z = -(n[3] + n[0] * v2[:, 0] + n[1] * v2[:, 1]) / n[2] + REGION_LIFT
                r, g, b = (int(c) for c in palette[(2 * region.id + region.id // 10) % 20])
                handles.append(
                    api.add_mesh_simple(
                        f"/regions/region_{region.id}_{k}_{m}", np.c_[v2, z].astype(np.float32),
                        np.asarray(f, dtype=np.uint32), color=(r, g, b), opacity=0.8, side="double",
                        cast_shadow=False, receive_shadow=False,
                    )
                )  # fmt: skip
    for name, segs, rgb in (
        ("traversable", view.traversable, CANDIDATE_RGB),
        ("blocked", view.blocked, REJECTED_RGB),
    ):
        if len(segs):
            lifted = segs + np.array([0.0, 0.0, PATH_LIFT])
            handles.append(
                api.add_line_segments(f"/borders/{name}", lifted.astype(np.float32), colors=rgb, thickness=5.0,
                                      thickness_units="screen")
            )  # fmt: skip
    return handles


def _arrows(poses: FloatArray, z: FloatArray, length: float) -> NDArray[np.float32]:
    """(N, 2, 3) segments from each base pose (x, y, yaw) along its heading, at heights ``z``."""
    p0 = np.c_[poses[:, :2], z]
    p1 = p0 + np.c_[np.cos(poses[:, 2]), np.sin(poses[:, 2]), np.zeros(len(poses))] * length
    return np.stack([p0, p1], axis=1).astype(np.float32)


@dataclass
class RobotModel:
    """The robot's URDF with meshes (yourdfpy) and where its root sits relative to its base frame."""

    spec: RobotSpec
    urdf: Any
    T_root_base: FloatArray

    def configuration(self, joints: dict[str, float]) -> dict[str, float]:
        """Every actuated joint's value: ``joints``, else the robot's reference values."""
        return joint_configuration(self.spec, joints, list(self.urdf.actuated_joint_names))

    def vector(self, cfg: dict[str, float]) -> NDArray[np.float64]:
        """The actuated joints' values (J,) in the URDF's order."""
        return np.array([cfg[n] for n in self.urdf.actuated_joint_names])

    def T_world_root(self, T_world_base: FloatArray) -> FloatArray:
        """(4, 4) world pose of the URDF's root link when the base frame is at ``T_world_base``."""
        return np.asarray(T_world_base @ np.linalg.inv(self.T_root_base))

    def link_poses(self, T_world_base: FloatArray, cfgs: list[dict[str, float]], link: str) -> FloatArray:
        """(N, 4, 4) world poses of ``link`` at each configuration, by the URDF's forward kinematics."""
        T_root = self.T_world_root(T_world_base)
        out = []
        for cfg in cfgs:
            self.urdf.update_cfg(cfg)
            out.append(
                T_root @ np.asarray(self.urdf.get_transform(link, self.urdf.base_link), dtype=np.float64)
            )
        return np.array(out).reshape(-1, 4, 4)


def load_robot_model(robot: str) -> RobotModel:
    """The robot file's URDF with its meshes (package folders only), for drawing.

    Raises:
        InputError: unknown robot, a mesh outside its package folders, or a URDF that does not load.
    """
    import yourdfpy

    from baseplace.robots.collision import check_mesh_paths
    from baseplace.robots.spec import load_spec
    from baseplace.robots.urdf import robot_urdf

    spec = load_spec(robot)
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
    urdf.update_cfg(joint_configuration(spec, {}, list(urdf.actuated_joint_names)))
    if spec.base_frame in urdf.link_map:
        T_root_base = np.asarray(urdf.get_transform(spec.base_frame, urdf.base_link), dtype=np.float64)
    else:
        T_root_base = np.eye(4)
    return RobotModel(spec, urdf, T_root_base)


def motion_configurations(
    model: RobotModel, final: dict[str, float], motion: Motion
) -> list[dict[str, float]]:
    """Whole-robot configurations along a reaching motion, :data:`MOTION_STEPS` per joint-space segment.

    Joints the motion does not move keep their values in ``final`` (else the reference's).
    """
    rows = motion.waypoints
    dense = [rows[:1]]
    for a, b in itertools.pairwise(rows):
        t = np.arange(1, MOTION_STEPS + 1)[:, None] / MOTION_STEPS
        dense.append(a + t * (b - a))
    stacked = np.concatenate(dense)
    base = model.configuration(final)
    return [{**base, **dict(zip(motion.joint_names, q.tolist(), strict=True))} for q in stacked]


def tcp_frame(model: RobotModel, view: ResultView, motion: Motion | None) -> str | None:
    """The TCP frame of the arm that reaches: the result's arm, else the arm moving the motion's joints."""
    arms = model.spec.arms
    name = view.arm if view.arm in arms else None
    if name is None and motion is not None:
        name = next((a for a, s in arms.items() if set(motion.joint_names) <= set(s.joints)), None)
    if name is None and arms:
        name = next(iter(arms))
    frame = arms[name].tcp_frame if name is not None else None
    return frame if frame in model.urdf.link_map else None


def _add_robot(server: viser.ViserServer, model: RobotModel, T_world_base: FloatArray, cfg: dict[str, float],
               root: str, rgba: tuple[float, float, float, float] | None = None) -> tuple[Any, Any]:  # fmt: skip
    from viser.extras import ViserUrdf

    T = model.T_world_root(T_world_base)
    frame = server.scene.add_frame(root, wxyz=_wxyz(T), position=T[:3, 3], show_axes=False)
    robot = ViserUrdf(server, model.urdf, root_node_name=root, mesh_color_override=rgba)
    robot.update_cfg(model.vector(cfg))
    return frame, robot


def build_scene(
    server: viser.ViserServer, view: ResultView, inputs: SceneInputs, robot: str | None
) -> dict[str, Any]:
    """Add the inputs' and the result's layers to ``server``'s scene.

    Args:
        server: the viser server.
        view: the result.
        inputs: its inputs, loaded (:func:`load_inputs`).
        robot: the robot to draw (name or robot file), or None for no robot meshes.

    Returns:
        layer name -> scene handle(s) (for the GUI toggles and tests); ``"tcp_path"`` also
        carries the drawn TCP positions as ``layers["tcp_points"]`` (M, 3) [m].
    """
    api = server.scene
    api.set_up_direction("+z")
    layers: dict[str, Any] = {}
    if inputs.grid is not None:
        layers["occupancy"] = _add_grid(api, inputs.grid)
    if inputs.surface is not None:
        layers["surface_map"] = _add_surface(api, inputs.surface)
    _add_scene_data(api, inputs.data, inputs.points, layers)  # type: ignore[arg-type]
    if view.regions:
        layers["regions"] = _add_json_regions(api, view)

    for i, T in enumerate(view.targets):
        layers[f"target_{i}"] = api.add_frame(f"/targets/target_{i}", wxyz=_wxyz(T), position=T[:3, 3],
                                              axes_length=0.15, axes_radius=0.012)  # fmt: skip
    if view.object_xyz is not None:
        layers["object"] = api.add_icosphere(
            "/object", radius=0.05, color=OBJECT_RGB, position=tuple(view.object_xyz)
        )

    if view.pointing is not None and inputs.image is not None:
        layers.update(_add_pointing(server, view, inputs))

    paths: list[Any] = []
    for i, poses in enumerate(view.paths):
        xy = densify(poses)
        p3 = np.c_[xy, ground(inputs, xy) + PATH_LIFT]
        if len(p3) >= 2:
            segs = np.stack([p3[:-1], p3[1:]], axis=1).astype(np.float32)
            paths.append(api.add_line_segments(f"/paths/path_{i}", segs, colors=PATH_RGB, thickness=4.0,
                                               thickness_units="screen"))  # fmt: skip
        paths.append(
            api.add_icosphere(f"/paths/start_{i}", radius=0.07, color=PATH_RGB, position=tuple(p3[0]))
        )
    layers["paths"] = paths

    planar = view.kind in ("candidates", "point", "surface_samples", "navigate")  # poses on the ground, no z
    if len(view.candidates):
        z = (
            ground(inputs, view.candidates[:, :2]) + MARKER_LIFT
            if planar
            else np.full(len(view.candidates), MARKER_LIFT)
        )
        rank = np.linspace(1.0, 0.45, len(view.candidates))[:, None]
        rgb = np.round(np.array(CANDIDATE_RGB) * rank + 255 * (1 - rank) * np.array([0.0, 0.35, 0.0])).astype(
            np.uint8
        )
        layers["candidates"] = [
            api.add_point_cloud("/candidates/positions", np.c_[view.candidates[:, :2], z].astype(np.float32),
                                rgb, point_size=0.09, point_shape="circle"),
            api.add_line_segments("/candidates/headings", _arrows(view.candidates, z, 0.25),
                                  colors=np.repeat(rgb[:, None], 2, axis=1), thickness=3.0, thickness_units="screen"),
        ]  # fmt: skip
    if len(view.rejected):
        z = ground(inputs, view.rejected) + MARKER_LIFT
        layers["rejected"] = api.add_point_cloud(
            "/rejected",
            np.c_[view.rejected, z].astype(np.float32),
            REJECTED_RGB,
            point_size=0.06,
            point_shape="circle",
        )

    robot_poses = [
        rp.T_world_base.copy() if not planar else _on_ground(rp.T_world_base, inputs) for rp in view.robots
    ]
    for i, T in enumerate(robot_poses[1:] if view.kind == "place" else [], start=1):
        layers[f"placement_{i}"] = api.add_frame(f"/placements/placement_{i}", wxyz=_wxyz(T), position=T[:3, 3],
                                                 axes_length=0.3, axes_radius=0.015)  # fmt: skip
    if view.robots and robot is not None:
        layers["robot_layer"] = RobotLayer(server, view, robot_poses, load_robot_model(robot), layers)
    return layers


def _add_pointing(server: viser.ViserServer, view: ResultView, inputs: SceneInputs) -> dict[str, Any]:
    """A ``point`` frame: the annotated image on the camera's frustum and in the panel, the objects, the ray."""
    from baseplace.viz.pointing import OBJECT_RGB as BOX_RGB
    from baseplace.viz.pointing import RAY_RGB, SELECTED_RGB, annotated_image

    p = view.pointing
    assert p is not None and inputs.image is not None and inputs.T_world_camera is not None and inputs.fov_y
    api = server.scene
    image = annotated_image(inputs.image, p.landmarks, p.ray_2d, p.image_boxes, p.selected)
    h, w = image.shape[:2]
    T = inputs.T_world_camera
    out: dict[str, Any] = {
        "camera": api.add_camera_frustum("/camera", fov=inputs.fov_y, aspect=w / h, scale=0.2,
                                         image=image, format="jpeg", wxyz=_wxyz(T), position=T[:3, 3]),
        "camera_image": server.gui.add_image(image, label="the frame", format="jpeg"),
    }  # fmt: skip
    boxes = []
    for k, (lo, hi) in enumerate(p.world_boxes):
        chosen = k == p.selected
        boxes.append(
            api.add_box(f"/objects/object_{k}", SELECTED_RGB if chosen else BOX_RGB, tuple(hi - lo),
                        opacity=None if chosen else 0.45, position=tuple((lo + hi) / 2))
        )  # fmt: skip
    out["objects"] = boxes
    if p.ray_3d is not None:
        out["ray"] = api.add_line_segments("/ray", p.ray_3d[None].astype(np.float32), colors=RAY_RGB,
                                           thickness=5.0, thickness_units="screen")  # fmt: skip
    return out


def _on_ground(T: FloatArray, inputs: SceneInputs) -> FloatArray:
    out = T.copy()
    out[2, 3] = float(ground(inputs, T[None, :2, 3])[0])
    return out


class RobotLayer:
    """The robot with its meshes at one of the result's robot poses, and that pose's reaching motion.

    A *Show* drop-down picks the placement or candidate when the result has several; the motion is
    drawn as the TCP's path and translucent copies of the moving links at the start and pre-grasp
    configurations, and played by a slider and a Play button (the robot starts at the grasp).
    """

    def __init__(self, server: viser.ViserServer, view: ResultView, poses: list[FloatArray], model: RobotModel,
                 layers: dict[str, Any]) -> None:  # fmt: skip
        self.server, self.view, self.poses, self.model, self.layers = server, view, poses, model, layers
        for rp in view.robots:
            if rp.motion is not None:
                unknown = sorted(set(rp.motion.joint_names) - set(model.urdf.actuated_joint_names))
                if unknown:
                    raise InputError(
                        f"{view.source}: the motion of {rp.label} moves joints {unknown} that robot "
                        f"{model.spec.name!r} lacks"
                    )
        self.frame: Any = None
        self.urdf: Any = None
        self.cfgs: list[dict[str, float]] = []
        self.motion_nodes: list[Any] = []
        self.lock = threading.Lock()
        self.slider: Any = None
        self.show_motion: Any = None
        if len(view.robots) > 1:
            labels = tuple(rp.label for rp in view.robots)
            pick = server.gui.add_dropdown("Show", labels, initial_value=labels[0])
            pick.on_update(lambda _: self.show(labels.index(pick.value)))
        if any(rp.motion is not None for rp in view.robots):
            with server.gui.add_folder("Reaching motion"):
                self.show_motion = server.gui.add_checkbox("Path and copies", initial_value=True)
                self.slider = server.gui.add_slider("Step", min=0, max=1, step=1, initial_value=1)
                play = server.gui.add_button("Play")
            self.show_motion.on_update(lambda _: self._set_motion_visible(bool(self.show_motion.value)))
            self.slider.on_update(lambda _: self._step(int(self.slider.value)))
            play.on_click(lambda _: self._play())
        self.show(0)

    def show(self, i: int) -> None:
        """Put the robot at robot pose ``i`` in its final configuration and draw that pose's motion."""
        with self.lock:
            rp, T = self.view.robots[i], self.poses[i]
            final = self.model.configuration(rp.joints)
            if self.frame is not None:
                T_root = self.model.T_world_root(T)
                self.frame.wxyz, self.frame.position = _wxyz(T_root), T_root[:3, 3]
                self.urdf.update_cfg(self.model.vector(final))
            self.layers["robot_pose"] = T
            for node in self.motion_nodes:
                node.remove()
            self.motion_nodes = []
            self.layers["ghosts"] = []
            self.layers.pop("tcp_path", None)
            self.layers.pop("tcp_points", None)
            self.cfgs = (
                [final] if rp.motion is None else motion_configurations(self.model, rp.joints, rp.motion)
            )
            if rp.motion is not None:
                self._draw_motion(T, rp.motion)
            if self.frame is None:  # the robot's meshes last: the lighter layers reach the browser first
                self.frame, self.urdf = _add_robot(self.server, self.model, T, final, "/robot")
                self.layers["robot"], self.layers["urdf"] = self.frame, self.urdf
            self.model.urdf.update_cfg(final)
        if self.slider is not None:
            self.slider.max = max(len(self.cfgs) - 1, 1)
            self.slider.value = len(self.cfgs) - 1
        if self.show_motion is not None:
            self._set_motion_visible(bool(self.show_motion.value))

    def _draw_motion(self, T: FloatArray, motion: Motion) -> None:
        scene = self.server.scene
        frame = tcp_frame(self.model, self.view, motion)
        if frame is not None:
            tcp = self.model.link_poses(T, self.cfgs, frame)[:, :3, 3]
            segs = np.stack([tcp[:-1], tcp[1:]], axis=1).astype(np.float32)
            line = scene.add_line_segments("/motion/tcp_path", segs, colors=TCP_RGB, thickness=7.0,
                                           thickness_units="screen")  # fmt: skip
            self.layers["tcp_points"], self.layers["tcp_path"] = tcp, line
            self.motion_nodes.append(line)
        moving = _moving_links(self.model, motion.joint_names)
        for name, k in {"start": 0, "pregrasp": motion.pregrasp * MOTION_STEPS}.items():
            if k < len(self.cfgs) - 1:
                root, copy = _add_robot(
                    self.server, self.model, T, self.cfgs[k], f"/motion/{name}", GHOST_RGBA
                )
                # only what the motion moves: a copy of the still base would tint the robot drawn in it.
                # Mesh nodes are named by their path of links (viser's ViserUrdf keeps them in _meshes).
                meshes = getattr(copy, "_meshes", [])
                for mesh in list(meshes):
                    if not moving.intersection(mesh.name.split("/")):
                        mesh.remove()
                        meshes.remove(mesh)
                self.layers["ghosts"].append(root)
                self.motion_nodes.append(root)  # removing it removes the copy beneath it

    def _set_motion_visible(self, visible: bool) -> None:
        for node in [self.layers.get("tcp_path"), *self.layers.get("ghosts", [])]:
            if node is not None:
                node.visible = visible

    def _step(self, k: int) -> None:
        with self.lock:
            if self.cfgs:
                self.urdf.update_cfg(self.model.vector(self.cfgs[min(k, len(self.cfgs) - 1)]))

    def _play(self) -> None:
        n = len(self.cfgs)
        for k in range(n):
            self.slider.value = k
            time.sleep(2.0 / max(n, 1))


def _moving_links(model: RobotModel, joints: tuple[str, ...]) -> set[str]:
    """The links downstream of ``joints`` in the URDF's tree."""
    children: dict[str, list[str]] = {}
    for j in model.urdf.joint_map.values():
        children.setdefault(j.parent, []).append(j.child)
    todo = [model.urdf.joint_map[j].child for j in joints if j in model.urdf.joint_map]
    out: set[str] = set()
    while todo:
        link = todo.pop()
        if link not in out:
            out.add(link)
            todo.extend(children.get(link, []))
    return out
