"""The ``reach`` and ``build_map`` jobs: look up and build reachability maps."""

from __future__ import annotations

import json
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from baseplace.errors import InputError
from baseplace.jobs.inputs import (
    CHECK_MARGIN,
    DEFAULT_MAP,
    Progress,
    base_xyyaw,
    check_map_file,
    check_robot_name,
    load_robot,
    map_output,
    map_step,
    map_timing,
    out_path,
    step_progress,
    target_pose,
    xyz_text,
)
from baseplace.jobs.report import BuildMapReport, ReachReport, RobotRef
from baseplace.robots.defaults import DEFAULT_ROBOT

if TYPE_CHECKING:
    from baseplace.reachability.build import BuildSettings
    from baseplace.reachability.rmap import ReachabilityMap
    from baseplace.robots.model import Robot

MAP_SUFFIXES = (".rmap", ".h5", ".hdf5")


def read_pose_file(
    path: str, width: int, what: str, angles: tuple[tuple[str, float, str], ...] = ()
) -> np.ndarray:
    """Rows of ``width`` finite numbers, one pose a line ("#" comments, commas or spaces).

    ``angles``: the limits of the last columns, angles [rad] (:func:`~baseplace.geometry.poses.check_angles`).
    """
    from baseplace.geometry.poses import check_angles

    p = Path(path)
    if not p.is_file():
        raise InputError(f"{what} file {p} does not exist")
    rows = []
    for lineno, line in enumerate(p.read_text().splitlines(), 1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        try:
            values = [float(v) for v in text.replace(",", " ").split()]
        except ValueError:
            raise InputError(f"{p}:{lineno}: {what} must be numbers, got {text!r}") from None
        if len(values) != width:
            raise InputError(f"{p}:{lineno}: a {what} needs {width} numbers, got {len(values)}")
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"{p}:{lineno}: {what} contains NaN or infinity")
        try:
            check_angles(values[width - len(angles) :], angles)
        except InputError as exc:
            raise InputError(f"{p}:{lineno}: {exc}") from None
        rows.append(values)
    if not rows:
        raise InputError(f"{what} file {p} holds no poses")
    return np.array(rows)


@dataclass
class ReachJob:
    """The inputs of :func:`reach_job`: exactly one of ``target``/``targets`` and of ``base``/``bases``.

    Attributes:
        map: reachability map (loaded or a file); None or "default": the robot's cached default map
            (built on first use).
        target: one world TCP pose "x y z roll pitch yaw" [m, rad].
        targets: a file with one target per line, or the targets' texts, paired row by row with the bases.
        base: one base pose "x y yaw" [m, rad].
        bases: a file with one base pose per line, or the base poses' texts.
        robot: check the map was built for this robot (the default map's robot; None: tiago).
    """

    map: ReachabilityMap | str | None = None
    target: str | None = None
    targets: str | Sequence[str] | None = None
    base: str | None = None
    bases: str | Sequence[str] | None = None
    robot: Robot | str | None = None

    def echo(self) -> dict[str, Any]:
        """The inputs as given."""
        return {"map": self.map if isinstance(self.map, str | None) else "loaded", "target": self.target,
                "targets": _echo_poses(self.targets), "base": self.base, "bases": _echo_poses(self.bases),
                "robot": self.robot if isinstance(self.robot, str | None) else self.robot.name}  # fmt: skip


def _given_poses(matrices: list[np.ndarray], what: str, fields: str) -> np.ndarray:
    if not matrices:
        raise InputError(f'give at least one {what} "{fields}"')
    return np.stack(matrices)


def _echo_poses(poses: str | Sequence[str] | None) -> str | list[str] | None:
    return poses if isinstance(poses, str | None) else list(poses)


