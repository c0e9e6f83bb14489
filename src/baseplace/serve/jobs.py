"""The service's jobs: request fields in, the jobs layer's report out.

Every endpoint builds the inputs of its job in :mod:`baseplace.jobs` from the request fields and
the warm state (robots, maps, a scene's points, grid and
:class:`~baseplace.placement.scene_cache.SceneCache`), calls the job, and returns the job's
``baseplace.result/1`` report: the JSON of ``baseplace COMMAND --json`` for the same inputs. A job
that fails raises :class:`JobFailed` with the CLI's one-line message, its exit code and the
failure report the CLI would print.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from baseplace.errors import BaseplaceError, InputError

if TYPE_CHECKING:
    from baseplace.jobs.report import Report
    from baseplace.serve.state import Scene, ServiceState


class JobFailed(BaseplaceError):
    """A job failed: the CLI's one line, its exit code (2 bad input, 3 nothing found) and report.

    ``report`` is the ``baseplace.result/1`` object the CLI prints with ``--json``: the job's
    partial report when it ran and found nothing, else the failure envelope of the command.
    """

    def __init__(self, message: str, exit_code: int, report: dict[str, Any]) -> None:
        super().__init__(message)
        self.exit_code = exit_code
        self.report = report


def failure_report(
    kind: str, message: str, exit_code: int, inputs: dict[str, Any] | None = None
) -> dict[str, Any]:
    """The CLI's failure report of a command that could not start (``kind``, the one line, exit 2 or 3)."""
    from baseplace.jobs.report import ErrorReport

    return ErrorReport(kind_name=kind, inputs=inputs or {}).failed(message, exit_code).to_json()


def run_job(
    kind: str, inputs: dict[str, Any], job: Callable[[], Report], folder: str | None = None
) -> dict[str, Any]:
    """Call a job: its report as JSON, or :class:`JobFailed` with the CLI's line and report.

    ``folder``: the service's own folder, cut from the answer's paths (they name the scene's
    files as ``SCENE_ID/...``, never a path of the server).
    """
    from baseplace.jobs.report import NoResultError

    try:
        report = job().to_json()
    except NoResultError as exc:
        message = _cut(str(exc), folder)
        raise JobFailed(
            message, exc.exit_code, _robot_file_name(_cut(exc.report.to_json(), folder))
        ) from None
    except BaseplaceError as exc:
        message = _cut(str(exc), folder)
        code = exc.exit_code if exc.exit_code in (2, 3) else 2
        raise JobFailed(message, code, failure_report(kind, message, code, _cut(inputs, folder))) from None
    out: dict[str, Any] = _cut(report, folder)
    return _robot_file_name(out)


def _robot_file_name(report: dict[str, Any]) -> dict[str, Any]:
    """The report with its robot's URDF named by file name only: a server's paths stay on the server."""
    robot = report.get("robot")
    if isinstance(robot, dict) and isinstance(robot.get("urdf"), str):
        report["robot"] = {**robot, "urdf": robot["urdf"].replace("\\", "/").rsplit("/", 1)[-1]}
    return report


def _cut(value: Any, folder: str | None) -> Any:
    """``value`` with ``folder/`` cut from every text in it."""
    if not folder:
        return value
    if isinstance(value, str):
        return value.replace(folder + "/", "")
    if isinstance(value, dict):
        return {k: _cut(v, folder) for k, v in value.items()}
    if isinstance(value, list):
        return [_cut(v, folder) for v in value]
    return value


CLI_NAMES = {"targets": "target", "grasp_points": "grasp_point", "obstacles": "obstacle"}
"""Request fields named otherwise than the CLI's options (``--target``, repeated, is ``targets``)."""


def in_radians(command: str, req: dict[str, Any]) -> dict[str, Any]:
    """The request's angles in radians: with ``degrees``, converted as the CLI's ``--degrees`` converts them.

    Without ``degrees`` the request is already in radians: it is passed on as it is (a copy).
    """
    if not req.get("degrees"):
        return dict(req)
    import argparse

    from baseplace.argtypes import in_radians as cli_in_radians

    names = {k: v for k, v in CLI_NAMES.items() if k in req}
    args = argparse.Namespace(command=command, **{names.get(k, k): v for k, v in req.items()})
    request_names = {v: k for k, v in names.items()}
    return {request_names.get(k, k): v for k, v in vars(cli_in_radians(args)).items() if k != "command"}


