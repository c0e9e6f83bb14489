"""The service's jobs: request fields in, the CLI's JSON out.

``place``, ``reach`` and ``segment`` run on what the service keeps warm (robots, maps, a scene's
:class:`~baseplace.placement.scene_cache.SceneCache`) and return the JSON of ``baseplace place
--json``, ``reach --json`` and ``segment --json``. The other commands (candidates, surface-map,
surface-sample, navigate) run the CLI's own command in this process on the scene's files, so
their inputs, checks, messages and JSON are the CLI's by construction. When the jobs layer
(``baseplace.jobs``) lands, every function here becomes a call of its job.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from baseplace.errors import BaseplaceError, InputError, NothingFoundError
from baseplace.serve.state import Scene, ServiceState


class CommandError(BaseplaceError):
    """A CLI command run for the service exited with an error; ``exit_code`` is the CLI's."""

    def __init__(self, message: str, exit_code: int, report: dict[str, Any] | None = None) -> None:
        super().__init__(message)
        self.exit_code = exit_code
        self.report = report


def _poses6(values: Sequence[str], what: str) -> np.ndarray:
    from baseplace.geometry.poses import parse_pose6

    if not values:
        raise InputError(f'give at least one {what} "x y z roll pitch yaw"')
    return np.stack([parse_pose6(t) for t in values])


def place(state: ServiceState, scene: Scene, req: dict[str, Any]) -> dict[str, Any]:
    """``baseplace place --json`` on an uploaded scene, with the scene's cache and warm robots and maps."""
    from baseplace.geometry.poses import matrix_to_rpy
    from baseplace.placement.motion import MotionSettings
    from baseplace.placement.pipeline import PlaceSettings
    from baseplace.placement.pipeline import place as place_in_scene
    from baseplace.placement.robustness import BaseErrorModel, RobustnessSettings
    from baseplace.placement.verify import contact_summary, most_frequent_contact
    from baseplace.world.grasped_object import parse_grasped_object

    targets = _poses6(req["targets"], "target")
    grasped = parse_grasped_object(req["object"])
    error = BaseErrorModel(req["error_model"], req["sigma_xy"], math.radians(req["sigma_yaw_deg"]),
                           req["xy_tolerance"], req["yaw_tolerance"])  # fmt: skip
    robustness = RobustnessSettings(req["robustness_samples"], error,
                                    "robustness" if req["rank_by_robustness"] else "reachability",
                                    req["min_robustness"], seed=req["seed"])  # fmt: skip
    settings = PlaceSettings(strategy=req["strategy"], placements=req["placements"], tries=req["tries"],
                             resolution=req["resolution"],
                             motion=None if req["no_motion_check"] else MotionSettings(),
                             robustness=robustness)  # fmt: skip
    robot = state.robot(req["robot"])
    rmap = state.reach_map(robot, req["arm"])
    cache = scene.cache
    result = place_in_scene(robot, rmap, cache.points, targets, settings, np.random.default_rng(req["seed"]),
                            grasped=grasped, cache=cache)  # fmt: skip
    arm = robot.arm(rmap.info.arm)
    placements = []
    for p in result.placements:
        T = p.T_world_base
        row: dict[str, Any] = {
            "base_pose": np.round(T, 6).tolist(), "x": round(float(T[0, 3]), 4), "y": round(float(T[1, 3]), 4),
            "z": round(float(T[2, 3]), 4), "yaw": round(p.yaw, 4),
            "roll_pitch_yaw": [round(float(v), 5) for v in matrix_to_rpy(T[:3, :3])],
            "region": p.region, "reachability": round(p.reachability, 5),
            "joints": [dict(zip(p.joint_names, np.round(q, 6).tolist(), strict=True)) for q in p.joints],
        }  # fmt: skip
        if p.motions is not None:
            row["motion"] = [{"path": np.round(m.path, 5).tolist(), "approach": np.round(m.approach, 5).tolist(),
                              "planned": m.planned} for m in p.motions]  # fmt: skip
        if p.robustness is not None:
            row["robustness"] = p.robustness.as_dict()
        placements.append(row)
    report = {
        "robot": {"name": robot.name, "urdf": str(robot.spec.urdf), "base_frame": robot.spec.base_frame,
                  "tcp_frames": {a: s.tcp_frame for a, s in robot.spec.arms.items()}, "arm": arm.name},
        "strategy": req["strategy"], "seed": req["seed"], "targets": list(req["targets"]),
        "placements": placements,
        "tries": result.tries,
        "failures": dict(result.failures),
        "collisions": contact_summary(result.contacts),
        "object": {"requested": req["object"], "found": result.grasped_note,
                   "allowed": None if result.grasped is None else result.grasped.to_json()},
        "floor": None,
        "timings_ms": {k: round(v, 2) for k, v in result.timings_ms.items()},
        "regions": len(result.terrain.segmentation.regions),
        "scene_id": scene.id,
    }  # fmt: skip
    if not placements:
        worst = most_frequent_contact(result.contacts)
        raise CommandError(
            f"no verified placement in {result.tries} tries with {req['strategy']} "
            f"(failures: {dict(result.failures) or 'none'}{'; ' + worst if worst else ''}); "
            f"try --tries, another --strategy, --object or check the target",
            NothingFoundError.exit_code,
            report,
        )
    return report


