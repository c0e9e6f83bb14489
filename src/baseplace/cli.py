"""The ``baseplace`` command.

Every command takes ``--json`` (exactly one JSON object on stdout) and ``--help``; commands with
randomness take ``--seed``. Exit codes: 0 ok, 2 bad input (one ``error: ...`` line on stderr),
3 ran but found nothing.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import re
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from baseplace.errors import BaseplaceError, InputError, NothingFoundError

DEFAULT_CHECKPOINT_EVERY = 50_000_000  # baseplace.reachability.build's, without importing numba for --help


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors and exit code 2."""

    def error(self, message: str) -> NoReturn:
        sys.stderr.write(f"error: {message} (see '{self.prog} --help')\n")
        raise SystemExit(2)


class _Formatter(argparse.HelpFormatter):
    """One line per command in ``baseplace --help``: wide, and room for the longest command name."""

    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=30, width=110)

    def add_argument(self, action: argparse.Action) -> None:
        super().add_argument(action)
        if isinstance(action, argparse._SubParsersAction):  # argparse measures subcommands one indent short
            self._action_max_length += 2


def _count(text: str) -> int:
    """Parse sample counts such as 5e7 or 50000000."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value) or value < 1 or value != int(value):
        raise argparse.ArgumentTypeError(f"must be a positive whole number, got {text!r}")
    return int(value)


def _cell(value: Any, fmt: str, suffix: str = "") -> str:
    """A table cell: ``value`` formatted with ``fmt`` and ``suffix``, or "-" when it is None."""
    return "-" if value is None else format(value, fmt) + suffix


def _int_list(text: str) -> list[int]:
    """Parse "1,2,3" into [1, 2, 3]."""
    try:
        values = [int(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a comma-separated list of integers: {text!r}") from None
    return values


def _finite_float(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return value


OBJECT_HELP = (
    'the grasped object, which only the hand may touch: "auto" (default: the cloud\'s cluster at the '
    'first target\'s grasp point, above its support), "none", "box CX CY CZ SX SY SZ [YAW]", '
    '"cylinder CX CY CZ RADIUS HEIGHT" [m, rad] or "points FILE" (the object\'s cloud), world frame'
)


def _nonneg_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


def _emit(args: argparse.Namespace, obj: dict[str, Any], text: str) -> None:
    if args.json:
        sys.stdout.write(json.dumps(obj) + "\n")
    else:
        sys.stdout.write(text.rstrip("\n") + "\n")


def _progress(args: argparse.Namespace, total: int, desc: str) -> tuple[Callable[[int], None] | None, Any]:
    """A progress callback for long steps; the bar appears on the first update (silent with --json)."""
    if args.json:
        return None, None
    from tqdm import tqdm

    class _LazyBar:
        bar: Any = None

        def update(self, done: int) -> None:
            if self.bar is None:
                self.bar = tqdm(
                    total=total, desc=desc, unit="samples", unit_scale=True, file=sys.stderr, leave=False
                )
            self.bar.update(done - self.bar.n)

        def close(self) -> None:
            if self.bar is not None:
                self.bar.close()

    lazy = _LazyBar()
    return lazy.update, lazy


def _default_map(args: argparse.Namespace, robot: Any, arm: str | None = None) -> Any:
    """The robot's cached default map, built on first use (tens of seconds) behind a progress bar."""
    from baseplace.demo import cached_map
    from baseplace.reachability.build import BuildSettings

    settings = BuildSettings()
    update, bar = _progress(args, settings.samples, f"default {robot.name} map (first run only)")
    try:
        return cached_map(robot, settings, arm, update)[0]
    finally:
        if bar is not None:
            bar.close()


MAP_SUFFIXES = (".rmap", ".h5", ".hdf5")
SURFACE_SUFFIXES = (".smap", ".h5", ".hdf5")
PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def _out_path(text: str | None, suffixes: Sequence[str] = PLOT_SUFFIXES, what: str = "--out") -> Path | None:
    """The output path, or None; checked (length, type, suffix, writable directory) before any work."""
    from baseplace.guards import check_output_path

    return None if text is None else check_output_path(text, what, suffixes)


def _step_progress(update: Callable[[int], None] | None) -> Callable[[int], None]:
    """Turn an absolute-progress callback into one that is told how many steps just finished."""
    done = 0

    def step(k: int) -> None:
        nonlocal done
        done += k
        if update is not None:
            update(done)

    return step


def _set_workers(workers: int | None) -> None:
    if workers is None:
        return
    import numba

    cores = os.cpu_count() or 1
    limit = int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
    if not (1 <= workers <= limit):
        raise InputError(
            f"--workers must be between 1 and {limit} (this machine has {cores} cores), got {workers}"
        )
    numba.set_num_threads(workers)


def cmd_robots(args: argparse.Namespace) -> int:
    """List the built-in robots."""
    from baseplace.robots.spec import BUILTIN_ROBOTS, builtin_spec

    rows: list[dict[str, Any]] = []
    for name in BUILTIN_ROBOTS:
        spec = builtin_spec(name)
        rows.append({
            "name": name,
            "urdf": str(spec.urdf),
            "base_frame": spec.base_frame,
            "default_arm": spec.default_arm,
            "arms": {a: {"joints": list(s.joints), "tcp_frame": s.tcp_frame, "approach": s.approach}
                     for a, s in spec.arms.items()},
            "footprint": {"radius": spec.footprint_radius} if spec.footprint_radius is not None
            else {"polygon": [list(p) for p in spec.footprint_polygon or ()]},
        })  # fmt: skip
    lines = []
    for name in BUILTIN_ROBOTS:
        spec = builtin_spec(name)
        arms = ", ".join(f"{a} (TCP {s.tcp_frame}, {len(s.joints)} joints)" for a, s in spec.arms.items())
        lines.append(f"{name:<11} base {spec.base_frame}; arms {arms}")
    lines.append(
        "custom robots: pass --robot path/to/robot.toml; check one with `baseplace robot check` (docs/robots.md)"
    )
    _emit(args, {"robots": rows}, "\n".join(lines))
    return 0


def cmd_robot_check(args: argparse.Namespace) -> int:
    """Load a robot file, describe it, render it and warn where it looks wrong."""
    from baseplace.robots.check import check_robot, collision_meshes
    from baseplace.robots.collision import load_collision_model
    from baseplace.robots.model import Robot
    from baseplace.viz.robot import plot_robot

    png = _out_path(args.png)  # checked before the robot loads
    robot = Robot(args.robot)
    if png is None:  # the robot's name as a plain file name in this folder
        png = Path(re.sub(r"[^A-Za-z0-9_.-]", "_", robot.name).lstrip(".") + "_check.png")
    report = check_robot(robot)
    plot_robot(robot, collision_meshes(robot, load_collision_model(robot)), png)
    obj = {**report.to_dict(), "png": str(png)}
    fp = report.footprint
    lines = [
        f"robot {report.name}: URDF {report.urdf}",
        f"base frame {report.base_frame}; footprint "
        + (f"radius {fp['radius']} m" if "radius" in fp else f"polygon {fp['polygon']}")
        + (
            f"; meshes fixed to the base reach {fp['base_mesh_radius']} m from its origin"
            if "base_mesh_radius" in fp
            else ""
        ),
    ]
    if report.mount is not None:
        lines.append(f"arm mounted at xyz {report.mount['xyz']} rpy {report.mount['rpy']}, "
                     f"base body up to {report.mount['base_height']} m")  # fmt: skip
    for name, arm in report.arms.items():
        lines.append(f"arm {name!r}: TCP {arm['tcp_frame']}, approach axis {arm['approach']} "
                     f"(at the reference configuration: TCP at {arm['tcp_at_reference']}, approach "
                     f"{arm['approach_in_base_at_reference']} in {report.base_frame})")  # fmt: skip
        lines += [
            f"  {j['name']:<24} {j['type']:<10} [{j['lower']:.4g}, {j['upper']:.4g}]" for j in arm["joints"]
        ]
    col = report.collision
    lines.append(f"collision: {col['geometries']} geometries, {col['pairs']} active self-collision pairs "
                 f"({'SRDF ' + col['srdf'] if col['srdf'] else 'pruned as MoveIt does, no SRDF'})"
                 + ("" if args.pairs else "; --pairs lists them"))  # fmt: skip
    if args.pairs:
        lines += [f"  {a} - {b}" for a, b in col["pair_names"]]
    lines.append(f"wrote {png}")
    lines += [f"warning: {w}" for w in report.warnings] or ["no warnings"]
    _emit(args, obj, "\n".join(lines))
    return 0


