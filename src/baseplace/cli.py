"""The ``baseplace`` command: parse the arguments, run one job, print its report.

Every command takes ``--json`` (exactly one JSON object on stdout, the report of docs/results.md,
also on failure) and ``--help``; commands with randomness take ``--seed``. Exit codes: 0 ok,
2 bad input or an output that does not fit (a full disk, quota or file size limit; one
``error: ...`` line on stderr, the previous file untouched), 3 ran but found nothing; 1 is an
internal failure. A cache that does not fit is a ``warning: ...`` line, never a failure. The work is done by
:mod:`baseplace.jobs`; nothing here loops over results or touches geometry.
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import importlib.util
import json
import os
import sys
import warnings
from collections.abc import Callable, Sequence
from types import ModuleType
from typing import TYPE_CHECKING, Any, NoReturn

from baseplace import __version__
from baseplace.argtypes import count, finite_float, in_radians, nonneg_int
from baseplace.errors import BaseplaceError, InputError, brief
from baseplace.jobs.inputs import DEFAULT_MAP_SAMPLES, Progress, motion_and_robustness
from baseplace.robots.defaults import DEFAULT_ROBOT
from baseplace.world.clearance import check_clearance


def _lazy_module(name: str) -> ModuleType:
    """Module ``name``, executed on its first attribute access: a command imports its own job alone."""
    if name in sys.modules:
        return sys.modules[name]
    spec = importlib.util.find_spec(name)
    assert spec is not None and spec.loader is not None, name
    spec.loader = importlib.util.LazyLoader(spec.loader)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    spec.loader.exec_module(module)
    parent, _, child = name.rpartition(".")
    setattr(sys.modules[parent], child, module)  # as an import does: ``import a.b`` then ``a.b`` works
    return module


if TYPE_CHECKING:
    from importlib.metadata import EntryPoint

    from baseplace.jobs import candidates, demo, explain, navigate, place, point, reach, surface, view, world
else:
    candidates, demo, explain, navigate, place, point, reach, surface, view, world = (
        _lazy_module(f"baseplace.jobs.{name}")
        for name in ("candidates", "demo", "explain", "navigate", "place", "point", "reach", "surface", "view",
                     "world")
    )  # fmt: skip

DEFAULT_CHECKPOINT_EVERY = 50_000_000  # baseplace.reachability.build's, without importing numba for --help
PLUGIN_GROUP = "baseplace.commands"
"""Entry-point group of commands added by other packages (:func:`_add_plugin_commands`)."""
KINDS = {"robots": "robots", "robot": "robot_check", "build-map": "build_map", "reach": "reach", "place": "place",
         "candidates": "candidates", "navigate": "navigate", "surface-map": "surface_map",
         "surface-sample": "surface_samples", "occupancy": "occupancy", "segment": "segment", "scene": "scene",
         "demo": "demo", "explain": "explain", "point": "point"}  # fmt: skip
"""Command -> the kind of report it prints."""
COMMANDS = {*KINDS, "serve", "view"}
"""The library's own commands (the plugins add theirs)."""


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors and exit code 2 (and the failure report with --json)."""

    json_argv: list[str] | None = None  # set by main when the command line asks for --json
    json_kind: str | None = None  # the command's kind; None for an unknown command

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        # no abbreviated options: `segment --cloud F` was taken for --cloud-topic F
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)

    def parse_command_line(self, args: Sequence[str]) -> argparse.Namespace:
        """``parse_args``, but an unrecognised argument is reported by the (sub)command that was given it."""
        ns, extras = self.parse_known_args(args)
        if extras:
            self._chosen(ns).error(f"unrecognized arguments: {' '.join(extras)}")
        return ns

    def _chosen(self, ns: argparse.Namespace) -> _Parser:
        """The innermost command's parser that ``ns`` went through."""
        for action in self._actions:
            if isinstance(action, argparse._SubParsersAction):
                name = getattr(ns, action.dest, None)
                chosen = action.choices.get(name) if isinstance(name, str) else None
                if isinstance(chosen, _Parser):
                    return chosen._chosen(ns)
        return self

    def error(self, message: str) -> NoReturn:
        text = f"{message} (see '{self.prog} --help')"
        if _Parser.json_argv is not None:
            _emit_error(_Parser.json_kind, text, 2, {"argv": _Parser.json_argv})
        sys.stderr.write(f"error: {text}\n")
        raise SystemExit(2)


class _Formatter(argparse.HelpFormatter):
    """One line per command in ``baseplace --help``: wide, and room for the longest command name."""

    def __init__(self, prog: str) -> None:
        super().__init__(prog, max_help_position=30, width=110)

    def add_argument(self, action: argparse.Action) -> None:
        super().add_argument(action)
        if isinstance(action, argparse._SubParsersAction):  # argparse measures subcommands one indent short
            self._action_max_length += 2


OBJECT_HELP = (
    'the grasped object, which only the hand may touch: "auto" (default: the cloud\'s cluster at the '
    'first target\'s grasp point, above its support), "none", "box CX CY CZ SX SY SZ [YAW]", '
    '"cylinder CX CY CZ RADIUS HEIGHT" [m, rad] or "points FILE" (the object\'s cloud), world frame'
)

OBSTACLE_HELP = (
    'a collision object beside the cloud, world frame: "box X Y Z SX SY SZ [YAW]" (centre, full sizes), '
    '"cylinder X Y Z RADIUS HEIGHT" (centre, axis vertical) [m, rad] or a mesh file PATH.stl|.obj|.ply '
    "in world coordinates [m]; repeat for several; contacts name it (obstacle box#0: kind and place among "
    "the --obstacle options, from 0)"
)