def _obstacles(scene: Scene | None, req: dict[str, Any]) -> list[str]:
    """The scene's obstacles (given on upload), then the request's: ``box#k`` counts through both."""
    return [*(scene.obstacles if scene is not None else ()), *(req.get("obstacles") or [])]


def place(state: ServiceState, scene: Scene, req: dict[str, Any], lane: str = "jobs") -> dict[str, Any]:
    """``baseplace place --json`` on an uploaded scene, with the scene's cache and warm robots and maps.

    The scene's grid (a recording's map topic, or POST /scenes/{id}/grid) is the CLI's
    ``--occupancy`` unless ``use_grid`` is off. ``lane``: whose robots (the thread it runs on).
    """
    from baseplace.jobs.inputs import CloudInput, motion_and_robustness
    from baseplace.jobs.place import PlaceJob, place_job
    from baseplace.placement.pipeline import PlaceSettings

    def job() -> Report:
        r = in_radians("place", req)
        motion, robustness = motion_and_robustness(r)
        settings = PlaceSettings(strategy=r["strategy"], placements=r["placements"], tries=r["tries"],
                                 resolution=r["resolution"], motion=motion, robustness=robustness,
                                 clearance=r["clearance"], stand_on=r["stand_on"])  # fmt: skip
        robot = state.robot(r["robot"], lane=lane)
        rmap = state.reach_map(robot, r["arm"])
        grid = scene.grid if r["use_grid"] else None
        return place_job(PlaceJob(r["targets"], robot, r["arm"], CloudInput(points=scene.cloud), grid,
                                  map=rmap, settings=settings, seed=r["seed"], start=r["start"],
                                  planner=r["planner"], object=r["object"], cache=scene.cache,
                                  grasp_points=r["grasp_points"], obstacles=_obstacles(scene, r)))  # fmt: skip

    return _with_scene(run_job("place", req, job, str(state.folder)), scene)


def explain(state: ServiceState, scene: Scene | None, req: dict[str, Any]) -> dict[str, Any]:
    """``baseplace explain --json``: the checks of ``place`` at one base pose, on a scene or on none."""
    from dataclasses import replace

    from baseplace.jobs.explain import ExplainJob, explain_job
    from baseplace.jobs.inputs import CloudInput
    from baseplace.placement.pipeline import PlaceSettings

    def job() -> Report:
        r = in_radians("explain", req)
        settings = PlaceSettings(resolution=r["resolution"], clearance=r["clearance"], stand_on=r["stand_on"])
        if r["no_motion_check"]:
            settings = replace(settings, motion=None)
        robot = state.robot(r["robot"])
        rmap = state.reach_map(robot, r["arm"])
        cloud = CloudInput() if scene is None else CloudInput(points=scene.cloud)
        return explain_job(ExplainJob(r["base"], r["target"], rmap, robot, r["arm"], cloud, r["object"], None,
                                      settings, r["seed"], r["grasp_point"],
                                      cache=None if scene is None else scene.cache,
                                      obstacles=_obstacles(scene, r)))  # fmt: skip

    report = run_job("explain", req, job, str(state.folder))
    return report if scene is None else _with_scene(report, scene)


def candidates(state: ServiceState, scene: Scene, req: dict[str, Any]) -> dict[str, Any]:
    """``baseplace candidates --json`` on an uploaded scene: its grid, and its cloud unless ``use_cloud`` is off."""
    from baseplace.jobs.candidates import CandidatesJob, candidates_job
    from baseplace.jobs.inputs import CloudInput, motion_and_robustness

    def job() -> Report:
        r = in_radians("candidates", req)
        robot = state.robot(r["robot"], lane="commands")
        rmap = state.reach_map(robot, r["arm"])
        cloud = CloudInput(points=scene.cloud) if r["use_cloud"] else CloudInput()
        return candidates_job(CandidatesJob(r["object"], scene.grid, cloud, r["robot_pose"], r["method"],
                                            robot, r["arm"], rmap, r["standoff"], r["seed"],
                                            r["object_shape"], *motion_and_robustness(r),
                                            cache=scene.cache if r["use_cloud"] else None,
                                            obstacles=_obstacles(scene, r), clearance=r["clearance"]))  # fmt: skip

    return _with_scene(run_job("candidates", req, job, str(state.folder)), scene)