def cmd_build_map(args: argparse.Namespace) -> int:
    """Build a map and save it."""
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.reachability.checkpoint import default_checkpoint_path
    from baseplace.robots.model import Robot

    if args.scheduler is None:
        _set_workers(args.workers)
    out = _out_path(args.out, MAP_SUFFIXES)
    assert out is not None  # --out is required
    settings = BuildSettings(
        samples=args.samples, seed=args.seed, voxel_size=args.voxel_size,
        orientation_resolution=args.orientation_resolution,
        self_collision=args.self_collision, manipulability=args.manipulability,
    )  # fmt: skip
    robot = Robot(args.robot)
    robot.arm(args.arm)  # validate before spending time
    checkpoint = None if args.no_resume else default_checkpoint_path(out)
    if checkpoint is not None and checkpoint.exists() and not args.json:
        sys.stderr.write(f"resuming from checkpoint {checkpoint}\n")
    update, bar = _progress(args, settings.samples, f"build-map {robot.name}")
    try:
        if args.scheduler is not None:
            import distributed  # noqa: F401  (it sets its loggers' levels on import)

            from baseplace.files import output_lock, remove_stray_temporaries

            for name in [
                "distributed",
                "asyncio",
                *logging.root.manager.loggerDict,
            ]:  # faults: one line of ours
                if name.startswith(("distributed", "asyncio")):
                    logging.getLogger(name).setLevel(logging.CRITICAL)
            from baseplace.reachability.distributed import build_map_distributed, connect

            with output_lock(out), connect(args.scheduler, n_workers=args.workers) as client:
                remove_stray_temporaries(out)
                rmap = build_map_distributed(args.robot, args.arm, settings, client, update, checkpoint,
                                             args.checkpoint_every, save_to=out)  # fmt: skip
        else:  # saved before the checkpoint goes; a second build to the same --out waits for this one
            rmap = build_map(
                robot, args.arm, settings, update, checkpoint, args.checkpoint_every, save_to=out
            )
    except KeyboardInterrupt:
        if checkpoint is None or not checkpoint.exists():
            raise
        sys.stderr.write(
            f"error: interrupted; progress saved in {checkpoint}: rerun the same command to resume\n"
        )
        return 130
    finally:
        if bar is not None:
            bar.close()
    size = out.stat().st_size
    info = rmap.info
    rate = info.samples / info.build_time_s if info.build_time_s > 0 else float("nan")
    obj = {
        "out": str(out), "robot": info.robot, "arm": info.arm, "samples": info.samples,
        "seed": info.seed, "cells_reached": rmap.n_reached, "build_time_s": round(info.build_time_s, 3),
        "samples_per_s": round(rate), "file_bytes": size,
        "dropped_self_collision": info.dropped_self_collision,
    }  # fmt: skip
    _emit(args, obj, f"wrote {out}: {rmap.n_reached} cells reached by {info.samples:.3g} samples "
                     f"in {info.build_time_s:.1f} s ({rate / 1e6:.2f} M samples/s), {size / 1e6:.1f} MB")  # fmt: skip
    return 0


def _read_pose_file(path: str, width: int, what: str) -> np.ndarray:
    p = Path(path)
    if not p.is_file():
        raise InputError(f"{what} file {p} does not exist")
    rows = []
    for lineno, line in enumerate(p.read_text().splitlines(), 1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        parts = text.replace(",", " ").split()
        try:
            values = [float(v) for v in parts]
        except ValueError:
            raise InputError(f"{p}:{lineno}: {what} must be numbers, got {text!r}") from None
        if len(values) != width:
            raise InputError(f"{p}:{lineno}: a {what} needs {width} numbers, got {len(values)}")
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"{p}:{lineno}: {what} contains NaN or infinity")
        rows.append(values)
    if not rows:
        raise InputError(f"{what} file {p} holds no poses")
    return np.array(rows)


def cmd_reach(args: argparse.Namespace) -> int:
    """Print inverse-reachability values."""
    from baseplace.geometry.poses import BasePose, parse_base_pose, parse_pose6, pose_from_xyz_rpy
    from baseplace.reachability.storage import check_map_matches, load_map

    if (args.target is None) == (args.targets is None):
        raise InputError("give exactly one of --target or --targets FILE")
    if (args.base is None) == (args.bases is None):
        raise InputError("give exactly one of --base or --bases FILE")
    rmap = load_map(args.map)
    if args.robot is not None:
        from baseplace.robots.model import Robot

        check_map_matches(rmap, Robot(args.robot), rmap.info.arm, args.map)
    targets = (parse_pose6(args.target)[None] if args.target is not None
               else pose_from_xyz_rpy(_read_pose_file(args.targets, 6, "target pose")))  # fmt: skip
    bases = (parse_base_pose(args.base).matrix()[None] if args.base is not None
             else BasePose.batch_matrix(_read_pose_file(args.bases, 3, "base pose")))  # fmt: skip
    if len(targets) != len(bases) and len(targets) != 1:
        raise InputError(
            f"--targets has {len(targets)} poses but --bases has {len(bases)}; they pair row by row"
        )
    if len(targets) == 1:
        values = rmap.inverse(targets[0], bases)
    else:
        from baseplace.geometry.poses import invert_transforms

        values = rmap.reachability(invert_transforms(bases) @ targets)
    vals = [round(float(v), 6) for v in values]
    _emit(args, {"values": vals}, "\n".join(f"{v:.6g}" for v in vals))
    return 0


def cmd_demo(args: argparse.Namespace) -> int:
    """Run the demo: segmentation, OSRM, a verified placement on a platform and the path up its ramp."""
    from baseplace.demo import run_demo
    from baseplace.guards import check_path_length

    check_path_length(str(Path(args.out) / "demo.json"), "--out")
    update, bar = _progress(args, args.samples, "default TIAGo map (first run only)")
    try:
        result = run_demo(Path(args.out), samples=args.samples, seed=args.seed, progress=update)
    finally:
        if bar is not None:
            bar.close()
    p, route, t = result["placement"], result["path"], result["timings_ms"]
    text = (
        f"map {result['map']['path']} ({'built' if result['map']['built_now'] else 'cached'})\n"
        f"{result['regions']} planar regions; verified placement on region {p['region']} "
        f"(tilt {p['region_tilt_deg']:.1f} deg): x={p['x']:.2f} y={p['y']:.2f} z={p['z']:.2f} yaw={p['yaw']:.2f}\n"
        f"path from {result['start']}: {route['length']:.2f} m through regions {route['regions']}\n"
        f"segmentation {t['segmentation']:.0f} ms, OSRM {t['osrm']:.0f} ms, query {t['query']:.0f} ms, "
        f"path {t['path']:.0f} ms, total {t['total'] / 1e3:.1f} s\n"
        f"wrote {args.out}/demo.json and {result['png']}"
    )
    _emit(args, result, text)
    return 0


def cmd_view(args: argparse.Namespace) -> int:
    """Serve the interactive 3D viewer of a result (the demo's by default) until Ctrl-C."""
    from baseplace.viz.viewer import serve

    if not (0 <= args.port <= 65535):
        raise InputError(f"--port must be between 0 and 65535, got {args.port}")
    serve(Path(args.result) if args.result else None, host=args.host, port=args.port, block=True)
    return 0


def _add_bag_args(p: argparse.ArgumentParser, clouds: bool = True, grid: bool = True) -> None:
    """``--bag`` and its topic options, the same on every command that reads a cloud or a grid."""
    g = p.add_argument_group("ROS recording (rosbag2 directory, .db3, .mcap, or ROS 1 .bag)")
    g.add_argument("--bag", default=None, help="read the inputs from this recording instead of files")
    if clouds:
        g.add_argument("--cloud-topic", action="append", default=None,
                       help="sensor_msgs/PointCloud2 topic, posed by /tf and /tf_static at its stamp; repeat for several")  # fmt: skip
        g.add_argument("--bag-clouds", default="last", choices=["last", "first", "all"],
                       help="which messages of each cloud topic (default last)")  # fmt: skip
    if grid:
        g.add_argument("--map-topic", default=None, help="nav_msgs/OccupancyGrid topic (its last message)")
    g.add_argument("--world-frame", default="map", help="frame of the results (default map)")