def _emit_error(kind: str | None, message: str, code: int, inputs: dict[str, Any]) -> None:
    """The failure report of a command that could not start (bad arguments) on stdout."""
    from baseplace.jobs.report import ErrorReport

    sys.stdout.write(ErrorReport(kind_name=kind, inputs=inputs).failed(message, code).dumps() + "\n")


def _cloud(args: argparse.Namespace) -> Any:
    """The cloud input of ``--cloud``/``--transform``/``--bag``/``--fuse``."""
    from baseplace.jobs.inputs import BagInput, CloudInput

    paths = args.cloud if isinstance(args.cloud, list) else [] if args.cloud is None else [args.cloud]
    transforms = args.transform if isinstance(args.transform, list) else [args.transform]
    bag = None
    if getattr(args, "bag", None) is not None:
        bag = BagInput(args.bag, tuple(getattr(args, "cloud_topic", None) or ()), getattr(args, "map_topic", None),
                       args.world_frame, getattr(args, "bag_clouds", "last"))  # fmt: skip
    return CloudInput(paths, transforms if paths else [], bag=bag, fuse=getattr(args, "fuse", False),
                      fuse_miss=getattr(args, "fuse_miss", 0.35), fused_out=getattr(args, "fused_out", None))  # fmt: skip


def _segment(args: argparse.Namespace, progress: Progress) -> Any:
    # the jobs' message names --cloud, which segment takes as CLOUD
    if args.cloud is None and args.bag is None:
        raise InputError("give a cloud file (baseplace segment CLOUD) or --bag FILE --cloud-topic TOPIC")
    return navigate.segment_job(navigate.SegmentJob(_cloud(args), args.algorithm, args.resolution, args.out))


def _build_map(args: argparse.Namespace, progress: Progress) -> Any:
    from baseplace.jobs.inputs import check_robot_name, out_path
    from baseplace.jobs.reach import MAP_SUFFIXES

    out_path(args.out, "--out", MAP_SUFFIXES)  # before the settings' imports and the checkpoint's name
    check_robot_name(args.robot, args.arm)
    from baseplace.reachability.build import BuildSettings
    from baseplace.reachability.checkpoint import default_checkpoint_path

    settings = BuildSettings(samples=args.samples, seed=args.seed, voxel_size=args.voxel_size,
                             orientation_resolution=args.orientation_resolution,
                             self_collision=args.self_collision, manipulability=args.manipulability,
                             support_threshold=args.support_threshold)  # fmt: skip
    checkpoint = None if args.no_resume else default_checkpoint_path(args.out)
    if checkpoint is not None and checkpoint.exists() and not args.json:
        sys.stderr.write(f"resuming from checkpoint {checkpoint}\n")
    job = reach.BuildMapJob(args.out, args.robot, args.arm, settings, checkpoint, args.checkpoint_every,
                            args.scheduler, args.workers)  # fmt: skip
    try:
        return reach.build_map_job(job, progress)
    except KeyboardInterrupt:
        if checkpoint is None or not checkpoint.exists():
            raise
        sys.stderr.write(
            f"error: interrupted; progress saved in {checkpoint}: rerun the same command to resume\n"
        )
        return 130


def _place(a: argparse.Namespace, progress: Progress) -> Any:
    job = place.PlaceJob(a.target or [], a.robot, a.arm, _cloud(a), a.occupancy, a.map, None, a.seed, a.start,
                         a.planner, a.object, a.floor, a.out, a.mcap, grasp_points=a.grasp_point or [],
                         obstacles=a.obstacle or [])  # fmt: skip
    check_clearance(a.clearance)  # before the settings' imports (seconds), with the job's inputs
    job.check_inputs()
    from baseplace.placement.pipeline import PlaceSettings

    motion, robustness = motion_and_robustness(vars(a))
    job.settings = PlaceSettings(strategy=a.strategy, placements=a.placements, tries=a.tries, resolution=a.resolution,
                                 motion=motion, robustness=robustness, clearance=a.clearance,
                                 stand_on=a.stand_on)  # fmt: skip
    return place.place_job(job, progress)


def _explain(a: argparse.Namespace, progress: Progress) -> Any:
    job = explain.ExplainJob(a.base, a.target, a.map, a.robot, a.arm, _cloud(a), a.object, a.floor, None, a.seed,
                             a.grasp_point, obstacles=a.obstacle or [])  # fmt: skip
    check_clearance(a.clearance)  # before the settings' imports (seconds), with the job's inputs
    job.check_inputs()
    from dataclasses import replace

    from baseplace.placement.pipeline import PlaceSettings

    settings = PlaceSettings(resolution=a.resolution, clearance=a.clearance, stand_on=a.stand_on)
    job.settings = settings if not a.no_motion_check else replace(settings, motion=None)
    return explain.explain_job(job, progress)


def _candidates(a: argparse.Namespace, progress: Progress) -> Any:
    job = candidates.CandidatesJob(a.object, a.occupancy, _cloud(a), a.robot_pose, a.method, a.robot, a.arm, a.map,
                                   a.standoff, a.seed, a.object_shape, None, None, a.png, a.mcap,
                                   obstacles=a.obstacle or [], clearance=a.clearance)  # fmt: skip
    job.check_inputs()  # before the settings' imports (seconds)
    job.motion, job.robustness = motion_and_robustness(vars(a))
    return candidates.candidates_job(job, progress)


