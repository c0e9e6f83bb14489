"""Diagnosis of the OSRM experiment's failures: grasps whose hand alone touches an obstacle voxel.

For every grasp of ``baseplace experiment osrm`` (same scenes and grasps: the seed, class and
scene index fix them), the hand's collision geometry at the grasp pose is checked against the
obstacle voxels the placement uses (scene voxels less the grasped object's, support included).
Such a grasp fails from every base pose: the 25 mm voxels of a neighbour or the rim reach into
the hand, although the grasp planner found the hand clear of the true shapes.

Usage: python bench/osrm_hand_blocked.py [--seed 2026] [--scenes 5] [--grasps 10] [--results FILE]
"""

from __future__ import annotations

import argparse
import json

import coal
import numpy as np

from baseplace.placement.pipeline import PlaceSettings, _obstacles
from baseplace.reachability.build import BuildSettings
from baseplace.reachability.cache import cached_map
from baseplace.robots.model import Robot
from baseplace.terrain.polygons import footprint_outline
from baseplace.world.environment import HandFilter, contact_groups
from baseplace_experiments.osrm_experiment import (
    SCENE_CLASSES,
    ExperimentSettings,
    _class_name,
    experiment_scene,
    grasp_candidates,
)
from baseplace_experiments.results import write_results
from common import STARTED


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--seed", type=int, default=2026)
    parser.add_argument("--scenes", type=int, default=5)
    parser.add_argument("--grasps", type=int, default=10)
    parser.add_argument("--results", default=None, help="write the results (JSON with provenance) here")
    args = parser.parse_args()
    robot = Robot("tiago")
    rmap = cached_map(robot, BuildSettings())[0]
    hand = HandFilter(robot, rmap.info.arm)
    outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
    s = ExperimentSettings(grasps_per_scene=args.grasps, seed=args.seed)
    out = {}
    for c, (size_class, n_planes) in enumerate(SCENE_CLASSES):
        blocked = total = 0
        for k in range(args.scenes):
            rng, scene, _, terrain = experiment_scene(s, c, k)
            grasps, objects, _ = grasp_candidates(scene, rng, s.grasps_per_scene, hand=hand)
            obstacles = _obstacles(terrain, terrain.segmentation, PlaceSettings(), outline)
            for g, obj in zip(grasps, objects, strict=True):
                groups, _ = contact_groups(terrain.voxels, obstacles, obj)
                trees = [
                    coal.makeOctree(np.ascontiguousarray(v.centres), v.resolution)
                    for v in groups.values()
                    if len(v)
                ]
                blocked += int(not hand.clear(g, trees))
                total += 1
        out[_class_name(size_class, n_planes)] = {"grasps": total, "hand_blocked": blocked,
                                                  "share": round(100 * blocked / total, 1)}  # fmt: skip
        print(_class_name(size_class, n_planes), out[_class_name(size_class, n_planes)], flush=True)
    result = {"seed": args.seed, "scenes": args.scenes, "grasps": args.grasps, "classes": out}
    if args.results is not None:
        result = write_results(args.results, result, STARTED, used_seeds=[args.seed])
    print(json.dumps(result))


if __name__ == "__main__":
    main()