def _bag(args: argparse.Namespace, need_cloud: bool, need_grid: bool) -> Any:
    """The recording's scene for ``--bag``, or None without it."""
    if getattr(args, "bag", None) is None:
        return None
    if getattr(args, "_bag_scene", None) is not None:
        return args._bag_scene
    from baseplace.io.bag import read_bag

    topics = getattr(args, "cloud_topic", None) or []
    if need_cloud and not topics:
        raise InputError("with --bag, give the cloud topic: --cloud-topic /camera/points")
    map_topic = getattr(args, "map_topic", None)
    if need_grid and map_topic is None:
        raise InputError("with --bag, give the map topic: --map-topic /map")
    args._bag_scene = read_bag(
        args.bag, topics, map_topic, args.world_frame, getattr(args, "bag_clouds", "last")
    )
    return args._bag_scene


def _world_cloud(args: argparse.Namespace) -> Any:
    """The cloud of ``--cloud`` (or ``--bag``) in the world frame: through ``--transform`` or tf, or checked z-up."""
    from baseplace.terrain.diagnose import check_up_direction
    from baseplace.terrain.io import Cloud, load_cloud, load_transform

    scene = _bag(args, need_cloud=True, need_grid=False)
    if scene is not None:
        source = f"{args.bag} {' '.join(args.cloud_topic)}"
        if getattr(args, "fuse", False):
            return _fused([(c.world_points, c.T_world_sensor[:3, 3]) for c in scene.clouds], args, source)
        return Cloud(scene.world_points(), source=source)
    if args.cloud is None:
        raise InputError("give --cloud FILE or --bag FILE --cloud-topic TOPIC")
    paths = args.cloud if isinstance(args.cloud, list) else [args.cloud]
    transforms = args.transform if isinstance(args.transform, list) else [args.transform]
    if len(paths) > 1 and len(transforms) not in (0, len(paths)) and transforms != [None]:
        raise InputError(
            f"give one --transform per --cloud ({len(paths)} clouds, {len(transforms)} transforms)"
        )
    clouds, origins = [], []
    for k, path in enumerate(paths):
        cloud = load_cloud(path)
        spec = transforms[k] if len(transforms) == len(paths) else transforms[0] if len(paths) == 1 else None
        origins.append(np.zeros(3))
        if spec is not None:
            T = load_transform(spec)
            cloud = cloud.transformed(T)
            origins[-1] = T[:3, 3]
        else:
            check_up_direction(
                cloud.points, optical=cloud.width is not None and cloud.height not in (None, 1)
            )
        clouds.append(cloud)
    if getattr(args, "fuse", False):
        return _fused([(c.points, o) for c, o in zip(clouds, origins, strict=True)], args, " ".join(paths))
    if len(clouds) == 1:
        return clouds[0]
    return Cloud(np.vstack([c.points for c in clouds]), source=" ".join(paths))


def _fused(clouds: list[tuple[np.ndarray, np.ndarray]], args: argparse.Namespace, source: str) -> Any:
    """World clouds with their sensor origins fused into one OctoMap (seed 000); its occupied voxels."""
    from baseplace.terrain.fusion import FusionSettings, PosedCloud, fuse_clouds
    from baseplace.terrain.io import Cloud

    save = _out_path(getattr(args, "fused_out", None), (".bt",), "--fused-out")
    points = fuse_clouds(
        [PosedCloud(p, o) for p, o in clouds], FusionSettings(prob_miss=args.fuse_miss), save
    )
    return Cloud(points, source=f"OctoMap of {source}")


def _add_fuse_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("fusion (seed 000: the clouds into one OctoMap by ray casting)")
    g.add_argument("--fuse", action="store_true",
                   help="fuse the clouds (every --cloud, or the bag's clouds) into a 25 mm OctoMap, rays from each sensor origin")  # fmt: skip
    g.add_argument("--fuse-miss", type=float, default=0.35,
                   help="occupancy probability of a ray passing a voxel (default 0.35; octomap's own: 0.4)")  # fmt: skip
    g.add_argument("--fused-out", default=None, help="also write the fused OctoMap (.bt)")


def _grid(args: argparse.Namespace, option: str = "occupancy") -> Any:
    """The occupancy grid of ``--occupancy`` (or ``--bag --map-topic``), or None without either."""
    from baseplace.world.occupancy import load_occupancy

    if getattr(args, "bag", None) is not None and getattr(args, "map_topic", None) is not None:
        return _bag(args, need_cloud=False, need_grid=True).grid
    path = getattr(args, option, None)
    return None if path is None else load_occupancy(path)


def cmd_segment(args: argparse.Namespace) -> int:
    """Segment a cloud into planar regions."""
    from baseplace.terrain.pipeline import terrain_from_points, terrain_json

    out = _out_path(args.out)
    cloud = _world_cloud(args)
    terrain = terrain_from_points(cloud.points, args.algorithm, args.resolution)
    result = terrain_json(terrain)
    result["cloud"] = {"path": str(args.cloud or args.bag), "points": len(cloud.points)}
    result["algorithm"] = args.algorithm
    result["resolution"] = terrain.segmentation.hmap.resolution
    if out is not None:
        from baseplace.viz.regions import plot_regions

        plot_regions(terrain.segmentation, terrain.graph, out)
        result["png"] = str(out)
    lines = [f"{len(result['regions'])} planar regions from {len(cloud.points)} points at "
             f"{result['resolution']:g} m cells ({result['timings_ms']['total']:.0f} ms, {args.algorithm})"]  # fmt: skip
    for r in result["regions"]:
        lines.append(f"  region {r['id']}: tilt {r['tilt_deg']:.1f} deg, area {r['area_m2']:.2f} m^2, "
                     f"centroid z {r['centroid'][2]:.3f} m")  # fmt: skip
    trav = sum(e["traversable"] for e in result["edges"])
    lines.append(f"{len(result['edges'])} border edges, {trav} traversable")
    if out is not None:
        lines.append(f"wrote {out}")
    _emit(args, result, "\n".join(lines))
    return 0


def cmd_scene_generate(args: argparse.Namespace) -> int:
    """Generate a random test scene with ground truth."""
    from baseplace.sim.scenes import SceneSettings, generate_scene, save_scene
    from baseplace.terrain.io import Cloud, save_cloud

    _out_path(args.out, (".ply", ".pcd", ".npy"))
    _out_path(args.truth, (".json",), "--truth")
    settings = SceneSettings(size_class=args.size_class, n_planes=args.planes, sigma=args.sigma,
                             extent=(args.extent, args.extent), with_box=not args.no_box)  # fmt: skip
    rng = np.random.default_rng(args.seed)
    scene = generate_scene(settings, rng)
    points = scene.sample_cloud(rng)
    save_cloud(Cloud(points, source="baseplace scene generate"), args.out)
    truth = args.truth or str(Path(args.out).with_suffix(".json"))
    save_scene(scene, truth)
    obj = {"cloud": args.out, "truth": truth, "points": len(points), "planes": len(scene.planes) - 1,
           "seed": args.seed, "size_class": args.size_class}  # fmt: skip
    _emit(args, obj, f"wrote {args.out} ({len(points)} points) and {truth} "
                     f"({len(scene.planes) - 1} {args.size_class} planes, seed {args.seed})")  # fmt: skip
    return 0