def _point(a: argparse.Namespace, progress: Progress) -> Any:
    job = point.PointJob(a.rgb, a.depth, a.intrinsics, a.transform, a.landmarks, a.occupancy, a.robot, a.arm, a.map,
                         a.robot_pose, a.seed, selection=a.selection, png=a.png, bag=a.bag, rgb_topic=a.rgb_topic,
                         depth_topic=a.depth_topic, camera_info_topic=a.camera_info_topic,
                         world_frame=a.world_frame, bag_frame=a.bag_frame)  # fmt: skip
    if a.occupancy is not None:
        job.motion, job.robustness = motion_and_robustness(vars(a))
    return point.point_job(job, progress)


def _demo(a: argparse.Namespace, progress: Progress) -> Any:
    from baseplace.guards import check_path_length

    check_path_length(os.path.join(a.out, "demo.json"), "--out")
    return demo.demo_job(demo.DemoJob(a.out, a.samples, a.seed), progress)


JOBS: dict[str, Callable[[argparse.Namespace, Progress], Any]] = {
    "robots": lambda a, _: world.robots_job(),
    "check": lambda a, _: world.robot_check_job(world.RobotCheckJob(a.robot, a.png, a.pairs)),
    "build-map": _build_map,
    "reach": lambda a, progress: reach.reach_job(
        reach.ReachJob(a.map, a.target, a.targets, a.base, a.bases, a.robot), progress
    ),
    "place": _place,
    "explain": _explain,
    "candidates": _candidates,
    "point": _point,
    "navigate": lambda a, _: navigate.navigate_job(navigate.NavigateJob(
        a.start, a.goal, _cloud(a), a.robot, a.planner, a.time_limit, a.resolution, a.seed, a.out, a.mcap)),
    "surface-map": lambda a, progress: surface.surface_map_job(surface.SurfaceMapJob(
        a.polygon, a.height, a.out, a.robot, a.arms, a.resolution, a.orientations, a.samples, a.png), progress),
    "surface-sample": lambda a, _: surface.surface_samples_job(surface.SurfaceSamplesJob(
        a.map, a.n, a.occupancy, _cloud(a).bag if a.map_topic else None, a.candidates, not a.no_discount, a.robot,
        a.seed)),
    "occupancy": lambda a, _: world.occupancy_job(a.map),
    "segment": _segment,
    "generate": lambda a, _: world.scene_job(world.SceneJob(
        a.out, a.truth, a.size_class, a.planes, a.sigma, a.extent, not a.no_box, a.seed)),
    "demo": _demo,
}  # fmt: skip
"""Command -> its job: the arguments as the job's inputs."""


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


def _add_fuse_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("fusion: the clouds into one OctoMap by ray casting")
    g.add_argument("--fuse", action="store_true",
                   help="fuse the clouds (every --cloud, or the bag's clouds) into a 25 mm OctoMap, rays from each sensor origin")  # fmt: skip
    g.add_argument("--fuse-miss", type=float, default=0.35,
                   help="occupancy probability of a ray passing a voxel (default 0.35; octomap's own: 0.4)")  # fmt: skip
    g.add_argument("--fused-out", default=None, help="also write the fused OctoMap (.bt)")


def _add_motion_and_robustness_arguments(p: argparse.ArgumentParser) -> None:
    """Options of the reaching-motion check and the robustness score (place, candidates)."""
    p.add_argument("--no-motion-check", action="store_true",
                   help="skip the reaching-motion check (stowed -> pre-grasp path, straight approach)")  # fmt: skip
    p.add_argument("--robustness-samples", type=nonneg_int, default=64,
                   help="base-error draws scoring each placement (0: no score; default 64)")  # fmt: skip
    p.add_argument("--rank-by-robustness", action="store_true",
                   help="return the most robust placements first (default: the method's order)")  # fmt: skip
    p.add_argument("--robustness-motion", action="store_true",
                   help="a base-error draw counts only if the reaching motion from it exists too "
                        "(one motion check per draw: about 40 ms each on PCL's mug, 2.6 s for 64 draws)")  # fmt: skip
    p.add_argument("--min-robustness", type=float, default=0.0,
                   help="reject placements whose robustness is below this fraction (default 0)")  # fmt: skip
    p.add_argument("--error-model", default="gaussian", choices=["gaussian", "box"],
                   help="base error: gaussian (sigmas, within the tolerances) or uniform in the box")  # fmt: skip
    p.add_argument("--sigma-xy", type=float, default=0.03, help="base position error sigma [m] (default 0.03)")  # fmt: skip
    p.add_argument("--sigma-yaw-deg", type=float, default=2.0, help="base heading error sigma [deg] (default 2)")  # fmt: skip
    p.add_argument("--xy-tolerance", type=float, default=0.25, help="goal xy tolerance [m] (Nav2 default 0.25)")  # fmt: skip
    p.add_argument("--yaw-tolerance", type=float, default=None,
                   help="goal yaw tolerance [rad, deg with --degrees] (default 0.25 rad, Nav2's)")  # fmt: skip


def _add_degrees_argument(p: argparse.ArgumentParser) -> None:
    p.add_argument("--degrees", action="store_true",
                   help="the angles given here (pose headings and roll/pitch/yaw, pose files, --yaw-tolerance, "
                        "an object's yaw) are in degrees; without it radians, and values beyond 2 pi are refused")  # fmt: skip