def point(state: ServiceState, scene: Scene | None, req: dict[str, Any]) -> dict[str, Any]:
    """``baseplace point --json`` on a frame sent as base64 files; with a scene, its grid's candidates."""
    import base64
    import binascii
    import tempfile
    from pathlib import Path

    from baseplace.jobs.inputs import motion_and_robustness
    from baseplace.jobs.point import PointJob, point_job

    def job() -> Report:
        with tempfile.TemporaryDirectory(dir=state.folder) as folder:
            if req["bag"] is None:
                files = {
                    "rgb": Path(folder) / f"rgb.{req['rgb_format']}",
                    "depth": Path(folder) / f"depth.{req['depth_format']}",
                }
            else:  # the CLI's --bag: the frame and the camera's pose from the recording
                files = {"bag": Path(folder) / f"frame.{req['bag_format']}"}
            for key, path in files.items():
                try:
                    path.write_bytes(base64.b64decode(req[key], validate=True))
                except (binascii.Error, ValueError):
                    raise InputError(f"{key} is not base64") from None
            transform = req["transform"]
            numbers = (transform or "").replace(",", " ").split()
            if len(numbers) == 16:  # a matrix: the file the CLI reads
                (Path(folder) / "T_world_camera.txt").write_text(" ".join(numbers))
                transform = str(Path(folder) / "T_world_camera.txt")
            landmarks = None  # none: MediaPipe's hand landmarker, as the CLI without --landmarks
            if req["landmarks"] is not None:
                landmarks = str(Path(folder) / "landmarks.json")
                Path(landmarks).write_text(json.dumps(req["landmarks"]))
            robot: Any = req["robot"]
            rmap = None
            if scene is not None:
                robot = state.robot(req["robot"], lane="commands")
                rmap = state.reach_map(robot, req["arm"])
            motion, robustness = motion_and_robustness(req)
            rgb, depth = (str(files[k]) if k in files else None for k in ("rgb", "depth"))
            bag = str(files["bag"]) if "bag" in files else None
            return point_job(PointJob(rgb, depth, req["intrinsics"], transform,
                                      landmarks, None if scene is None else scene.grid,
                                      robot, req["arm"], rmap, req["robot_pose"], req["seed"], motion, robustness,
                                      selection=req["selection"], bag=bag, rgb_topic=req["rgb_topic"],
                                      depth_topic=req["depth_topic"], camera_info_topic=req["camera_info_topic"],
                                      world_frame=req["world_frame"], bag_frame=req["bag_frame"]))  # fmt: skip

    inputs = {k: v for k, v in req.items() if k not in ("rgb", "depth", "bag")}
    report = run_job("point", inputs, job, str(state.folder))
    report["inputs"] = {
        k: v for k, v in report["inputs"].items() if k not in ("rgb", "depth", "landmarks", "transform")
    }
    if isinstance(report["inputs"].get("bag"), dict):  # the recording's server-side path is no input
        report["inputs"]["bag"].pop("path", None)
    return report if scene is None else _with_scene(report, scene)


def navigate(state: ServiceState, scene: Scene, req: dict[str, Any]) -> dict[str, Any]:
    """``baseplace navigate --json`` across the scene's planar regions (its segmentation, kept)."""
    from baseplace.jobs.inputs import CloudInput
    from baseplace.jobs.navigate import NavigateJob, navigate_job

    def job() -> Report:
        r = in_radians("navigate", req)
        robot = state.robot(r["robot"], lane="commands")
        return navigate_job(NavigateJob(r["start"], r["goal"], CloudInput(points=scene.cloud), robot,
                                        r["planner"], r["time_limit"], r["resolution"], r["seed"],
                                        cache=scene.cache))  # fmt: skip

    return _with_scene(run_job("navigate", req, job, str(state.folder)), scene)