def cmd_place(args: argparse.Namespace) -> int:
    """Find verified base placements for the targets in a scanned scene."""
    from baseplace.demo import cached_map
    from baseplace.geometry.poses import matrix_to_rpy, parse_pose6
    from baseplace.placement.pipeline import PlaceSettings, place, with_floor
    from baseplace.placement.verify import contact_summary, most_frequent_contact
    from baseplace.reachability.build import BuildSettings
    from baseplace.reachability.storage import load_map
    from baseplace.robots.model import Robot
    from baseplace.world.grasped_object import parse_grasped_object

    if not args.target:
        raise InputError('give at least one --target "x y z roll pitch yaw"')
    targets = np.stack([parse_pose6(t) for t in args.target])
    grasped = parse_grasped_object(args.object)
    settings = PlaceSettings(strategy=args.strategy, placements=args.placements, tries=args.tries,
                             resolution=args.resolution, motion=_motion_settings(args),
                             robustness=_robustness_settings(args))  # fmt: skip
    out = _out_path(args.out)
    mcap = _out_path(args.mcap, (".mcap",), "--mcap")
    robot = Robot(args.robot)
    cloud = _world_cloud(args) if args.cloud is not None or (args.bag and args.cloud_topic) else None
    grid = _grid(args)
    if cloud is None and grid is None:
        raise InputError(
            "give --cloud FILE, --occupancy MAP.yaml, or --bag FILE with --cloud-topic/--map-topic"
        )
    points = None
    if cloud is not None:
        points = cloud.points if args.floor is None else with_floor(cloud.points, args.floor)
    if args.map is not None:
        rmap = load_map(args.map, robot, args.arm)
    else:
        update, bar = _progress(args, 50_000_000, f"default {robot.name} map (first run only)")
        try:
            rmap, _, _ = cached_map(robot, BuildSettings(), args.arm, update)
        finally:
            if bar is not None:
                bar.close()
    terrain = navmap = start = None
    if args.start is not None:
        from baseplace.navigation.navmap import navigation_map
        from baseplace.terrain.pipeline import terrain_from_points

        start = _base_xyyaw(args.start)
        if grid is None:
            assert points is not None  # a cloud or a grid was given
            terrain = terrain_from_points(points, resolution=args.resolution)
            navmap = navigation_map(terrain, robot.spec.footprint_bounding_radius)
            navmap.check_pose("--start", start[:2])
    if grid is not None:
        from baseplace.placement.in_map import place_in_map

        clouds = [] if points is None else [points]
        result = place_in_map(robot, rmap, clouds, grid, targets, settings, np.random.default_rng(args.seed),
                              grasped=grasped)  # fmt: skip
    else:
        assert points is not None
        result = place(robot, rmap, points, targets, settings, np.random.default_rng(args.seed), terrain=terrain,
                       grasped=grasped)  # fmt: skip
    arm = robot.arm(rmap.info.arm)
    if grid is not None and start is not None:  # on the navigation map, around what the cameras see
        from baseplace.placement.in_map import grid_routes

        goals = [(p.T_world_base[0, 3], p.T_world_base[1, 3], p.yaw) for p in result.placements]
        paths = grid_routes(grid, [] if cloud is None else [cloud.points], start, goals,
                            robot.spec.footprint_bounding_radius)  # fmt: skip
        result.failures["no_path"] += sum(r is None for r in paths)
        kept = [p for p, r in zip(result.placements, paths, strict=True) if r is not None]
        routes: list[Any] = [r for r in paths if r is not None]
    else:
        kept, routes = _routes(result.placements, navmap, start, args.planner, args.seed, result.failures)
    placements = []
    for p, route in zip(kept, routes, strict=True):
        T = p.T_world_base
        placements.append({
            "base_pose": np.round(T, 6).tolist(), "x": round(float(T[0, 3]), 4), "y": round(float(T[1, 3]), 4),
            "z": round(float(T[2, 3]), 4), "yaw": round(p.yaw, 4),
            "roll_pitch_yaw": [round(float(v), 5) for v in matrix_to_rpy(T[:3, :3])],
            "region": p.region, "reachability": round(p.reachability, 5),
            "joints": [dict(zip(p.joint_names, np.round(q, 6).tolist(), strict=True)) for q in p.joints],
            **_motion_and_robustness_json(p.motions, p.robustness),
        })  # fmt: skip
        if route is not None:
            placements[-1]["path"] = {"poses": np.round(route.poses, 4).tolist(), "length": round(route.length, 3),
                                      "planner": route.planner, "time_ms": round(route.time_ms, 1)}  # fmt: skip
    obj = {
        "robot": {"name": robot.name, "urdf": str(robot.spec.urdf), "base_frame": robot.spec.base_frame,
                  "tcp_frames": {a: s.tcp_frame for a, s in robot.spec.arms.items()}, "arm": arm.name},
        "strategy": args.strategy, "seed": args.seed, "targets": args.target,
        "placements": placements,
        "tries": result.tries,
        "failures": dict(result.failures),
        "collisions": contact_summary(result.contacts),
        "object": {"requested": args.object, "found": result.grasped_note,
                   "allowed": None if result.grasped is None else result.grasped.to_json()},
        "floor": args.floor,
        "timings_ms": {k: round(v, 2) for k, v in _place_timings(result.timings_ms, terrain, routes).items()},
        "regions": len(result.terrain.segmentation.regions),
    }  # fmt: skip
    if out is not None:
        from baseplace.terrain.polygons import footprint_outline
        from baseplace.viz.placement import plot_placement

        outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
        plot_placement(result.osrm, kept, outline, out,
                       f"{robot.name}, {args.strategy}: {len(placements)} placement(s) in {result.tries} tries",
                       [r.poses for r in routes if r is not None], result.rejected, result.contacts,
                       result.grasped)  # fmt: skip
        obj["png"] = str(out)
    if mcap is not None:
        _write_mcap(mcap, args, result.terrain, placements=[p.T_world_base for p in kept],
                    candidates=[p.T_world_base for p in kept], paths=[r.poses for r in routes if r is not None],
                    targets=list(targets))  # fmt: skip
        obj["mcap"] = str(mcap)
    if not placements and result.placements:
        raise NothingFoundError(
            f"none of the {len(result.placements)} verified placement(s) can be driven to from --start "
            f"{args.start} ({args.planner} planner); ask for more with --placements"
        )
    if not placements:
        if args.json:  # the counts per reason and per link, for the caller
            _emit(args, obj, "")
        worst = most_frequent_contact(result.contacts)
        raise NothingFoundError(
            f"no verified placement in {result.tries} tries with {args.strategy} "
            f"(failures: {dict(result.failures) or 'none'}{'; ' + worst if worst else ''}); "
            f"try --tries, another --strategy, --object or check the target"
        )
    lines = [f"{len(placements)} verified placement(s) in {result.tries} tries ({args.strategy}, "
             f"{result.timings_ms['total']:.0f} ms)"]  # fmt: skip
    for row in placements:
        lines.append(f"  x={row['x']:.3f} y={row['y']:.3f} z={row['z']:.3f} yaw={row['yaw']:.3f} "
                     f"region {row['region']} reachability {row['reachability']:.3f}{_robust_text(row)}")  # fmt: skip
    if out is not None:
        lines.append(f"wrote {out}")
    if mcap is not None:
        lines.append(f"wrote {mcap}")
    _emit(args, obj, "\n".join(lines))
    return 0


def _write_mcap(path: Path, args: argparse.Namespace, terrain: Any = None, **poses: Any) -> None:
    """Results as an MCAP recording (io.results): ``poses`` are ResultMessages fields; regions from ``terrain``."""
    from baseplace.io.results import ResultMessages, write_result_mcap

    scene = getattr(args, "_bag_scene", None)
    stamp = max((c.stamp_ns for c in scene.clouds), default=0) if scene is not None else 0
    regions = []
    if terrain is not None:
        for r in terrain.segmentation.regions:
            poly = terrain.graph.nodes[r.id]["polygon"]
            rings = []
            for p in list(poly.geoms) if poly.geom_type == "MultiPolygon" else [poly]:
                for ring in [p.exterior, *p.interiors]:
                    xy = np.asarray(ring.coords)
                    if len(xy):
                        rings.append(np.c_[xy, r.height_at(xy)])
            regions.append((r.id, rings))
    write_result_mcap(path, ResultMessages(args.world_frame, stamp, regions=regions, **poses))


def _motion_settings(args: argparse.Namespace) -> Any:
    """The reaching-motion check of --no-motion-check (None: off)."""
    from baseplace.placement.motion import MotionSettings

    return None if args.no_motion_check else MotionSettings()


def _robustness_settings(args: argparse.Namespace) -> Any:
    """Robustness settings from the --robustness-* and error-model options."""
    from baseplace.placement.robustness import BaseErrorModel, RobustnessSettings

    error = BaseErrorModel(args.error_model, args.sigma_xy, math.radians(args.sigma_yaw_deg),
                           args.xy_tolerance, args.yaw_tolerance)  # fmt: skip
    return RobustnessSettings(args.robustness_samples, error,
                              "robustness" if args.rank_by_robustness else "reachability",
                              args.min_robustness, seed=args.seed)  # fmt: skip


def _motion_and_robustness_json(motions: Any, robustness: Any) -> dict[str, Any]:
    """The joint waypoints of each target's reaching motion and the robustness score, if any."""
    out: dict[str, Any] = {}
    if motions is not None:
        out["motion"] = [{"path": np.round(m.path, 5).tolist(), "approach": np.round(m.approach, 5).tolist(),
                          "planned": m.planned} for m in motions]  # fmt: skip
    if robustness is not None:
        out["robustness"] = robustness.as_dict()
    return out