def build_parser(chosen: str | None = None) -> _Parser:
    """The argument parser of the ``baseplace`` command.

    With ``chosen`` (the command a command line names) the modules that register other commands
    (the service's, each plugin's) are not imported; None, or a name no one registers: all of them.
    """
    plugins = _plugins()
    everything = chosen is None or chosen not in COMMANDS | {ep.name for ep in plugins}
    parser = _Parser(prog="baseplace", description="Where should a mobile manipulator stand?", formatter_class=_Formatter)  # fmt: skip
    parser.add_argument("--version", action="version", version=f"baseplace {__version__}")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    sub.required = True

    def command(
        name: str, help_text: str, parent: Any = sub, description: str | None = None
    ) -> argparse.ArgumentParser:
        p = parent.add_parser(name, help=help_text, description=description or help_text)
        p.add_argument("--json", action="store_true", help="print exactly one JSON object on stdout")
        p.set_defaults(job=JOBS[name])
        return p

    command("robots", "list the built-in robots, their arms and TCP frames")
    _add_robot_commands(sub, command)
    if everything or chosen == "serve":
        from baseplace.serve.command import add_serve_command

        add_serve_command(sub)

    p = command("build-map", "build a reachability map by random joint sampling")
    p.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"built-in name or robot file (default: {DEFAULT_ROBOT})"
    )
    p.add_argument("--arm", default=None, help="arm name (default: the robot's default arm)")
    p.add_argument("--samples", type=count, default=DEFAULT_MAP_SAMPLES, help="joint samples (default 2e8)")
    p.add_argument("--out", required=True, help="output map file (.rmap, HDF5)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--workers", type=int, default=None,
                   help="threads, or worker processes with --scheduler local (default: all cores)")  # fmt: skip
    p.add_argument("--voxel-size", type=float, default=0.05, help="position resolution [m] (default 0.05)")
    p.add_argument("--orientation-resolution", type=float, default=0.8,
                   help="largest orientation bin [rad] (default 0.8)")  # fmt: skip
    p.add_argument("--self-collision", action="store_true", help="drop self-colliding samples (slow)")
    p.add_argument("--manipulability", action="store_true", help="store the best manipulability per cell")
    p.add_argument("--support-threshold", type=finite_float, default=0.8,
                   help="support a pose needs to be called reachable, in [0, 1]; 0: whole cells "
                        "(default 0.8, see docs/maps.md)")  # fmt: skip
    p.add_argument("--scheduler", default=None,
                   help='dask scheduler "tcp://host:port" or "local" (local worker processes); '
                        "default: this process, all cores")  # fmt: skip
    p.add_argument("--checkpoint-every", type=count, default=DEFAULT_CHECKPOINT_EVERY,
                   help="save progress to OUT.partial every N samples (default 5e7; also on Ctrl-C)")  # fmt: skip
    p.add_argument("--no-resume", action="store_true", help="ignore and write no OUT.partial checkpoint")

    p = command("reach", "reachability of TCP targets from base poses (IRM lookup)")
    p.add_argument("--map", default=None,
                   help='map file from build-map (default, or "default": the cached default map of --robot, built once)')  # fmt: skip
    p.add_argument("--robot", default=None,
                   help="check the map was built for this robot; without --map, the default map's robot (default: tiago)")  # fmt: skip
    p.add_argument("--target", help='world TCP pose "x y z roll pitch yaw" [m, rad]')
    p.add_argument("--targets", help="file with one target pose per line")
    p.add_argument("--base", help='base pose "x y yaw" [m, rad]')
    p.add_argument("--bases", help="file with one base pose per line, paired with --targets")
    _add_degrees_argument(p)

    p = command("place", "verified base placements for TCP targets in a scanned scene")
    p.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"built-in name or robot file (default: {DEFAULT_ROBOT})"
    )
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
    p.add_argument("--target", action="append", help='TCP target "x y z roll pitch yaw" [m, rad]; repeat for several')  # fmt: skip
    p.add_argument("--grasp-point", action="append", default=None,
                   help='instead of --target: the pose of the point between the fingertips "x y z roll pitch yaw" '
                        "[m, rad] (TIAGo: 0.151 m ahead of the TCP); repeat for several")  # fmt: skip
    p.add_argument("--strategy", default="MR", choices=["MR", "TO", "MRTO", "orm", "grid", "random"],
                   help="MR (most reachable cell), TO (a reachable cell facing the targets), MRTO, or a baseline (default MR)")  # fmt: skip
    p.add_argument("--placements", type=int, default=1, help="M: placements to return (default 1)")
    p.add_argument("--tries", type=int, default=100, help="N: candidates to check at most (default 100)")
    p.add_argument("--map", default=None, help="reachability map (default: the cached default map, built once)")  # fmt: skip
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--out", default=None, help="PNG: OSRM over the scene with the placements (Fig. 2b)")
    p.add_argument("--start", default=None, help='current base pose "x y yaw": also plan a path to each placement')  # fmt: skip
    p.add_argument("--planner", default="rrt", choices=["rrt", "regions"],
                   help="path planner with --start: OMPL RRTConnect or the region graph (default rrt)")  # fmt: skip
    p.add_argument("--resolution", type=finite_float, default=None,
                   help="height-map cell [m] (default: from the cloud's extent and point spacing, 0.02-0.05)")  # fmt: skip
    p.add_argument("--object", default="auto", help=OBJECT_HELP)
    p.add_argument("--obstacle", action="append", default=None, help=OBSTACLE_HELP)
    p.add_argument("--floor", type=finite_float, default=None,
                   help="add a floor plane at this height [m] (z up) under and around a cloud that shows none")  # fmt: skip
    p.add_argument("--clearance", type=finite_float, default=None, metavar="METRES",
                   help="keep this far [m] from the scene near the grasped object (default: 3 sigma of the "
                        "support plane's residuals or, without one, of the surfaces' noise near it; at least 3 mm)")  # fmt: skip
    p.add_argument("--stand-on", default="ground", choices=["ground", "any"],
                   help="where the base may stand: the ground and the regions it can drive onto from it "
                        "over steps up to 4 cm (ground, default), or every planar region large enough "
                        "(any: seed 000's experiments; a table top too)")  # fmt: skip
    _add_motion_and_robustness_arguments(p)
    _add_degrees_argument(p)

    p = command("explain", "why one base pose can or cannot reach one target: map, IK, collisions, motion")
    p.add_argument(
        "--base", help='base pose "x y yaw" [m, rad]; on a scene it stands on the region under (x, y)'
    )
    p.add_argument("--target", help='TCP target "x y z roll pitch yaw" [m, rad]')
    p.add_argument("--grasp-point", default=None,
                   help='instead of --target: the pose of the point between the fingertips "x y z roll pitch yaw" [m, rad]')  # fmt: skip
    p.add_argument("--map", default=None, help="reachability map (default: the cached default map)")
    p.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"built-in name or robot file (default: {DEFAULT_ROBOT})"
    )
    p.add_argument("--arm", default=None, help="arm (default: the robot's default arm)")
    p.add_argument("--cloud", action="append", default=None,
                   help="scene cloud, as place takes it (none: IK and self-collision only); repeat for several")  # fmt: skip
    p.add_argument("--transform", action="append", default=None,
                   help='world_T_sensor file, or the sensor-frame up vector "ux uy uz"; one per --cloud')  # fmt: skip
    _add_bag_args(p, grid=False)
    p.add_argument("--object", default="auto", help=OBJECT_HELP)
    p.add_argument("--obstacle", action="append", default=None, help=OBSTACLE_HELP)
    p.add_argument("--floor", type=finite_float, default=None,
                   help="add a floor plane at this height [m] (z up) under and around a cloud that shows none")  # fmt: skip
    p.add_argument("--clearance", type=finite_float, default=None, metavar="METRES",
                   help="keep this far [m] from the scene near the grasped object (default: 3 sigma of the "
                        "support plane's residuals or, without one, of the surfaces' noise near it; at least 3 mm)")  # fmt: skip
    p.add_argument(
        "--stand-on",
        default="ground",
        choices=["ground", "any"],
        help="where the base may stand, as place's (default ground)",
    )
    p.add_argument("--resolution", type=finite_float, default=None,
                   help="height-map cell [m] (default: from the cloud, as place)")  # fmt: skip
    p.add_argument(
        "--no-motion-check", action="store_true", help="skip the reaching-motion check, as place's"
    )
    _add_degrees_argument(p)
    p.add_argument(
        "--seed", type=nonneg_int, default=0, help="random seed of IK and the motion planner (default 0)"
    )

    p = command("candidates", "base placement candidates around an object")
    p.add_argument("--occupancy", default=None, help="occupancy grid: map_server YAML (or --bag --map-topic)")
    p.add_argument("--object", required=True, help='object position "x y z" in the map frame [m]')
    p.add_argument("--cloud", default=None, help="RGB-D cloud in the map frame (.pcd, .ply, .npy, ...)")
    p.add_argument("--transform", default=None, help="world_T_sensor file or up vector for --cloud")
    p.add_argument("--robot-pose", default=None, help='robot pose "x y yaw": rank by motion cost, plan a path')  # fmt: skip
    p.add_argument("--method", default="radial", choices=["radial", "irm"],
                   help="radial (rays around the object) or irm (reachability map); both verified (default radial)")  # fmt: skip
    p.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"built-in name or robot file (default: {DEFAULT_ROBOT})"
    )
    p.add_argument("--arm", default=None, help="arm (default: the robot's default arm)")
    p.add_argument("--map", default=None, help="reachability map (default: the cached default map)")
    p.add_argument("--standoff", type=float, default=None,
                   help="TCP distance behind the grasp point [m] (default: 0.15 for TIAGo, else 0)")  # fmt: skip
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--png", default=None, help="PNG of the candidates over the grid")
    p.add_argument("--mcap", default=None, help="also write the candidates (best first) as an MCAP recording")
    _add_bag_args(p)
    p.add_argument("--object-shape", default="auto",
                   help=OBJECT_HELP.replace("first target's grasp point", "--object position"))  # fmt: skip
    p.add_argument("--obstacle", action="append", default=None, help=OBSTACLE_HELP)
    p.add_argument("--clearance", type=finite_float, default=None, metavar="METRES",
                   help="keep this far [m] from the scene near the object (default: as place's)")  # fmt: skip
    _add_motion_and_robustness_arguments(p)
    _add_degrees_argument(p)

    p = command("point", "the object a person points at in an RGB-D frame, and where to stand to pick it up")
    p.add_argument("--rgb", default=None, help="RGB image (PNG or JPEG)")
    p.add_argument("--depth", default=None,
                   help="aligned depth image: 16-bit PNG in millimetres (0: none) or float32 .npy in metres")  # fmt: skip
    p.add_argument("--intrinsics", default=None, help='"fx fy cx cy" [px] or a ROS CameraInfo YAML')
    p.add_argument("--transform", default=None,
                   help='world_T_camera file (4x4, optical frame), or the camera-frame up vector "ux uy uz"')  # fmt: skip
    p.add_argument("--landmarks", default=None,
                   help="JSON of 21 MediaPipe hand landmarks (normalised x, y; relative z) instead of the hand model")  # fmt: skip
    p.add_argument("--selection", default="finger3d", choices=["finger3d", "first", "nearest"],
                   help="finger3d: the object at the smallest angle from the index finger's 3-D line from depth "
                        "(within 16 deg; without depth on the finger nearest, else first); first: the seed's, the first object "
                        "box the finger's image line enters; nearest: the object whose box centre lies at the "
                        "smallest angle from the image line (within 12 deg) (default finger3d)")  # fmt: skip
    p.add_argument("--occupancy", default=None, help="occupancy grid (map_server YAML): also where to stand")
    p.add_argument("--robot-pose", default=None, help='robot pose "x y yaw": rank by motion cost, plan a path')  # fmt: skip
    p.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"built-in name or robot file (default: {DEFAULT_ROBOT})"
    )
    p.add_argument("--arm", default=None, help="arm (default: the robot's default arm)")
    p.add_argument("--map", default=None, help="reachability map (default: the cached default map)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument(
        "--png", default=None, help="picture: the image with hand, line and boxes; candidates from above"
    )
    g = p.add_argument_group(
        "ROS recording (rosbag2 directory, .db3, .mcap, or ROS 1 .bag) instead of the files"
    )
    g.add_argument(
        "--bag", default=None, help="read the frame from this recording: image, depth, CameraInfo, tf"
    )
    g.add_argument("--rgb-topic", default=None, help="sensor_msgs/Image colour topic (rgb8, bgr8, rgba8, bgra8, mono8)")  # fmt: skip
    g.add_argument("--depth-topic", default=None,
                   help="sensor_msgs/Image aligned depth topic (16UC1 [mm] or 32FC1 [m]); the message closest in stamp")  # fmt: skip
    g.add_argument("--camera-info-topic", default=None, help="sensor_msgs/CameraInfo topic; the message closest in stamp")  # fmt: skip
    g.add_argument("--bag-frame", default="last", choices=["last", "first"],
                   help="which colour message (default last); the camera is posed by /tf and /tf_static at its stamp")  # fmt: skip
    g.add_argument("--world-frame", default="map", help="frame of the results (default map)")
    _add_motion_and_robustness_arguments(p)
    _add_degrees_argument(p)

    p = command("navigate", "a base path across the planar regions of a scanned scene")  # fmt: skip
    p.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"built-in name or robot file (default: {DEFAULT_ROBOT})"
    )
    p.add_argument("--cloud", default=None, help="scene cloud: .pcd, .ply, .bt, .npy, .xyz (z up, or --transform)")  # fmt: skip
    p.add_argument("--transform", default=None, help='world_T_sensor file, or the sensor-frame up vector "ux uy uz"')  # fmt: skip
    _add_bag_args(p, grid=False)
    _add_fuse_args(p)
    p.add_argument("--mcap", default=None, help="also write the path and the regions as an MCAP recording")
    p.add_argument("--start", required=True, help='start base pose "x y yaw" [m, rad]')
    p.add_argument("--goal", required=True, help='goal base pose "x y yaw" [m, rad]')
    p.add_argument("--planner", default="rrt", choices=["rrt", "regions"],
                   help="OMPL RRTConnect or the region-graph planner (default rrt)")  # fmt: skip
    p.add_argument("--time-limit", type=float, default=2.0, help="RRT planning time limit [s] (default 2)")
    p.add_argument("--resolution", type=float, default=None,
                   help="height-map cell [m] (default: from the cloud's extent and point spacing, 0.02-0.05)")  # fmt: skip
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--out", default=None, help="PNG of the path over regions and obstacles (as Fig. 4)")
    _add_degrees_argument(p)

    p = command("surface-map", "where to stand to work on a whole table or shelf")
    p.add_argument(
        "--robot", default=DEFAULT_ROBOT, help=f"built-in name or robot file (default: {DEFAULT_ROBOT})"
    )
    p.add_argument("--arms", default="any",
                   help="any (either arm), both (both arms) or one arm's name (default: any)")  # fmt: skip
    p.add_argument("--polygon", required=True, help='the surface outline "x1,y1;x2,y2;..." [m]')
    p.add_argument("--height", type=float, required=True, help="surface height above the floor [m]")
    p.add_argument("--resolution", type=float, default=0.05, help="grid spacing [m] (default 0.05)")
    p.add_argument("--orientations", type=int, default=16, help="base headings (default 16)")
    p.add_argument("--out", required=True, help="surface map file (.smap, sparse HDF5)")
    p.add_argument("--png", default=None, help="PNG of R_S over the floor around the surface")
    p.add_argument("--samples", type=count, default=DEFAULT_MAP_SAMPLES,
                   help="samples of the cached reachability maps, built once per arm (default 2e8)")  # fmt: skip

    p = command("surface-sample", "sample good, spread-out base poses from a surface map")  # fmt: skip
    p.add_argument("--map", required=True, help="surface map from surface-map")
    p.add_argument("--n", type=int, default=5, help="poses to sample (default 5)")
    p.add_argument("--occupancy", default=None, help="operational area: map_server YAML (free cells only)")
    _add_bag_args(p, clouds=False)
    p.add_argument("--candidates", type=int, default=40, help="N: best of N valid candidates (default 40)")
    p.add_argument("--no-discount", action="store_true", help="do not spread consecutive poses (eq. 3)")
    p.add_argument("--robot", default=None, help="robot file for custom robots (default: the map's robot)")
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")

    p = command("occupancy", "read an occupancy grid (map_server YAML + image) as nav2 does")  # fmt: skip
    p.add_argument("map", help="map YAML file")

    p = command("segment", "planar regions, polygons and region graph of a point cloud")
    p.add_argument("cloud", nargs="?", default=None, help="point cloud: .pcd, .ply, .bt (OctoMap), .npy, .xyz")  # fmt: skip
    p.add_argument("--algorithm", choices=["robust", "baseline"], default="robust",
                   help="robust or baseline region growing (default: robust)")  # fmt: skip
    p.add_argument("--transform", default=None,
                   help='world_T_sensor: a file with a 4x4 matrix, or the sensor-frame up vector "ux uy uz"')  # fmt: skip
    p.add_argument("--resolution", type=float, default=None,
                   help="height-map cell [m] (default: from the cloud's extent and point spacing, 0.02-0.05)")  # fmt: skip
    p.add_argument("--out", default=None, help="PNG of the regions")
    _add_bag_args(p, grid=False)
    _add_fuse_args(p)

    scene = sub.add_parser("scene", help="generated test scenes with ground truth", description="generated scenes")  # fmt: skip
    scene_sub = scene.add_subparsers(dest="scene_command", metavar="SUBCOMMAND", parser_class=_Parser)
    scene_sub.required = True
    p = command("generate", "write a random scene's cloud and ground truth", scene_sub,
                "A floor, inclined planes of a size class and a box with objects, "
                "with Gaussian height noise.")  # fmt: skip
    p.add_argument("--size-class", default="small", choices=["small", "medium", "large"],
                   help="plane sides 1-1.5, 1.5-2 or 2-2.5 m (default small)")  # fmt: skip
    p.add_argument("--planes", type=nonneg_int, default=2, help="number of inclined planes (default 2)")
    p.add_argument("--sigma", type=float, default=0.025, help="height noise std [m] (default 0.025)")
    p.add_argument("--extent", type=float, default=10.0, help="scene side [m] (default 10)")
    p.add_argument("--no-box", action="store_true", help="leave out the box with objects")
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")
    p.add_argument("--out", required=True, help="cloud file (.ply, .pcd or .npy)")
    p.add_argument("--truth", default=None, help="ground-truth JSON (default: next to --out)")

    _add_plugin_commands(sub, [ep for ep in plugins if everything or ep.name == chosen])

    _add_view_command(sub)

    p = command("demo", "the main job on built-in defaults: out/demo.json and out/demo.png")
    p.add_argument("--out", default="out", help="output directory (default: out)")
    p.add_argument(
        "--samples", type=count, default=DEFAULT_MAP_SAMPLES, help="samples of the cached map (default 2e8)"
    )
    p.add_argument("--seed", type=nonneg_int, default=0, help="random seed (default 0)")
    return parser