def reach(state: ServiceState, req: dict[str, Any]) -> dict[str, Any]:
    """``baseplace reach --json`` on the robot's default map: targets and base poses paired row by row."""
    from baseplace.geometry.poses import BasePose, invert_transforms, parse_base_pose

    robot = state.robot(req["robot"])
    rmap = state.reach_map(robot, req["arm"])
    targets = _poses6(req["targets"], "target")
    if not req["bases"]:
        raise InputError('give at least one base pose "x y yaw"')
    poses = [parse_base_pose(b) for b in req["bases"]]
    bases = BasePose.batch_matrix(np.array([[p.x, p.y, p.yaw] for p in poses]))
    if len(targets) != len(bases) and len(targets) != 1:
        raise InputError(f"targets has {len(targets)} poses but bases has {len(bases)}; they pair row by row")
    if len(targets) == 1:
        values = rmap.inverse(targets[0], bases)
    else:
        values = rmap.reachability(invert_transforms(bases) @ targets)
    return {"values": [round(float(v), 6) for v in values]}


def segment(scene: Scene, resolution: float | None) -> dict[str, Any]:
    """``baseplace segment --json`` of the scene's cloud (the robust segmentation, kept per scene)."""
    from baseplace.terrain.pipeline import terrain_json

    terrain = scene.cache.terrain(resolution)
    result = terrain_json(terrain)
    result["cloud"] = {"path": scene.source, "points": scene.points}
    result["algorithm"] = "robust"
    result["resolution"] = terrain.segmentation.hmap.resolution
    result["scene_id"] = scene.id
    return result


def run_command(argv: list[str], folder: str | None = None) -> dict[str, Any]:
    """Run ``baseplace ARGV --json`` in this process: its JSON, or :class:`CommandError` with its error line.

    ``folder``: the service's own folder, cut from the answer's paths (they name the scene's
    files as ``SCENE_ID/...``, never a path of the server).
    """
    from baseplace.cli import main

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            code = main([*argv, "--json"])
        except SystemExit as exc:  # argparse: a bad option value
            code = int(exc.code) if isinstance(exc.code, int) else 2
    stdout, stderr = out.getvalue(), err.getvalue()
    if folder:
        stdout = stdout.replace(json.dumps(folder + "/")[1:-1], "").replace(folder + "/", "")
        stderr = stderr.replace(folder + "/", "")
    lines = [line for line in stderr.splitlines() if line.startswith("error: ")]
    report = None
    text = stdout.strip()
    if text:
        with contextlib.suppress(ValueError):
            report = json.loads(text.splitlines()[-1])
    if code != 0:
        message = lines[-1][len("error: ") :] if lines else f"{argv[0]} failed (exit {code})"
        raise CommandError(message, code, report)
    if report is None:
        raise BaseplaceError(f"{argv[0]} printed no JSON")
    return report