def _robust_text(row: dict[str, Any]) -> str:
    r = row.get("robustness")
    return "" if r is None else f" robustness {r['rate']:.2f} [{r['ci95'][0]:.2f}, {r['ci95'][1]:.2f}]"


def _place_timings(timings: dict[str, float], terrain: Any, routes: list[Any]) -> dict[str, float]:
    """Placement timings [ms], with the segmentation and path planning done for --start."""
    out = dict(timings)
    if terrain is not None:
        out["segmentation"] = terrain.timings_ms["total"]
        out["navigation"] = sum(r.time_ms for r in routes)
        out["total"] = timings["total"] + out["segmentation"] + out["navigation"]
    return out


def _base_xyyaw(text: str) -> np.ndarray:
    from baseplace.geometry.poses import parse_base_pose

    p = parse_base_pose(text)
    return np.array([p.x, p.y, p.yaw])


def _routes(
    placements: list[Any], navmap: Any, start: Any, planner: str, seed: int, failures: Any
) -> tuple[list[Any], list[Any]]:
    """The placements the base can drive to from ``start``, with their paths (all, without a start)."""
    if navmap is None:
        return placements, [None] * len(placements)
    from baseplace.navigation.planners import plan_path

    kept, routes = [], []
    for p in placements:
        T = p.T_world_base
        try:
            route = plan_path(navmap, start, np.array([T[0, 3], T[1, 3], p.yaw]), planner, seed=seed)
        except BaseplaceError:
            failures["no_path"] += 1
            continue
        kept.append(p)
        routes.append(route)
    return kept, routes


def cmd_candidates(args: argparse.Namespace) -> int:
    """Seed 004: base placement candidates from an object position, a cloud and an occupancy grid."""
    from baseplace.geometry.poses import BasePose
    from baseplace.placement.candidates import RadialSettings, motion_costs, radial_search
    from baseplace.placement.irm_candidates import (
        IrmSettings,
        grasp_poses,
        grasp_standoff,
        irm_candidates,
        verify_candidates,
    )
    from baseplace.reachability.storage import load_map
    from baseplace.robots.model import Robot
    from baseplace.terrain.voxels import VoxelMap
    from baseplace.world.environment import Environment, contact_groups
    from baseplace.world.grasped_object import GraspedObject, find_grasped_object, parse_grasped_object
    from baseplace.world.gridnav import GridNavigator

    out = _out_path(args.png, what="--png")
    mcap = _out_path(args.mcap, (".mcap",), "--mcap")
    robust = _robustness_settings(args)
    p_o = _parse_xyz(args.object, "--object")
    robot_pose = _base_xyyaw(args.robot_pose) if args.robot_pose is not None else None
    grid = _grid(args)
    if grid is None:
        raise InputError("give --occupancy MAP.yaml or --bag FILE --map-topic TOPIC")
    robot = Robot(args.robot)
    rmap = load_map(args.map, robot, args.arm) if args.map else _default_map(args, robot, args.arm)
    settings = RadialSettings.for_robot(robot, rmap)
    _check_object(grid, p_o, settings.d_max)
    points = None
    if args.cloud is not None or (args.bag and args.cloud_topic):
        points = _world_cloud(args).points
    # the shared verification: IK for one of the grasps, whole robot against the cloud's voxels;
    # only the hand may touch the object's own (found at --object or given by --object-shape)
    shape = parse_grasped_object(args.object_shape, "--object-shape")
    grasped = shape if shape != "auto" else None
    if shape == "auto" and points is not None:
        grasped = find_grasped_object(points, p_o)
    voxels = VoxelMap(0.025, np.zeros((0, 3), dtype=np.int64))
    if points is not None:
        voxels = VoxelMap.from_points(points)
    groups, object_voxels = contact_groups(
        voxels, voxels, grasped if isinstance(grasped, GraspedObject) else None
    )
    environment = Environment(robot, groups, grasped=object_voxels, hand_arm=args.arm)
    motion = None
    motion_settings = _motion_settings(args)
    # the way to the pre-grasp must avoid the object too: only the hand may touch it, at the end
    if motion_settings is not None:
        from baseplace.placement.motion import MotionChecker, transit_environment

        transit = transit_environment(robot, groups, object_voxels)
        arm = robot.arm(rmap.info.arm)
        if transit is None:
            motion = MotionChecker(robot, arm, environment, None, motion_settings)
        else:
            motion = MotionChecker(robot, arm, transit, environment, motion_settings)
    standoff = grasp_standoff(robot) if args.standoff is None else args.standoff
    approach = robot.arm(rmap.info.arm).approach_axis  # the TCP axis out of the hand, from the robot file
    grasps = grasp_poses(p_o, n=16, top_down=True, standoff=standoff, approach_axis=approach)
    rng = np.random.default_rng(args.seed)
    rejected: list[tuple[tuple[float, float], str]] = []
    if args.method == "radial":
        search = radial_search(p_o, settings, points, grid)
        rejected += [(r.xy, str(r.reason)) for r in search.rejected]
        verified, failed = verify_candidates(
            robot, rmap.info.arm, search.candidates, grasps, environment, rng, motion
        )
        rejected += [((c.pose.x, c.pose.y), why) for c, why in failed]
    else:
        verified = irm_candidates(robot, rmap, p_o, grasps, environment, grid, IrmSettings(), rng, motion)
    if robust.samples > 0:
        from baseplace.placement.robustness import score_candidates

        verified = score_candidates(robot.arm(rmap.info.arm), environment, grasps, verified, robust)
        too_low = [c for c in verified if c.robustness is not None and c.robustness.rate < robust.minimum]
        rejected += [((c.pose.x, c.pose.y), "robustness") for c in too_low]
        verified = [c for c in verified if c not in too_low]
    start = robot_pose if robot_pose is not None else np.r_[p_o[:2], 0.0]
    costs = motion_costs(verified, p_o, BasePose(*start)) if verified else np.zeros(0)
    order = np.argsort(costs, kind="stable")
    if robust.rank == "robustness":  # most robust first, motion cost breaks ties
        order = np.lexsort(
            (costs, np.array([-(c.robustness.rate if c.robustness else 0.0) for c in verified]))
        )
    ranked = [verified[i] for i in order]
    route = None
    if robot_pose is not None and ranked:
        navigator = GridNavigator(grid, settings.r_r)
        for c in ranked:  # the pickup loop: the first candidate the planner reaches
            try:
                route = navigator(BasePose(*robot_pose), c.pose)
            except InputError:
                route = None
            if route is not None:
                break
    rows = [
        {"x": round(c.pose.x, 4), "y": round(c.pose.y, 4), "yaw": round(c.pose.yaw, 4),
         "distance": round(c.distance, 4), "motion_cost": round(float(costs[i]), 4), "method": c.method,
         "reachability": round(c.reachability, 5), "grasp": grasps[c.grasp].round(5).tolist(),
         "joints": dict(zip(c.joint_names, np.round(c.joints, 6).tolist(), strict=True)) if c.joints is not None else {},
         **_motion_and_robustness_json(None if c.motion is None else [c.motion], c.robustness)}
        for i, c in zip(order, ranked, strict=True)
    ]  # fmt: skip
    obj: dict[str, Any] = {
        "method": args.method, "robot": robot.name, "object": p_o.tolist(), "occupancy": args.occupancy or args.bag,
        "robot_pose": None if robot_pose is None else robot_pose.tolist(), "candidates": rows,
        "rejected": [{"x": round(xy[0], 4), "y": round(xy[1], 4), "reason": why} for xy, why in rejected],
        "path": None if route is None else np.round(route, 4).tolist(),
        "object_shape": {"requested": args.object_shape,
                         "allowed": grasped.to_json() if isinstance(grasped, GraspedObject) else None},
        "settings": {"r_r": settings.r_r, "d_min": settings.d_min, "d_max": round(settings.d_max, 4),
                     "theta": round(settings.theta, 5), "k_obs": settings.k_obs, "grasp_standoff": standoff},
    }  # fmt: skip
    if out is not None:
        from baseplace.viz.candidates import plot_candidates

        plot_candidates(grid, p_o, ranked, rejected, out, robot_pose, route,
                        f"{args.method} candidates for {robot.name}: {len(ranked)} verified, {len(rejected)} rejected")  # fmt: skip
        obj["png"] = str(out)
    if mcap is not None:
        from baseplace.geometry.poses import pose_from_xyz_rpy

        T_c = [pose_from_xyz_rpy([c.pose.x, c.pose.y, 0.0, 0.0, 0.0, c.pose.yaw]) for c in ranked]
        _write_mcap(mcap, args, candidates=T_c, placements=T_c[:1],
                    paths=[] if route is None else [np.asarray(route)])  # fmt: skip
        obj["mcap"] = str(mcap)
    if not ranked:
        raise NothingFoundError(
            f"no verified candidate ({args.method}); {len(rejected)} positions rejected "
            f"({', '.join(sorted({why for _, why in rejected})) or 'none tried'})"
        )
    lines = [
        f"{len(ranked)} verified {args.method} candidate(s), best first ({robust.rank if robust.rank == 'robustness' else 'motion cost'}):"
    ]
    lines += [
        f"  x={r['x']:.3f} y={r['y']:.3f} yaw={r['yaw']:.3f} cost {r['motion_cost']:.2f} m{_robust_text(r)}"
        for r in rows
    ]
    _emit(args, obj, "\n".join(lines))
    return 0