def _plugins() -> list[EntryPoint]:
    """The entry points of :data:`PLUGIN_GROUP`, by name, a name registered twice (two installs) once.

    Listed from the installed packages' metadata: none of their modules is imported.
    """
    from importlib.metadata import entry_points

    found: dict[str, EntryPoint] = {}
    for ep in sorted(entry_points(group=PLUGIN_GROUP), key=lambda e: e.name):
        found.setdefault(ep.name, ep)
    return list(found.values())


def _add_plugin_commands(sub: Any, plugins: Sequence[EntryPoint]) -> None:
    """Commands that other packages register under the entry-point group :data:`PLUGIN_GROUP`.

    Each entry point is a function called with ``baseplace``'s subparsers (it adds its commands
    with ``sub.add_parser``, as the papers' experiments add ``experiment``); its name is the
    command it adds, so that a command line naming another command never imports it. A plugin
    that fails to load is left out with one ``warning: ...`` line, and the other commands still work.
    """
    for ep in plugins:
        try:
            ep.load()(sub)
        except Exception as exc:  # a broken plugin must not take the library's commands with it
            first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
            sys.stderr.write(f"warning: the {ep.name!r} commands ({ep.value}) did not load: {first}\n")


def _add_robot_commands(sub: Any, command: Callable[..., argparse.ArgumentParser]) -> None:
    robot = sub.add_parser("robot", help="check a robot file: arms, joints, TCP axes, footprint, a picture",
                           description="robot files (see docs/robots.md)")  # fmt: skip
    robot_sub = robot.add_subparsers(dest="robot_command", metavar="SUBCOMMAND", parser_class=_Parser)
    robot_sub.required = True
    p = command("check", "load a robot file, print what it describes, render it and warn where it looks wrong", robot_sub,
                "Prints arms, joints, limits, TCP approach axes, footprint and self-collision pairs; renders "
                "the collision geometry to a PNG; warns about approach axes that do not point out of the hand, "
                "links without collision geometry and footprints smaller than the base.")  # fmt: skip
    p.add_argument("robot", help="robot file (.toml/.yaml) or built-in name")
    p.add_argument("--png", default=None, help="picture of the robot (default: NAME_check.png here)")
    p.add_argument("--pairs", action="store_true", help="list the active self-collision pairs")


