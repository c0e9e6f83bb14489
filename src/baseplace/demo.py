"""The main job on built-in defaults (`make demo` / `baseplace demo`).

For now: build or reuse the cached default TIAGo map, compute the inverse reachability of a demo
grasp target over base poses around it, verify the best base pose with IK, and write
``out/demo.json`` and ``out/demo_irm.png``.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from baseplace.geometry.poses import BasePose, invert_transforms, parse_pose6
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.reachability.storage import load_map, save_map
from baseplace.robots.codegen import cache_dir
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot

DEMO_TARGET = "1.0 0.5 0.9 0 0 0"


def cached_map(
    robot: Robot,
    settings: BuildSettings,
    arm: str | None = None,
    progress: Callable[[int], None] | None = None,
) -> tuple[ReachabilityMap, Path, bool]:
    """Load the map for these settings from the cache, building and saving it if absent.

    Returns:
        (map, path, built) where built tells whether it was built now.
    """
    arm_name = arm or robot.spec.default_arm
    key = (
        f"{robot.name}-{arm_name}-{robot.spec.urdf_sha256[:12]}-s{settings.samples}-seed{settings.seed}"
        f"-v{settings.voxel_size}-o{settings.orientation_resolution}"
    )
    path = cache_dir().parent / "maps" / f"{key}.rmap"
    if path.is_file():
        return load_map(path, robot, arm_name), path, False
    path.parent.mkdir(parents=True, exist_ok=True)
    rmap = build_map(robot, arm_name, settings, progress)
    save_map(rmap, path)
    return rmap, path, True


def run_demo(
    out_dir: Path,
    samples: int = 50_000_000,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Run the demo and write its JSON and PNG into ``out_dir``; returns the JSON object."""
    from baseplace.viz.irm import plot_irm_topdown

    t0 = time.perf_counter()
    robot = Robot("tiago")
    rmap, path, built = cached_map(robot, BuildSettings(samples=samples, seed=seed), progress=progress)
    t_map = time.perf_counter() - t0

    T_world_target = parse_pose6(DEMO_TARGET)
    res, n_yaw = 0.05, 36
    xs = np.arange(-0.6, 2.6 + 1e-9, res)
    ys = np.arange(-1.1, 2.1 + 1e-9, res)
    yaws = np.arange(n_yaw) * 2 * np.pi / n_yaw
    X, Y, G = np.meshgrid(xs, ys, yaws, indexing="ij")
    poses = np.stack([X.ravel(), Y.ravel(), G.ravel()], axis=1)
    _ = rmap.tables  # build the lookup tables outside the timed query
    t1 = time.perf_counter()
    values = rmap.inverse(T_world_target, BasePose.batch_matrix(poses)).reshape(len(xs), len(ys), n_yaw)
    t_query = time.perf_counter() - t1

    rng = np.random.default_rng(seed)
    ik = DampedLeastSquaresIK(robot.arm())
    order = np.argsort(values.ravel())[::-1]
    best = None
    for flat in order[:50]:  # the best cells first; the first pose IK confirms wins
        pose = BasePose(*poses[flat])
        q = ik.solve(invert_transforms(pose.matrix()) @ T_world_target, rng)
        if q is not None:
            best = (pose, float(values.ravel()[flat]), q)
            break

    out_dir.mkdir(parents=True, exist_ok=True)
    png = out_dir / "demo_irm.png"
    plot_irm_topdown(
        xs, ys, values.sum(axis=2).T, T_world_target[:3, 3], T_world_target[:3, 0],
        (best[0].x, best[0].y, best[0].yaw) if best else None,
        f"TIAGo inverse reachability of target ({DEMO_TARGET})", png,
    )  # fmt: skip
    result: dict[str, Any] = {
        "robot": robot.name,
        "target": DEMO_TARGET,
        "map": {
            "path": str(path),
            "built_now": built,
            "samples": rmap.info.samples,
            "cells_reached": rmap.n_reached,
            "build_time_s": round(rmap.info.build_time_s, 2),
        },
        "base_poses_evaluated": int(values.size),
        "timings_s": {"map": round(t_map, 3), "irm_query": round(t_query, 4)},
        "best": None,
        "png": str(png),
    }
    if best is not None:
        pose, value, q = best
        result["best"] = {"x": pose.x, "y": pose.y, "yaw": pose.yaw, "reachability": value,
                          "joints": dict(zip(robot.arm().joint_names, q.tolist(), strict=True))}  # fmt: skip
    (out_dir / "demo.json").write_text(json.dumps(result, indent=2))
    return result