def _parse_xyz(text: str, what: str) -> np.ndarray:
    try:
        values = [float(v) for v in text.replace(",", " ").split()]
    except ValueError:
        raise InputError(f'{what} must be "x y z" in metres, got {text!r}') from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise InputError(f'{what} must be 3 finite numbers "x y z" [m], got {text!r}')
    return np.array(values)


def _check_object(grid: Any, p_o: np.ndarray, reach: float) -> None:
    """Clear errors for an object outside the map or buried in an obstacle (no free cell in reach)."""
    from scipy import ndimage

    x, y = float(p_o[0]), float(p_o[1])
    if not grid.inside(p_o[None, :2])[0]:
        raise InputError(f"--object ({x:.2f}, {y:.2f}) lies outside the occupancy grid {grid.source}")
    free = (grid.data >= 0) & (grid.data < 50)
    if not free.any():
        raise InputError(f"the occupancy grid {grid.source} has no free cell")
    gap = ndimage.distance_transform_edt(~free) * grid.resolution
    col, row = grid.world_to_cell(p_o[None, :2])[0]
    if gap[row, col] > reach:
        raise InputError(
            f"--object ({x:.2f}, {y:.2f}) lies inside an obstacle or unknown space: the nearest free cell is {gap[row, col]:.2f} m "
            f"away, beyond the arm's reach ({reach:.2f} m)"
        )


def cmd_navigate(args: argparse.Namespace) -> int:
    """Seed 000 V: a base path across the planar regions of a scanned scene."""
    from baseplace.navigation.navmap import navigation_map
    from baseplace.navigation.planners import plan_path
    from baseplace.robots.model import Robot
    from baseplace.terrain.pipeline import terrain_from_points

    out = _out_path(args.out)
    mcap = _out_path(args.mcap, (".mcap",), "--mcap")
    start, goal = _base_xyyaw(args.start), _base_xyyaw(args.goal)
    robot = Robot(args.robot)
    cloud = _world_cloud(args)
    terrain = terrain_from_points(cloud.points, resolution=args.resolution)
    navmap = navigation_map(terrain, robot.spec.footprint_bounding_radius)
    path = plan_path(navmap, start, goal, args.planner, args.time_limit, args.seed)
    obj = {
        "robot": robot.name, "planner": path.planner, "start": start.tolist(), "goal": goal.tolist(),
        "poses": np.round(path.poses, 4).tolist(), "length": round(path.length, 3),
        "regions": list(path.regions), "time_ms": round(path.time_ms, 1),
        "footprint_radius": navmap.radius, "timings_ms": {k: round(v, 1) for k, v in terrain.timings_ms.items()},
    }  # fmt: skip
    if out is not None:
        from baseplace.viz.navigation import plot_navigation

        plot_navigation(navmap, [path], start, goal, out)
        obj["png"] = str(out)
    if mcap is not None:
        _write_mcap(mcap, args, terrain, paths=[path.poses])
        obj["mcap"] = str(mcap)
    text = (f"{path.planner} path of {path.length:.2f} m through regions {list(path.regions)} "
            f"in {path.time_ms:.0f} ms, {len(path.poses)} poses") + (f"\nwrote {out}" if out else "")  # fmt: skip
    _emit(args, obj, text)
    return 0


def _surface_arms(robot: Any, arms: str) -> tuple[list[str], str]:
    """The arms of ``--arms`` and how they combine: any/both over every arm, or one arm by name."""
    from baseplace.errors import unknown

    names = list(robot.spec.arms)
    if arms in ("any", "both"):
        if arms == "both" and len(names) < 2:
            raise InputError(
                f"--arms both needs two arms; {robot.name} has one ({names[0]}): use any or {names[0]}"
            )
        return names, arms
    if arms not in names:
        raise unknown("arm", arms, ["any", "both", *names], robot.name)
    return [arms], "any"


def cmd_surface_map(args: argparse.Namespace) -> int:
    """Seed 002: the inverse surface reachability map of a polygonal working surface."""
    import time

    from baseplace.demo import cached_map
    from baseplace.placement.surface_map import build_surface_map, parse_polygon
    from baseplace.placement.surface_storage import save_surface_map
    from baseplace.reachability.build import BuildSettings
    from baseplace.robots.model import Robot

    out, png = _out_path(args.out, SURFACE_SUFFIXES), _out_path(args.png, what="--png")
    assert out is not None
    polygon = parse_polygon(args.polygon)
    robot = Robot(args.robot)
    arms, combine = _surface_arms(robot, args.arms)
    settings = BuildSettings(samples=args.samples)
    update, bar = _progress(args, settings.samples, "reachability map")
    try:
        rmaps = {arm: cached_map(robot, settings, arm, update)[0] for arm in arms}
    finally:
        if bar is not None:
            bar.close()
    for rmap in rmaps.values():
        _ = rmap.tables  # the dense lookup of the reachability map is built once, outside the timing
    t0 = time.perf_counter()
    smap = build_surface_map(robot, rmaps, polygon, args.height, args.resolution, args.orientations, combine)
    build_ms = (time.perf_counter() - t0) * 1e3
    size = save_surface_map(smap, out)
    obj = {**smap.summary(), "out": str(out), "file_bytes": size, "build_ms": round(build_ms, 2)}
    if png is not None:
        from baseplace.viz.surface import plot_surface_map

        plot_surface_map(smap, png)
        obj["png"] = str(png)
    text = (
        f"surface map of {len(polygon)}-gon at {args.height} m for {robot.name} arms {'+'.join(arms)} ({combine}): "
        f"{obj['nonzero_poses']} poses with R_S > 0, max R_S {obj['max']:.2f}, built in {build_ms:.1f} ms\n"
        f"wrote {out} ({size / 1e3:.1f} kB)" + (f" and {png}" if png is not None else "")
    )
    _emit(args, obj, text)
    return 0


def cmd_surface_sample(args: argparse.Namespace) -> int:
    """Seed 002 III-B: good, spread-out base poses sampled from a surface map."""
    from baseplace.placement.surface_sampling import SurfaceSampler
    from baseplace.placement.surface_storage import load_surface_map
    from baseplace.robots.model import Robot

    if args.n < 1 or args.candidates < 1:
        raise InputError(f"--n and --candidates must be >= 1, got {args.n} and {args.candidates}")
    smap = load_surface_map(args.map)
    robot = Robot(args.robot or smap.robot)
    occupancy = _grid(args)
    sampler = SurfaceSampler(smap, robot, occupancy, args.candidates, discounted=not args.no_discount)
    rng = np.random.default_rng(args.seed)
    samples = [sampler.sample(rng) for _ in range(args.n)]
    poses = [
        {"x": round(s.x, 4), "y": round(s.y, 4), "theta": round(s.theta, 4),
         "reachability": round(s.reachability, 4), "score": round(s.score, 4)}
        for s in samples
    ]  # fmt: skip
    obj = {"map": str(args.map), "robot": robot.name, "occupancy": args.occupancy or args.bag, "poses": poses}
    lines = [f"{'x':>7} {'y':>7} {'theta':>7} {'R_S':>6} {'score':>6}"]
    lines += [
        f"{p['x']:7.3f} {p['y']:7.3f} {p['theta']:7.3f} {p['reachability']:6.3f} {p['score']:6.3f}"
        for p in poses
    ]
    _emit(args, obj, "\n".join(lines))
    return 0