def option_argv(options: dict[str, Any]) -> list[str]:
    """CLI options from request fields: ``{"robot_pose": "0 0 0"}`` -> ``["--robot-pose", "0 0 0"]``.

    None leaves an option out; True is a flag; lists repeat the option. Names are the request
    model's fields, never free text from the request.
    """
    argv: list[str] = []
    for name, value in options.items():
        flag = "--" + name.replace("_", "-")
        if value is None or value is False:
            continue
        if value is True:
            argv.append(flag)
        elif isinstance(value, list):
            for v in value:
                argv += [flag, str(v)]
        else:
            argv += [flag, str(value)]
    return argv


def scene_files(scene: Scene, cloud: bool, grid: str) -> list[str]:
    """The scene's files as CLI options: ``--cloud`` and the grid option ``grid`` (if it has one)."""
    argv = ["--cloud", str(scene.cloud_file)] if cloud else []
    if grid and scene.grid_yaml is not None:
        argv += [grid, str(scene.grid_yaml)]
    return argv


def add_grid(scene: Scene, image: bytes, suffix: str, meta: dict[str, Any]) -> dict[str, Any]:
    """Attach an occupancy grid (map_server image + YAML fields) to a scene; ``baseplace occupancy --json``."""
    from baseplace.world.occupancy import load_occupancy

    if suffix not in ("pgm", "png"):
        raise InputError(f"unknown grid image format {suffix!r}; valid: pgm, png")
    if not image:
        raise InputError("the upload is empty: send the grid image as the request body")
    import uuid

    name = f"grid-{uuid.uuid4().hex[:8]}"  # a new grid never breaks the one the scene has until it is read
    image_path, yaml_path = scene.folder / f"{name}.{suffix}", scene.folder / f"{name}.yaml"
    image_path.write_bytes(image)
    origin = [float(meta["origin_x"]), float(meta["origin_y"]), float(meta["origin_yaw"])]
    doc = {"image": image_path.name, "resolution": float(meta["resolution"]), "origin": origin,
           "negate": int(bool(meta["negate"])), "occupied_thresh": float(meta["occupied_thresh"]),
           "free_thresh": float(meta["free_thresh"]), "mode": str(meta["mode"])}  # fmt: skip
    yaml_path.write_text(json.dumps(doc) + "\n")  # JSON is YAML
    try:
        grid = load_occupancy(yaml_path)
    except BaseException:
        image_path.unlink(missing_ok=True)
        yaml_path.unlink(missing_ok=True)
        raise
    scene.grid_yaml = yaml_path
    report: dict[str, Any] = grid.to_json()
    report["scene_id"] = scene.id
    return report


def add_grid_values(scene: Scene, grid: Any) -> None:
    """Attach an :class:`~baseplace.world.occupancy.OccupancyGrid` (e.g. a recording's) as map_server files.

    Written in map_server's ``raw`` mode (a pixel is the cell value, 255 unknown), which reads
    back cell for cell.
    """
    import cv2

    values = np.asarray(grid.data)
    pixels = np.where((values >= 0) & (values <= 100), values, 255).astype(np.uint8)[::-1]
    ok, png = cv2.imencode(".png", pixels)
    if not ok:
        raise InputError("cannot encode the recording's occupancy grid")
    x, y, yaw = (float(v) for v in grid.origin)
    meta = {"resolution": grid.resolution, "origin_x": x, "origin_y": y, "origin_yaw": yaw, "negate": False,
            "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "raw"}  # fmt: skip
    add_grid(scene, png.tobytes(), "png", meta)