def _map_box(rmap: ReachabilityMap | str | None, robot: Robot | None) -> tuple[np.ndarray, np.ndarray] | None:
    """The box of a map's voxel grid in the base frame [m], read without its cells.

    The build sizes the grid to hold every TCP position the arm can reach (``rmap.reach_bounds``):
    outside it, every value is 0. None where the file is unreadable or the map is not ``robot``'s:
    loading the map says what is wrong. The default map (not built yet, maybe): the box of the
    arm's reach bound from the robot model (:class:`~baseplace.jobs.inputs.ReachBound`).
    """
    if rmap is None or rmap == DEFAULT_MAP:
        from baseplace.jobs.inputs import ReachBound

        assert robot is not None  # the default map's robot
        bound = ReachBound.of_robot(robot, robot.spec.default_arm)
        r = bound.radius
        return np.array([-r, -r, -r]), np.array([r, r, bound.height])
    if not isinstance(rmap, str):
        g = rmap.grid
        lo = np.asarray(g.origin, dtype=float)
        return lo, lo + np.asarray(g.shape, dtype=float) * g.voxel_size
    import h5py

    from baseplace.h5files import CORRUPT_FILE_ERRORS, read_text

    try:
        with h5py.File(rmap, "r") as f:
            grid = json.loads(read_text(f, "grid"))
            info = json.loads(read_text(f, "info"))
        if robot is not None and (info["robot"], info["urdf_sha256"]) != (robot.name, robot.spec.urdf_sha256):
            return None
        lo = np.array([float(v) for v in grid["origin"]])
        hi = lo + np.array([int(v) for v in grid["shape"]], dtype=float) * float(grid["voxel_size"])
    except (*CORRUPT_FILE_ERRORS, TypeError):
        return None  # loading the map says what is wrong
    return (lo, hi) if lo.shape == hi.shape == (3,) and np.isfinite([lo, hi]).all() else None


def _check_in_reach(job: ReachJob, robot: Robot | None, T_base_target: np.ndarray, n_targets: int) -> None:
    """Refuse a query in which no target lies within the arm's reach of its base pose.

    Every value would be 0: most likely millimetres, or a target in another frame. The arm's
    reach is the box of the map's grid, read from the file's header before its cells.

    Args:
        job: the query (for the map and the message).
        robot: the robot the map must be for, if given.
        T_base_target: (P, 4, 4) each target in the frame of the base pose it pairs with.
        n_targets: targets given (1: paired with every base pose, else row by row).
    """
    box = _map_box(job.map, robot)
    if box is None:
        return
    lo, hi = box
    p = T_base_target[:, :3, 3]
    outside = np.linalg.norm(p - np.clip(p, lo, hi), axis=1)
    if (outside <= CHECK_MARGIN).any():
        return
    i = int(np.argmin(outside))
    pair = "--target" if job.target is not None else f"target {i if n_targets > 1 else 0}"
    base = "--base" if job.base is not None else f"base pose {i}"
    box_text = ", ".join(f"{a} {u:.2f}..{v:.2f}" for a, u, v in zip("xyz", lo, hi, strict=True))
    raise InputError(
        f"{pair} is {outside[i]:.2f} m beyond the arm's reach from {base}"
        f"{' (the nearest pair)' if len(p) > 1 else ''}: at {xyz_text(p[i])} m in the base frame, outside "
        f"the map's reach box ({box_text}); coordinates are in metres"
    )