def cmd_occupancy(args: argparse.Namespace) -> int:
    """An occupancy grid in map_server format, as map_server reads it."""
    from baseplace.world.occupancy import load_occupancy

    grid = load_occupancy(args.map)
    values = grid.data
    text = (
        f"{grid.width} x {grid.height} cells of {grid.resolution} m, origin {list(grid.origin)}: "
        f"{int((values == 0).sum())} free, {int((values == 100).sum())} occupied, {int((values < 0).sum())} unknown, "
        f"{int(((values > 0) & (values < 100)).sum())} in between"
    )
    _emit(args, grid.to_json(), text)
    return 0


def _add_motion_and_robustness_arguments(p: argparse.ArgumentParser) -> None:
    """Options of the reaching-motion check and the robustness score (place, candidates)."""
    p.add_argument("--no-motion-check", action="store_true",
                   help="skip the reaching-motion check (stowed -> pre-grasp path, straight approach)")  # fmt: skip
    p.add_argument("--robustness-samples", type=_nonneg_int, default=64,
                   help="base-error draws scoring each placement (0: no score; default 64)")  # fmt: skip
    p.add_argument("--rank-by-robustness", action="store_true",
                   help="return the most robust placements first (default: the method's order)")  # fmt: skip
    p.add_argument("--min-robustness", type=float, default=0.0,
                   help="reject placements whose robustness is below this fraction (default 0)")  # fmt: skip
    p.add_argument("--error-model", default="gaussian", choices=["gaussian", "box"],
                   help="base error: gaussian (sigmas, within the tolerances) or uniform in the box")  # fmt: skip
    p.add_argument(
        "--sigma-xy", type=float, default=0.03, help="base position error sigma [m] (default 0.03)"
    )
    p.add_argument(
        "--sigma-yaw-deg", type=float, default=2.0, help="base heading error sigma [deg] (default 2)"
    )
    p.add_argument(
        "--xy-tolerance", type=float, default=0.25, help="goal xy tolerance [m] (Nav2 default 0.25)"
    )
    p.add_argument(
        "--yaw-tolerance", type=float, default=0.25, help="goal yaw tolerance [rad] (Nav2 default 0.25)"
    )


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of the ``baseplace`` command."""
    parser = _Parser(
        prog="baseplace",
        description="Where should a mobile manipulator stand?",
        formatter_class=_Formatter,
    )
    parser.add_argument("--version", action="version", version=f"baseplace {_version()}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    def command(
        name: str,
        help_text: str,
        func: Callable[[argparse.Namespace], int],
        parent: Any = sub,
        description: str | None = None,
    ) -> argparse.ArgumentParser:
        p = parent.add_parser(name, help=help_text, description=description or help_text)
        p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
        p.set_defaults(func=func)
        return p

    command("robots", "list the built-in robots, their arms and TCP frames", cmd_robots)
    _add_robot_commands(sub, command)

    p = command("build-map", "build a reachability map by random joint sampling", cmd_build_map)
    p.add_argument("--robot", default="tiago", help="built-in name or robot file (default: tiago)")
    p.add_argument("--arm", default=None, help="arm name (default: the robot's default arm)")
    p.add_argument("--samples", type=_count, default=50_000_000, help="joint samples, e.g. 5e7 (default)")
    p.add_argument("--out", required=True, help="output map file (.rmap, HDF5)")
    p.add_argument("--seed", type=_nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--workers", type=int, default=None,
                   help="threads, or worker processes with --scheduler local (default: all cores)")  # fmt: skip
    p.add_argument("--voxel-size", type=float, default=0.05, help="position resolution [m] (default 0.05)")
    p.add_argument("--orientation-resolution", type=float, default=0.8,
                   help="largest orientation bin [rad] (default 0.8)")  # fmt: skip
    p.add_argument("--self-collision", action="store_true", help="drop self-colliding samples (slow)")
    p.add_argument("--manipulability", action="store_true", help="store the best manipulability per cell")
    p.add_argument("--scheduler", default=None,
                   help='dask scheduler "tcp://host:port" or "local" (local worker processes); '
                        "default: this process, all cores")  # fmt: skip
    p.add_argument("--checkpoint-every", type=_count, default=DEFAULT_CHECKPOINT_EVERY,
                   help="save progress to OUT.partial every N samples (default 5e7; also on Ctrl-C)")  # fmt: skip
    p.add_argument("--no-resume", action="store_true", help="ignore and write no OUT.partial checkpoint")

    p = command("reach", "reachability of TCP targets from base poses (IRM lookup)", cmd_reach)
    p.add_argument("--map", required=True, help="map file from build-map")
    p.add_argument("--robot", default=None, help="check the map was built for this robot")
    p.add_argument("--target", help='world TCP pose "x y z roll pitch yaw" [m, rad]')
    p.add_argument("--targets", help="file with one target pose per line")
    p.add_argument("--base", help='base pose "x y yaw" [m, rad]')
    p.add_argument("--bases", help="file with one base pose per line, paired with --targets")

    p = command("place", "verified base placements for TCP targets in a scanned scene (seed 000)", cmd_place)
    p.add_argument("--robot", default="tiago", help="built-in name or robot file (default: tiago)")
    p.add_argument("--arm", default=None, help="arm (default: the robot's default arm)")
    p.add_argument("--cloud", action="append", default=None,
                   help="scene cloud: .pcd, .ply, .bt, .npy, .xyz (z up, or --transform); repeat for several")  # fmt: skip
    p.add_argument("--transform", action="append", default=None,
                   help='world_T_sensor file, or the sensor-frame up vector "ux uy uz"; one per --cloud')  # fmt: skip
    p.add_argument("--occupancy", default=None,
                   help="navigation map (map_server YAML) in the clouds' world frame: its free cells are floor")  # fmt: skip
    p.add_argument("--mcap", default=None, help="also write the result as an MCAP recording (ROS 2 messages)")
    _add_bag_args(p)
    _add_fuse_args(p)
    p.add_argument(
        "--target", action="append", help='TCP target "x y z roll pitch yaw" [m, rad]; repeat for several'
    )
    p.add_argument("--strategy", default="MR", choices=["MR", "TO", "MRTO", "orm", "grid", "random"],
                   help="seed 000's MR, TO, MRTO, or a baseline (default MR)")  # fmt: skip
    p.add_argument("--placements", type=int, default=1, help="M: placements to return (default 1)")
    p.add_argument("--tries", type=int, default=100, help="N: candidates to check at most (default 100)")
    p.add_argument(
        "--map", default=None, help="reachability map (default: the cached default map, built once)"
    )
    p.add_argument("--seed", type=_nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--out", default=None, help="PNG: OSRM over the scene with the placements (Fig. 2b)")
    p.add_argument(
        "--start", default=None, help='current base pose "x y yaw": also plan a path to each placement'
    )
    p.add_argument("--planner", default="rrt", choices=["rrt", "regions"],
                   help="path planner with --start: OMPL RRTConnect or the region graph (default rrt)")  # fmt: skip
    p.add_argument("--resolution", type=_finite_float, default=None,
                   help="height-map cell [m] (default: from the cloud's extent and point spacing, 0.02-0.05)")  # fmt: skip
    p.add_argument("--object", default="auto", help=OBJECT_HELP)
    p.add_argument("--floor", type=_finite_float, default=None,
                   help="add a floor plane at this height [m] (z up) under and around a cloud that shows none")  # fmt: skip
    _add_motion_and_robustness_arguments(p)

    p = command("candidates", "base placement candidates around an object (seed 004)", cmd_candidates)
    p.add_argument("--occupancy", default=None, help="occupancy grid: map_server YAML (or --bag --map-topic)")
    p.add_argument("--object", required=True, help='object position "x y z" in the map frame [m]')
    p.add_argument("--cloud", default=None, help="RGB-D cloud in the map frame (.pcd, .ply, .npy, ...)")
    p.add_argument("--transform", default=None, help="world_T_sensor file or up vector for --cloud")
    p.add_argument(
        "--robot-pose", default=None, help='robot pose "x y yaw": rank by motion cost, plan a path'
    )
    p.add_argument("--method", default="radial", choices=["radial", "irm"],
                   help="radial (seed 004 Algorithm 1) or irm (reachability map); both verified (default radial)")  # fmt: skip
    p.add_argument("--robot", default="tiago", help="built-in name or robot file (default: tiago)")
    p.add_argument("--arm", default=None, help="arm (default: the robot's default arm)")
    p.add_argument("--map", default=None, help="reachability map (default: the cached default map)")
    p.add_argument("--standoff", type=float, default=None,
                   help="TCP distance behind the grasp point [m] (default: 0.15 for TIAGo, else 0)")  # fmt: skip
    p.add_argument("--seed", type=_nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--png", default=None, help="PNG of the candidates over the grid (as seed 004 Fig. 2)")
    p.add_argument("--mcap", default=None, help="also write the candidates (best first) as an MCAP recording")
    _add_bag_args(p)
    p.add_argument("--object-shape", default="auto",
                   help=OBJECT_HELP.replace("first target's grasp point", "--object position"))  # fmt: skip
    _add_motion_and_robustness_arguments(p)

    p = command(
        "navigate", "a base path across the planar regions of a scanned scene (seed 000 V)", cmd_navigate
    )
    p.add_argument("--robot", default="tiago", help="built-in name or robot file (default: tiago)")
    p.add_argument(
        "--cloud", default=None, help="scene cloud: .pcd, .ply, .bt, .npy, .xyz (z up, or --transform)"
    )
    p.add_argument(
        "--transform", default=None, help='world_T_sensor file, or the sensor-frame up vector "ux uy uz"'
    )
    _add_bag_args(p, grid=False)
    _add_fuse_args(p)
    p.add_argument("--mcap", default=None, help="also write the path and the regions as an MCAP recording")
    p.add_argument("--start", required=True, help='start base pose "x y yaw" [m, rad]')
    p.add_argument("--goal", required=True, help='goal base pose "x y yaw" [m, rad]')
    p.add_argument("--planner", default="rrt", choices=["rrt", "regions"],
                   help="OMPL RRTConnect (seed 000) or the region-graph planner (default rrt)")  # fmt: skip
    p.add_argument("--time-limit", type=float, default=2.0, help="RRT planning time limit [s] (default 2)")
    p.add_argument("--resolution", type=float, default=None,
                   help="height-map cell [m] (default: from the cloud's extent and point spacing, 0.02-0.05)")  # fmt: skip
    p.add_argument("--seed", type=_nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--out", default=None, help="PNG of the path over regions and obstacles (as Fig. 4)")

    p = command("surface-map", "where to stand to work on a whole table or shelf (seed 002)", cmd_surface_map)
    p.add_argument("--robot", default="tiago", help="built-in name or robot file (default: tiago)")
    p.add_argument("--arms", default="any",
                   help="any (either arm), both (both arms) or one arm's name (default: any)")  # fmt: skip
    p.add_argument("--polygon", required=True, help='the surface outline "x1,y1;x2,y2;..." [m]')
    p.add_argument("--height", type=float, required=True, help="surface height above the floor [m]")
    p.add_argument("--resolution", type=float, default=0.05, help="grid spacing [m] (default 0.05)")
    p.add_argument("--orientations", type=int, default=16, help="base headings (default 16)")
    p.add_argument("--out", required=True, help="surface map file (.smap, sparse HDF5)")
    p.add_argument("--png", default=None, help="PNG of R_S over the floor around the surface")
    p.add_argument("--samples", type=_count, default=50_000_000,
                   help="samples of the cached reachability maps, built once per arm (default 5e7)")  # fmt: skip

    p = command("surface-sample", "sample good, spread-out base poses from a surface map (seed 002)",
                cmd_surface_sample)  # fmt: skip
    p.add_argument("--map", required=True, help="surface map from surface-map")
    p.add_argument("--n", type=int, default=5, help="poses to sample (default 5)")
    p.add_argument("--occupancy", default=None, help="operational area: map_server YAML (free cells only)")
    _add_bag_args(p, clouds=False)
    p.add_argument("--candidates", type=int, default=40, help="N: best of N valid candidates (default 40)")
    p.add_argument("--no-discount", action="store_true", help="do not spread consecutive poses (eq. 3)")
    p.add_argument("--robot", default=None, help="robot file for custom robots (default: the map's robot)")
    p.add_argument("--seed", type=_nonneg_int, default=0, help="random seed (default 0)")

    p = command("occupancy", "read an occupancy grid (map_server YAML + image) as nav2 does",
                cmd_occupancy)  # fmt: skip
    p.add_argument("map", help="map YAML file")

    p = command("segment", "planar regions, polygons and region graph of a point cloud", cmd_segment)
    p.add_argument(
        "cloud", nargs="?", default=None, help="point cloud: .pcd, .ply, .bt (OctoMap), .npy, .xyz"
    )
    p.add_argument("--algorithm", choices=["robust", "baseline"], default="robust",
                   help="robust (seed 000) or baseline region growing (default: robust)")  # fmt: skip
    p.add_argument("--transform", default=None,
                   help='world_T_sensor: a file with a 4x4 matrix, or the sensor-frame up vector "ux uy uz"')  # fmt: skip
    p.add_argument("--resolution", type=float, default=None,
                   help="height-map cell [m] (default: from the cloud's extent and point spacing, 0.02-0.05)")  # fmt: skip
    p.add_argument("--out", default=None, help="PNG of the regions (as seed 000 Fig. 2a)")
    _add_bag_args(p, grid=False)
    _add_fuse_args(p)

    scene = sub.add_parser(
        "scene", help="generated test scenes with ground truth", description="generated scenes"
    )
    scene_sub = scene.add_subparsers(dest="scene_command", metavar="SUBCOMMAND", parser_class=_Parser)
    scene_sub.required = True
    p = command("generate", "write a random scene's cloud and ground truth", cmd_scene_generate, scene_sub,
                "A floor, inclined planes of a size class and a box with objects (seed 000 VI), "
                "with Gaussian height noise.")  # fmt: skip
    p.add_argument("--size-class", default="small", choices=["small", "medium", "large"],
                   help="plane sides 1-1.5, 1.5-2 or 2-2.5 m (default small)")  # fmt: skip
    p.add_argument("--planes", type=_nonneg_int, default=2, help="number of inclined planes (default 2)")
    p.add_argument("--sigma", type=float, default=0.025, help="height noise std [m] (default 0.025)")
    p.add_argument("--extent", type=float, default=10.0, help="scene side [m] (default 10)")
    p.add_argument("--no-box", action="store_true", help="leave out the box with objects")
    p.add_argument("--seed", type=_nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--out", required=True, help="cloud file (.ply, .pcd or .npy)")
    p.add_argument("--truth", default=None, help="ground-truth JSON (default: next to --out)")

    from baseplace_experiments.cli import add_experiment_commands

    add_experiment_commands(sub)

    p = command("view", "interactive 3D viewer of a result in the browser (viser)", cmd_view)
    p.add_argument(
        "result", nargs="?", default=None, help="result JSON with view data (default: out/demo.json)"
    )
    p.add_argument("--port", type=int, default=8080, help="port (default 8080; 0: any free port)")
    p.add_argument(
        "--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)"
    )

    p = command("demo", "the main job on built-in defaults: out/demo.json and out/demo.png", cmd_demo)
    p.add_argument("--out", default="out", help="output directory (default: out)")
    p.add_argument("--samples", type=_count, default=50_000_000, help="samples of the cached map")
    p.add_argument("--seed", type=_nonneg_int, default=0, help="random seed (default 0)")
    return parser


def _version() -> str:
    from baseplace import __version__

    return __version__


def _add_robot_commands(sub: Any, command: Callable[..., argparse.ArgumentParser]) -> None:
    robot = sub.add_parser("robot", help="check a robot file: arms, joints, TCP axes, footprint, a picture",
                           description="robot files (see docs/robots.md)")  # fmt: skip
    robot_sub = robot.add_subparsers(dest="robot_command", metavar="SUBCOMMAND", parser_class=_Parser)
    robot_sub.required = True
    p = command("check", "load a robot file, print what it describes, render it and warn where it looks wrong",
                cmd_robot_check, robot_sub,
                "Prints arms, joints, limits, TCP approach axes, footprint and self-collision pairs; renders "
                "the collision geometry to a PNG; warns about approach axes that do not point out of the hand, "
                "links without collision geometry and footprints smaller than the base.")  # fmt: skip
    p.add_argument("robot", help="robot file (.toml/.yaml) or built-in name")
    p.add_argument("--png", default=None, help="picture of the robot (default: NAME_check.png here)")
    p.add_argument("--pairs", action="store_true", help="list the active self-collision pairs")


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: run one command, map errors to exit codes."""
    parser = build_parser()
    args = parser.parse_args(argv)
    from baseplace.status import elapsed_status

    try:
        with elapsed_status(f"baseplace {args.command}", enabled=not getattr(args, "json", False)):
            return int(args.func(args))
    except BaseplaceError as exc:
        sys.stderr.write(f"error: {exc}\n")
        return exc.exit_code
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted\n")
        return 130


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