def _add_view_command(sub: Any) -> None:
    """Add ``view`` to ``baseplace``'s subparsers."""
    p = sub.add_parser("view", help="interactive 3D viewer of any result in the browser (viser)",
                       description="interactive 3D viewer of any result in the browser (viser)")  # fmt: skip
    p.set_defaults(func=_view)
    p.add_argument(
        "result", nargs="?", default=None,
        help="the --json of place, candidates, surface-map, surface-sample, navigate, segment, point or demo, "
        "with the inputs it names (default: out/demo.json), or a reachability map (.rmap, .h5, .hdf5)",
    )  # fmt: skip
    p.add_argument(
        "--map", default=None, help="draw this reachability map (build-map's --out) instead of a result"
    )
    p.add_argument("--out", default=None,
                   help="with a map: write slices of it to this PNG (.png, .pdf, .svg) instead of serving a 3D view")  # fmt: skip
    p.add_argument("--port", type=int, default=8080, help="port (default 8080; 0: any free port)")
    p.add_argument(
        "--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)"
    )
    g = p.add_argument_group("inputs in place of those the result names (moved files, or none named)")
    g.add_argument("--cloud", action="append", default=None, help="point cloud; repeat for several")
    g.add_argument(
        "--transform", action="append", default=None, help="world_T_sensor file or up vector per --cloud"
    )
    g.add_argument(
        "--floor", type=float, default=None, help="floor height [m] added under the cloud, as --floor"
    )
    g.add_argument("--occupancy", default=None, help="occupancy grid (map_server YAML)")
    g.add_argument("--surface-map", default=None, help="surface map file (surface-map's --out)")
    g.add_argument("--robot", default=None, help="robot name or robot file")