def reach_job(job: ReachJob, progress: Progress | None = None) -> ReachReport:
    """Inverse-reachability values of the targets from the base poses, in [0, 1].

    Without a map (or ``map="default"``), the robot's cached default map, built on first use
    behind ``progress``.

    Raises:
        InputError: not exactly one of each pair, malformed poses, a map of another robot.
    """
    t0 = time.perf_counter()
    if (job.target is None) == (job.targets is None):  # before the map's imports (numba)
        raise InputError("give exactly one of --target or --targets FILE")
    if (job.base is None) == (job.bases is None):
        raise InputError("give exactly one of --base or --bases FILE")
    check_robot_name(job.robot)
    check_map_file(job.map)
    from baseplace.geometry.poses import RPY_LIMITS, YAW_LIMIT, BasePose, invert_transforms, pose_from_xyz_rpy

    default = job.map is None or job.map == DEFAULT_MAP
    robot = (
        load_robot(job.robot or DEFAULT_ROBOT)
        if default
        else None
        if job.robot is None
        else load_robot(job.robot)
    )
    if job.target is not None:
        targets = target_pose(job.target, "--target")[None]
    elif isinstance(job.targets, str):
        targets = pose_from_xyz_rpy(read_pose_file(job.targets, 6, "target pose", RPY_LIMITS))
    else:
        given = [target_pose(t, f"--targets {k}") for k, t in enumerate(job.targets or ())]
        targets = _given_poses(given, "target", "x y z roll pitch yaw")
    if job.base is not None:
        bases = BasePose(*base_xyyaw(job.base, "--base")).matrix()[None]
    elif isinstance(job.bases, str):
        bases = BasePose.batch_matrix(read_pose_file(job.bases, 3, "base pose", (YAW_LIMIT,)))
    else:
        given = [BasePose(*base_xyyaw(b, f"--bases {k}")).matrix() for k, b in enumerate(job.bases or ())]
        bases = _given_poses(given, "base pose", "x y yaw")
    if len(targets) != len(bases) and len(targets) != 1:
        raise InputError(
            f"--targets has {len(targets)} poses but --bases has {len(bases)}; they pair row by row"
        )
    _check_in_reach(job, robot, invert_transforms(bases) @ targets, len(targets))  # before the map is read
    from baseplace.reachability.cache import resolve_map
    from baseplace.reachability.storage import check_map_matches, load_map

    chosen = None
    if default:
        assert robot is not None
        t_map = time.perf_counter()
        chosen = resolve_map(robot, None, None, progress)
        rmap, map_s = chosen.rmap, time.perf_counter() - t_map
    else:
        assert job.map is not None
        rmap, map_s = job.map if not isinstance(job.map, str) else load_map(job.map), 0.0
        if robot is not None:
            check_map_matches(rmap, robot, rmap.info.arm, str(job.map))
    t_load = time.perf_counter()
    if len(targets) == 1:
        values = rmap.inverse(targets[0], bases)
    else:
        values = rmap.reachability(invert_transforms(bases) @ targets)
    return ReachReport(
        robot=None if robot is None else RobotRef.of(robot, rmap.info.arm), inputs=job.echo(),
        values=[round(float(v), 6) for v in values],
        timings_ms={"load": (t_load - t0 - map_s) * 1e3, **({} if chosen is None else map_timing(chosen, map_s)),
                    "query": (time.perf_counter() - t_load) * 1e3},
        outputs={} if chosen is None else map_output(chosen),
    )  # fmt: skip


@dataclass
class BuildMapJob:
    """The inputs of :func:`build_map_job`.

    Attributes:
        out: the map file (.rmap, HDF5).
        robot: built-in name, robot file or loaded Robot (a file or name with ``scheduler``).
        arm: the arm (None: the default arm).
        settings: samples, seed, resolutions, self-collision, manipulability.
        checkpoint: where to save progress (None: no checkpoint).
        checkpoint_every: samples between checkpoints.
        scheduler: dask scheduler "tcp://host:port" or "local" (None: this process).
        workers: threads of this process, or local worker processes with ``scheduler="local"``.
    """

    out: str
    robot: Robot | str = DEFAULT_ROBOT
    arm: str | None = None
    settings: BuildSettings | None = None
    checkpoint: Path | None = None
    checkpoint_every: int = 50_000_000
    scheduler: str | None = None
    workers: int | None = None


def set_workers(workers: int | None) -> None:
    """Use ``workers`` numba threads in this process (None: all cores)."""
    if workers is None:
        return
    import os

    import numba

    limit = int(numba.config.NUMBA_NUM_THREADS)  # type: ignore[attr-defined]
    if not (1 <= workers <= limit):
        raise InputError(
            f"--workers must be between 1 and {limit} (this machine has {os.cpu_count() or 1} cores), got {workers}"
        )
    numba.set_num_threads(workers)