def surface_map(state: ServiceState, req: dict[str, Any], out: str) -> dict[str, Any]:
    """``baseplace surface-map --json``, the map written to ``out`` (in the service's folder)."""
    from baseplace.jobs.surface import SurfaceMapJob, surface_map_job

    def job() -> Report:
        from baseplace.jobs.surface import surface_arms

        robot = state.robot(req["robot"], lane="commands")
        arms, _ = surface_arms(robot, req["arms"])
        maps = {arm: state.reach_map(robot, arm) for arm in arms}  # the warm maps, loaded once
        return surface_map_job(SurfaceMapJob(req["polygon"], req["height"], out, robot, req["arms"],
                                             req["resolution"], req["orientations"], maps=maps))  # fmt: skip

    return run_job("surface_map", req, job, str(state.folder))


def surface_samples(
    state: ServiceState, req: dict[str, Any], map_file: str, scene: Scene | None
) -> dict[str, Any]:
    """``baseplace surface-sample --json`` from a surface map; a scene's grid as the operational area."""
    from baseplace.jobs.surface import SurfaceSamplesJob, surface_samples_job

    def job() -> Report:
        if scene is not None and scene.grid is None:
            raise InputError(
                f"scene {scene.id} has no occupancy grid: attach one with POST /scenes/{scene.id}/grid"
            )
        grid = None if scene is None else scene.grid
        return surface_samples_job(SurfaceSamplesJob(map_file, req["n"], grid, None, req["candidates"],
                                                     not req["no_discount"], None, req["seed"]))  # fmt: skip

    return run_job("surface_samples", req, job, str(state.folder))


def reach(state: ServiceState, req: dict[str, Any]) -> dict[str, Any]:
    """``baseplace reach --json`` on the robot's default map: targets and base poses paired row by row."""
    from baseplace.jobs.reach import ReachJob, reach_job

    def job() -> Report:
        robot = state.robot(req["robot"])  # its spec only: read from any thread
        rmap = state.reach_map(robot, req["arm"])
        return reach_job(ReachJob(rmap, targets=req["targets"], bases=req["bases"], robot=robot))

    return run_job("reach", req, job)


def segment(scene: Scene, resolution: float | None) -> dict[str, Any]:
    """``baseplace segment --json`` of the scene's cloud (the robust segmentation, kept per scene)."""
    from baseplace.jobs.inputs import CloudInput
    from baseplace.jobs.navigate import SegmentJob, segment_job

    inputs = {"resolution": resolution}
    report = run_job("segment", inputs,
                     lambda: segment_job(SegmentJob(CloudInput(points=scene.cloud), "robust", resolution,
                                                    cache=scene.cache)))  # fmt: skip
    report["cloud"]["path"] = scene.source
    return _with_scene(report, scene)


def _with_scene(report: dict[str, Any], scene: Scene) -> dict[str, Any]:
    report["scene_id"] = scene.id
    return report


def add_grid(scene: Scene, image: bytes, suffix: str, meta: dict[str, Any]) -> dict[str, Any]:
    """Attach an occupancy grid (map_server image + YAML fields) to a scene; ``baseplace occupancy --json``."""
    from baseplace.jobs.world import occupancy_job
    from baseplace.serve.state import attach_grid, write_grid_files

    image_path, yaml_path = write_grid_files(scene, image, suffix, meta)
    try:  # the report as ``baseplace occupancy --json`` gives it
        report = run_job("occupancy", {"map": str(yaml_path)}, lambda: occupancy_job(str(yaml_path)),
                         str(scene.folder.parent))  # fmt: skip
    except BaseException:
        image_path.unlink(missing_ok=True)
        yaml_path.unlink(missing_ok=True)
        raise
    attach_grid(scene, image_path, yaml_path)  # the grid the jobs read
    return _with_scene(report, scene)