def _view(a: argparse.Namespace) -> int:
    """Serve the interactive 3D viewer of any result (the demo's by default) until Ctrl-C."""
    given = {"cloud": a.cloud, "transform": a.transform, "floor": a.floor, "occupancy": a.occupancy,
             "surface_map": a.surface_map, "robot": a.robot}  # fmt: skip
    return view.view_job(view.ViewJob(a.result, a.map, a.out, a.host, a.port, given), announce=print)


def _cache_warnings_in_one_line(show: Callable[..., None]) -> Callable[..., None]:
    """``warnings.showwarning`` that prints a skipped cache entry as ``warning: ...``, others with ``show``."""
    from baseplace.files import CacheSkipped

    def showwarning(message: Warning | str, category: type[Warning], *where: Any, **kw: Any) -> None:
        if issubclass(category, CacheSkipped):
            sys.stderr.write(f"warning: {message}\n")
        else:
            show(message, category, *where, **kw)

    return showwarning


def _echo(args: argparse.Namespace) -> dict[str, Any]:
    """The arguments as given, for a failure report."""
    return {k: v for k, v in vars(args).items() if k not in ("func", "job", "json") and not k.startswith("_")}


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: parse, run one job, print its report; errors map to exit codes 2 and 3."""
    argv = list(sys.argv[1:] if argv is None else argv)
    words = [a for a in argv if not a.startswith("-")]
    _Parser.json_argv = argv if "--json" in argv else None
    _Parser.json_kind = KINDS.get(words[0]) if words else None
    args = build_parser(words[0] if words else None).parse_command_line(argv)
    from baseplace.jobs.report import NoResultError, Report
    from baseplace.status import ProgressBars, elapsed_status

    as_json = getattr(args, "json", False)
    bars = ProgressBars(enabled=not as_json)
    try:
        with elapsed_status(f"baseplace {args.command}", enabled=not as_json), warnings.catch_warnings():
            warnings.showwarning = _cache_warnings_in_one_line(warnings.showwarning)
            args = in_radians(args)
            report = args.job(args, bars) if hasattr(args, "job") else args.func(args)
    except NoResultError as exc:
        if as_json:
            _out(exc.report.dumps() + "\n")
        sys.stderr.write(f"error: {exc}\n")
        return exc.exit_code
    except BaseplaceError as exc:
        if as_json:
            _emit_error(KINDS.get(args.command), str(exc), exc.exit_code, _echo(args))
        sys.stderr.write(f"error: {exc}\n")
        return exc.exit_code
    except OSError as exc:
        from baseplace.files import disk_full_reason, is_disk_full
        from baseplace.guards import MAX_COMPONENT_BYTES, MAX_PATH_BYTES

        if is_disk_full(exc):
            # a writer that does not go through baseplace.files: its message is a library's, maybe lines long
            message = f"cannot write {exc.filename or 'an output'}: {disk_full_reason(exc)}; free some space"
        elif exc.errno == errno.ENAMETOOLONG:  # a path given to a reader that does not check its length first
            name = brief(os.fsdecode(exc.filename), 60) if isinstance(exc.filename, str | bytes) else "a path"
            message = (f"{name}: the file name is too long (the limits are {MAX_COMPONENT_BYTES} bytes a "
                       f"component and {MAX_PATH_BYTES} in all)")  # fmt: skip
        else:
            raise
        if as_json:
            _emit_error(KINDS.get(args.command), message, 2, _echo(args))
        sys.stderr.write(f"error: {message}\n")
        return 2
    except KeyboardInterrupt:
        sys.stderr.write("error: interrupted\n")
        return 130
    except MemoryError:  # an internal failure: every size a user gives is checked before it is allocated
        sys.stderr.write(
            "error: out of memory (an internal failure; BASEPLACE_MAX_MEMORY_MB lowers the limits)\n"
        )
        return 1
    finally:
        bars.close()
    if not isinstance(report, Report):  # view and the experiments print their own output
        return int(report)
    obj = report.to_json()
    if as_json:
        return _out(json.dumps(obj) + "\n") or 0
    from baseplace.jobs.text import report_text

    return _out(report_text(obj) + "\n") or 0


def _out(text: str) -> int | None:
    """Print ``text`` on stdout; None, or 2 when stdout is a file on a full disk (one error line)."""
    try:
        sys.stdout.write(text)
        sys.stdout.flush()
    except OSError as exc:
        from baseplace.files import disk_full_reason, is_disk_full

        if not is_disk_full(exc):
            raise
        with contextlib.suppress(OSError, ValueError):  # the rest of the buffer goes nowhere, not into a
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # traceback at exit
        sys.stderr.write(f"error: cannot write the report to stdout: {disk_full_reason(exc)}\n")
        return 2
    return None


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
