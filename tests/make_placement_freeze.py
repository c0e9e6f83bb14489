"""The scenes of tests/test_placement_methods.py, and the script that recorded their placements once.

``python tests/make_placement_freeze.py`` runs every placement method on these scenes with the code of
its checkout and writes what each returned (base poses in order, regions, reachability, joints,
robustness counts) to ``tests/data/placement_freeze.json``. It was run once on main, before issue 26
merged the two verified-placement types; the test compares the refactored code to that file, so the
recorded numbers are not the code's own output. The script calls main's interfaces (the
``RadialCandidate`` results of the seed-004 methods) and is kept as the record of how the file was made.
"""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np

FREEZE = Path(__file__).parent / "data" / "placement_freeze.json"
MAP_SAMPLES, MAP_SEED = 2_000_000, 3  # conftest's tiago_map
STRATEGIES = ["MR", "TO", "MRTO", "orm", "random", "grid"]
TABLE = (1.6, 2.4, 1.1, 2.9, 0.74)  # test_candidates' table: x0, x1, y0, y1, top [m]
ROBUST_SAMPLES = 16


def platform_scene():
    """test_placement's platform (2.4 m square, tilted 6 deg), top-down targets above it and above the floor."""
    from baseplace.geometry.poses import pose_from_xyz_rpy
    from baseplace.sim.scenes import Plane, Scene, SceneSettings
    from baseplace.terrain.pipeline import terrain_from_points

    slope = math.tan(math.radians(6))
    a, c = slope, 0.25 + slope * 1.2
    floor = Plane(0, "floor", (0.0, 0.0), (8.0, 8.0), 0.0, 0.0, 0.0, 0.0)
    platform = Plane(1, "platform", (0.0, 0.0), (2.4, 2.4), 0.0, a, 0.0, c)
    scene = Scene(SceneSettings(n_planes=1, extent=(8.0, 8.0), with_box=False), (floor, platform))
    points = scene.sample_cloud(np.random.default_rng(3), sigma=0.01)
    top = float(platform.z(np.array([[0.1, 0.0]]))[0])
    on_platform = pose_from_xyz_rpy([0.1, 0.0, top + 0.75, 0.0, math.pi / 2, 0.0])
    on_floor = pose_from_xyz_rpy([2.6, 1.5, 0.75, 0.0, math.pi / 2, 0.0])
    return points, terrain_from_points(points), {"platform": on_platform, "floor": on_floor}


def table_scene():
    """test_candidates' table grid and cloud, a bottle on it, its grasps and the table-top environment."""
    from baseplace.placement.irm_candidates import grasp_poses
    from baseplace.world.occupancy import OccupancyGrid

    x0, x1, y0, y1, top = TABLE
    centres = (np.arange(80) + 0.5) * 0.05
    X, Y = np.meshgrid(centres, centres)
    grid = OccupancyGrid(np.where((X >= x0) & (X <= x1) & (Y >= y0) & (Y <= y1), 100, 0).astype(np.int8), 0.05,
                         (0.0, 0.0, 0.0))  # fmt: skip
    rng = np.random.default_rng(4)
    table = np.c_[rng.uniform(x0, x1, 20000), rng.uniform(y0, y1, 20000), top + rng.normal(0, 0.004, 20000)]
    floor = np.c_[rng.uniform(0, 4, 30000), rng.uniform(0, 4, 30000), rng.normal(0, 0.004, 30000)]
    p_o = np.array([2.2, 2.5, top + 0.1])
    a = rng.uniform(0, 2 * np.pi, 2000)
    cup = np.c_[p_o[0] + 0.04 * np.cos(a), p_o[1] + 0.04 * np.sin(a), rng.uniform(top, top + 0.12, 2000)]
    table_top = np.stack(np.meshgrid(np.arange(x0, x1, 0.02), np.arange(y0, y1, 0.02), [top - 0.01]), -1)
    grasps = grasp_poses(p_o, n=8, top_down=True, standoff=0.15)
    return grid, np.r_[table, floor, cup], p_o, table_top.reshape(-1, 3), grasps


def place_settings(strategy: str):
    """MR with the reaching-motion check and the robustness ranking; the others the pose alone."""
    from baseplace.placement.motion import MotionSettings
    from baseplace.placement.pipeline import POSE_ONLY_CHECKS, PlaceSettings
    from baseplace.placement.robustness import RobustnessSettings

    # stand_on "any": the platform scene's raised platform has no ramp; aafd602 (the freeze) stood on
    # every planar region, as seed 000 does, and the default now keeps to the ground (tests/test_stand_on.py)
    if strategy == "MR":
        robust = RobustnessSettings(samples=ROBUST_SAMPLES, rank="robustness", pool=3)
        return PlaceSettings(strategy, placements=2, tries=40, motion=MotionSettings(), robustness=robust,
                             stand_on="any")  # fmt: skip
    return PlaceSettings(strategy, placements=2, tries=200, stand_on="any", **POSE_ONLY_CHECKS)


def _record(T, joints, reachability, region=-1, robustness=None, grasp=-1, distance=None, ray=-1):
    return {
        "T_world_base": np.asarray(T, dtype=float).ravel().tolist(),
        "joints": [np.asarray(q, dtype=float).tolist() for q in joints],
        "reachability": float(reachability), "region": int(region), "grasp": int(grasp),
        "distance": None if distance is None else float(distance), "ray": int(ray),
        "robustness": None if robustness is None else [robustness.successes, robustness.samples],
    }  # fmt: skip


def main() -> None:
    from baseplace.placement.candidates import radial_search
    from baseplace.placement.irm_candidates import IrmSettings, irm_candidates, verify_candidates
    from baseplace.placement.pipeline import place
    from baseplace.placement.robustness import RobustnessSettings, score_candidates
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.robots.model import Robot
    from baseplace.terrain.voxels import VoxelMap
    from baseplace.world.environment import Environment

    tiago = Robot("tiago")
    rmap = build_map(tiago, None, BuildSettings(samples=MAP_SAMPLES, seed=MAP_SEED))
    out: dict[str, list[dict]] = {}
    points, terrain, targets = platform_scene()
    for (where, target), strategy in itertools.product(targets.items(), STRATEGIES):
        result = place(tiago, rmap, points, target, place_settings(strategy), np.random.default_rng(0),
                       terrain=terrain)  # fmt: skip
        out[f"osrm_{strategy}_{where}"] = [_record(p.T_world_base, p.joints, p.reachability, p.region, p.robustness)
                                   for p in result.placements]  # fmt: skip
    grid, cloud, p_o, table_top, grasps = table_scene()
    env = Environment(tiago, VoxelMap.from_points(table_top, 0.025))
    search = radial_search(p_o, None, cloud, grid)
    radial, _ = verify_candidates(tiago, None, search.candidates, grasps, env, np.random.default_rng(0))
    irm = irm_candidates(tiago, rmap, p_o, grasps, env, grid, IrmSettings(count=3), np.random.default_rng(0))
    robust = RobustnessSettings(samples=ROBUST_SAMPLES)
    for name, found in (("radial", radial), ("irm", irm)):
        scored = score_candidates(tiago.arm(), env, grasps, found, robust)
        out[name] = [_record(c.T_world_base, [c.joints], c.reachability, -1, c.robustness, c.grasp, c.distance,
                             c.ray) for c in scored]  # fmt: skip
    FREEZE.write_text(json.dumps(out, indent=1) + "\n")
    print({k: len(v) for k, v in out.items()})


if __name__ == "__main__":
    main()