def store_in_cache(rmap: ReachabilityMap, path: Path) -> bool:
    """Keep a default map built by ``build-map`` in the per-user cache too; False where it cannot."""
    from baseplace.files import OutputError, private_dir, skip_cache_entry
    from baseplace.reachability.storage import save_map

    try:
        private_dir(path.parent)
        save_map(rmap, path, compress=False)
    except OutputError as exc:
        skip_cache_entry("the map", path.parent, exc)
        return False
    except (OSError, InputError):
        return False  # a read-only cache: the map was written to --out all the same
    return True


def build_map_job(job: BuildMapJob, progress: Progress | None = None) -> BuildMapReport:
    """Build a reachability map by random joint sampling and save it to ``job.out``.

    A second build to the same file waits for the first; the map is saved before its checkpoint goes.

    Raises:
        InputError: bad input (an unknown arm, bad settings, an unwritable output, bad workers).
    """
    out = out_path(job.out, "--out", MAP_SUFFIXES)  # outputs first: before the imports and any work
    check_robot_name(job.robot, job.arm)
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.reachability.cache import cached_map_path
    from baseplace.reachability.storage import load_map, save_map

    assert out is not None
    if job.scheduler is None:
        set_workers(job.workers)
    settings = job.settings or BuildSettings()
    robot = load_robot(job.robot)
    robot.arm(job.arm)  # validate before spending time
    arm_name = job.arm or robot.spec.default_arm
    update = step_progress(progress, map_step(robot.name, arm_name), settings.samples)
    cached = cached_map_path(robot, settings, arm_name)
    reused = cached.is_file()
    if reused:  # the per-user cache holds this very map (the default map after a first run): no rebuild
        rmap = load_map(cached, robot, arm_name)
        if out.resolve() != cached.resolve():
            save_map(rmap, out)
    elif job.scheduler is None:
        rmap = build_map(robot, job.arm, settings, update, job.checkpoint, job.checkpoint_every, save_to=out)
    else:
        import logging

        import distributed  # noqa: F401  (it sets its loggers' levels on import)

        from baseplace.files import output_lock, remove_stray_temporaries
        from baseplace.reachability.distributed import build_map_distributed, connect

        for name in ["distributed", "asyncio", *logging.root.manager.loggerDict]:  # faults: one line of ours
            if name.startswith(("distributed", "asyncio")):
                logging.getLogger(name).setLevel(logging.CRITICAL)
        if not isinstance(job.robot, str):
            raise InputError(
                "a distributed build needs the robot as a built-in name or robot file, not a loaded Robot"
            )
        with output_lock(out), connect(job.scheduler, n_workers=job.workers) as client:
            remove_stray_temporaries(out)
            rmap = build_map_distributed(job.robot, job.arm, settings, client, update, job.checkpoint,
                                         job.checkpoint_every, save_to=out)  # fmt: skip
    # the default map built here is kept in the cache too: place, reach and explain reuse it
    stored = reused or (settings == BuildSettings() and store_in_cache(rmap, cached))
    cached_at = str(cached) if stored else None
    inputs = {"out": job.out, "robot": job.robot if isinstance(job.robot, str) else robot.name, "arm": job.arm,
              "samples": settings.samples, "seed": settings.seed, "voxel_size": settings.voxel_size,
              "orientation_resolution": settings.orientation_resolution, "scheduler": job.scheduler,
              "workers": job.workers}  # fmt: skip
    info = rmap.info
    rate = info.samples / info.build_time_s if info.build_time_s > 0 else 0.0
    return BuildMapReport(
        robot=RobotRef.of(robot, info.arm), inputs=inputs, outputs={"map": str(out)},
        timings_ms={"build": info.build_time_s * 1e3}, samples=info.samples, seed=info.seed,
        cells_reached=rmap.n_reached, build_time_s=round(info.build_time_s, 3), samples_per_s=round(rate),
        file_bytes=out.stat().st_size, dropped_self_collision=info.dropped_self_collision,
        support={"count": info.support_count, "threshold": info.support_threshold, "fill": info.fill_threshold}
        if info.supported else None,
        quality=json.loads(info.quality) if info.quality else None, cached_at=cached_at, reused=reused,
    )  # fmt: skip
