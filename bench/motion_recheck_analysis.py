"""Why a motion found by bench_motion_verdicts.py touches its own model at the finer re-check.

An analysis of a results file, not a run: for the first motion the product found whose re-check
(joint lines cut at ``joint_resolution / RECHECK``) touches its own model, it rebuilds the scene
as the bench does and checks (1) every state the product itself checked (``MotionChecker.edge_states``)
with coal on every pair (``Environment.colliding_arm_exact``), and (2) each flagged re-check state:
coal's verdict and the robot travel bound (lever arms) to the nearest state the product checked.
``MotionSettings.point_step`` promises ``clearance - point_step / 2`` between checked states.

Usage: python bench/motion_recheck_analysis.py bench/results/motion_verdicts_heldout_v1.json
"""

import itertools
import json
import math
import sys

import numpy as np

import bench_motion_verdicts as B
from baseplace.placement.pipeline import PlaceSettings, scene_checks, with_floor
from baseplace.placement.scene_cache import SceneCache
from baseplace.reachability.cache import resolve_map
from baseplace.robots.model import Robot
from baseplace_experiments.table_grid import TableGridSettings

d = json.load(open(sys.argv[1]))
row = next(r for r in d["checks"] if r["product"]["found"] and r["product"]["recheck"]["colliding"])
seed, cell, g = row["seed"], tuple(row["cell"]), row["grasp"]
robot = Robot("tiago")
rmap = resolve_map(robot, None).rmap
arm = robot.arm(rmap.info.arm)
s = TableGridSettings()
p_true, p_est, seen = B.scene(seed, cell, s)
points = with_floor(seen, 0.0)
cache = SceneCache(points)
target = np.array(row["target"])
T = np.array(row["T_world_base"])
checks = scene_checks(
    robot, arm.name, points, cache.terrain(None), target[None], PlaceSettings(), "auto", cache
)
mc = checks.verifier.motion
env = mc.environment
path = np.array(row["product"]["path"])
print("waypoints", len(path))
# the product's own states on each line, checked by coal on every pair
bad_exact = 0
n_states = 0
for a, b in itertools.pairwise(path):
    n = mc.edge_states(a, b)
    for k in range(n + 1):
        q = a + (b - a) * (k / n)
        n_states += 1
        if env.colliding_arm_exact(arm, q, T):
            bad_exact += 1
print("product's states", n_states, "colliding by coal on every pair:", bad_exact)
# the finer re-check's flagged states, and how far they are from the nearest product state in robot travel
step = mc.settings.joint_resolution / B.RECHECK
for li, (a, b) in enumerate(itertools.pairwise(path)):
    n = max(1, math.ceil(float(np.linalg.norm(b - a)) / step))
    m = mc.edge_states(a, b)
    for k in range(n + 1):
        f = k / n
        q = a + (b - a) * f
        if env.colliding_arm(arm, q, T):
            exact = env.colliding_arm_exact(arm, q, T)
            near = min(abs(f - j / m) for j in range(m + 1))
            travel = near * float(np.abs(b - a) @ mc.levers)
            print(
                f"line {li} fraction {f:.4f}: filter colliding, exact {exact}; nearest product state {near:.4f} of the line away, robot travel bound {travel * 1000:.2f} mm; contacts {env.contacts_arm(arm, q, T)}; clearance {env.clearance if hasattr(env, 'clearance') else '?'}"
            )
