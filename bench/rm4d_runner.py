"""The RM4D half of ``bench_rm4d.py``: run by the Python of a throwaway environment holding RM4D.

Not part of baseplace and never imported by it: ``bench_rm4d.py`` starts it as
``PYTHON bench/rm4d_runner.py WORKDIR`` with RM4D's checkout on ``PYTHONPATH``. It uses RM4D's
own classes as its README and ``experiment_scripts/create_map.py`` do (``Simulator``,
``Franka``, ``ReachabilityMap4D``, ``JointSpaceConstructor``), with two settings for a robot
without a floor: the ground-plane check is switched off and the map's z range covers the whole
reach (RM4D's default starts at the floor). Inputs (WORKDIR): ``config.json``, ``heldout.npy``
and ``random.npy`` (N, 4, 4) TCP poses in the arm's base frame (``panda_link0``). Outputs:
``result.json`` and ``rm4d_<mode>_<set>.npy`` (N,) booleans, the map's verdict per pose.
Only numpy arrays are exchanged (``allow_pickle=False``).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np
from rm4d import JointSpaceConstructor, ReachabilityMap4D
from rm4d.robots import Franka, Simulator


class Counted:
    """A configuration check that counts its calls (RM4D resamples until one passes)."""

    def __init__(self, check):
        self.check = check
        self.calls = 0

    def __call__(self):
        self.calls += 1
        return self.check()


def make(cfg: dict, self_collision: bool, seed: int):
    sim = Simulator(with_gui=False)
    robot = Franka(sim)
    robot.in_collision_with_plane = lambda: False  # no floor: the map is of the arm alone
    counter = Counted(robot.in_collision)
    robot.in_collision = counter
    rmap = ReachabilityMap4D(xy_limits=cfg["xy_limits"], z_limits=cfg["z_limits"], voxel_res=cfg["voxel"])
    return sim, robot, rmap, JointSpaceConstructor(rmap, robot, seed=seed), counter


def build(cfg: dict, self_collision: bool, seed: int, samples: int | None, budget_s: float | None):
    """Build a map from ``samples`` samples, or for ``budget_s`` seconds; returns map and stats."""
    sim, _robot, rmap, constructor, counter = make(cfg, self_collision, seed)
    chunk = 200 if self_collision else 1000
    done = 0
    quiet = io.StringIO()
    start = time.perf_counter()
    with contextlib.redirect_stderr(quiet):  # tqdm's bar
        while True:
            n = chunk if samples is None else min(chunk, samples - done)
            if n <= 0:
                break
            constructor.sample(n_samples=n, prevent_collisions=self_collision)
            done += n
            if budget_s is not None and time.perf_counter() - start >= budget_s:
                break
    elapsed = time.perf_counter() - start
    drawn = counter.calls if self_collision else done
    sim.disconnect()
    return rmap, {"kept": done, "drawn": drawn, "time_s": elapsed}


def verdict(rmap, T: np.ndarray, base_z: float) -> np.ndarray:
    """The map's answer per pose (N, 4, 4) in the base frame; False outside the map."""
    out = np.zeros(len(T), dtype=bool)
    for i, tf in enumerate(T):
        tf = tf.copy()
        tf[2, 3] += base_z  # the robot stands at z = base_z in RM4D's world
        try:
            out[i] = bool(rmap.is_reachable(rmap.get_indices_for_ee_pose(tf)))
        except IndexError:
            out[i] = False
    return out


def main() -> None:
    work = Path(sys.argv[1])
    cfg = json.loads((work / "config.json").read_text())
    heldout = np.load(work / "heldout.npy", allow_pickle=False)
    random_poses = np.load(work / "random.npy", allow_pickle=False)
    base_z = 0.01  # RM4D's robots stand 1 cm above the world origin (RobotBase)
    result: dict = {"modes": {}}
    # the same arm and TCP: RM4D's FK of the check configurations, for bench_rm4d.py to compare
    sim, robot, *_ = make(cfg, False, 0)
    fk = []
    for q in cfg["fk_check_q"]:
        pos, quat = robot.forward_kinematics(np.asarray(q))
        fk.append([*pos, *quat])
    result["fk_check_world_pos_quat_xyzw"] = fk
    result["base_z"] = base_z
    sim.disconnect()
    for mode in cfg["modes"]:
        on = mode == "on"
        rates = []
        for r in range(cfg["rate_repeats"]):
            _, st = build(cfg, on, 1000 + r, cfg["rate_samples"][mode], None)
            rates.append(st["drawn"] / st["time_s"])
        rmap, st = build(cfg, on, cfg["seed"], None, cfg["budget_s"])
        path = work / f"rm4d_{mode}"
        rmap.to_file(str(path))
        size = os.path.getsize(str(path) + ".npy")
        pred = {"heldout": verdict(rmap, heldout, base_z), "random": verdict(rmap, random_poses, base_z)}
        for name, p in pred.items():
            np.save(work / f"rm4d_{mode}_{name}.npy", p, allow_pickle=False)
        single = heldout[: cfg["query_poses"]]
        t = time.perf_counter()
        verdict(rmap, single, base_z)
        single_rate = len(single) / (time.perf_counter() - t)
        result["modes"][mode] = {
            "rate_per_s_median": statistics.median(rates),
            "rates_per_s": rates,
            "equal_time_build": st,
            "file_bytes": size,
            "single_query_per_s": single_rate,
            "map_cells": int(rmap.map.size),
            "map_cells_reachable": int(rmap.map.sum()),
        }
    (work / "result.json").write_text(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
