"""baseplace and RM4D side by side on the same Franka Panda arm and TCP, in one run.

RM4D (Rudorfer et al., "RM4D: A Combined Reachability and Inverse Reachability Map", its public
repository) is never a dependency: it runs in a throwaway environment whose Python and checkout
are passed in, through ``bench/rm4d_runner.py``; only numpy arrays and JSON cross over.

Protocol (fixed before the first run):
- Robot: RM4D's own Panda URDF (``rm4d/robots/assets/franka_panda/panda166.urdf``) for both, TCP
  ``panda_grasptarget`` (RM4D's end-effector link 11), base ``panda_link0``; baseplace reads
  example-robot-data's Panda SRDF for its disabled collision pairs. RM4D's FK of 20 random
  configurations is checked against pinocchio's (the same arm and TCP, to 1e-6 m).
- No floor: RM4D's ground-plane check is off and its map's z range covers the reach (baseplace's
  provable reach box, rounded out to the 5 cm voxels); RM4D otherwise as published (5 cm voxels,
  36 tilt bins, joint-space sampling, pybullet self-collision checks).
- Two modes: self-collision checks off and on (baseplace: the sphere model, ``--self-collision``
  builds; RM4D: pybullet, resampling until free).
- Build rate: joint samples drawn and checked per second, median of 3 builds (RM4D 10,000 / 2,000
  samples off / on, baseplace 2^23 / 2^22). Equal build time: each tool samples until
  ``--budget`` seconds are spent (RM4D in chunks of 1,000 / 200 samples, baseplace in chunks of
  2^20; with ``--build-option``, baseplace builds its median rate times the budget instead); the
  table gives the actual build times.
- Recall: the share of 10,000 held-out FK poses (pinocchio FK of uniform random configurations,
  seed 1234, that coal finds free of self-collision) each map calls reachable.
- Precision against the same IK: 20,000 poses drawn uniformly in baseplace's reach box with
  Haar-uniform orientations (seed 4321); every pose a map calls reachable is solved by baseplace's
  damped least-squares IK with 80 random restarts; with checks on, a solution counts only if coal
  finds it free (up to 4 IK rounds with fresh restarts). Precision = solved / called reachable;
  also the share of random poses each map calls reachable and (on 2,000 of them) the share IK
  reaches.
- Queries: single-pose rate (one pose per call, 10,000 calls) and batched rate (baseplace: one
  call for 10^5 poses; RM4D has no batched query, so its batch is the same per-pose loop).
- File size: baseplace's map file (``save_map``), RM4D's ``to_file``.

Usage:
  python bench/bench_rm4d.py --rm4d RM4D_CHECKOUT --python RM4D_VENV/bin/python [--budget 45]
      [--build-option KEY=VALUE ...]   (extra BuildSettings fields, e.g. a certified build)
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from baseplace.reachability.build import CHUNK, BuildSettings, MapAccumulator, build_map
from baseplace.reachability.rmap import ReachabilityMap, reach_bounds
from baseplace.reachability.storage import save_map
from baseplace.robots.collision import SelfCollision
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.robots.spec import ArmSpec, RobotSpec, _erd
from baseplace_experiments.results import fixed_protocol
from common import report

PROTOCOL_FILE = "docs/protocols/rm4d_side_by_side.md"

PANDA_URDF = Path("rm4d/robots/assets/franka_panda/panda166.urdf")
TCP = "panda_grasptarget"
VOXEL = 0.05
MAX_CHUNKS = 10_000


def panda(rm4d: Path) -> Robot:
    """RM4D's Panda with example-robot-data's SRDF, TCP ``panda_grasptarget``."""
    urdf = rm4d / PANDA_URDF
    if not urdf.is_file():
        raise SystemExit(f"error: {urdf} not found; --rm4d must be a checkout of RM4D's repository")
    return Robot(
        RobotSpec(
            name="panda_rm4d",
            urdf=urdf,
            srdf=_erd("panda_description/srdf/panda.srdf"),
            base_frame="panda_link0",
            arms={"arm": ArmSpec(tuple(f"panda_joint{i}" for i in range(1, 8)), TCP, approach="z")},
            default_arm="arm",
            footprint_radius=0.1,
        )
    )


def pin_fk(robot: Robot, Q: np.ndarray) -> np.ndarray:
    """TCP poses (N, 4, 4) in the base frame by pinocchio (the independent FK)."""
    arm, q_ref = robot.arm(), robot.q_reference
    return np.array(
        [robot.frame_pose(arm.to_pinocchio(q, q_ref), TCP, relative_to=arm.base_frame) for q in Q]
    )


def random_poses(lo: np.ndarray, hi: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    T = np.zeros((n, 4, 4))
    T[:, :3, 3] = rng.uniform(lo, hi, (n, 3))
    T[:, :3, :3] = Rotation.random(n, random_state=rng).as_matrix()
    T[:, 3, 3] = 1.0
    return T


def ik_oracle(robot: Robot, T: np.ndarray, rounds: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """(any solution, a self-collision-free solution) per pose (N,), by IK with restarts + coal."""
    arm = robot.arm()
    ik = DampedLeastSquaresIK(arm)
    exact = SelfCollision(robot, num_threads=1)
    rng = np.random.default_rng(99)
    q, ok = ik.solve_batch(T, rng)
    solved = ok.copy()
    free = ok & ~exact.colliding_arm(arm, q)
    for _ in range(rounds - 1):
        todo = np.flatnonzero(solved & ~free)
        if not len(todo):
            break
        q2, ok2 = ik.solve_batch(T[todo], rng)
        free[todo] = ok2 & ~exact.colliding_arm(arm, q2)
    return solved, free


def baseplace_build(
    robot: Robot, on: bool, samples: int, res: float, options: dict[str, Any]
) -> ReachabilityMap:
    settings = BuildSettings(
        samples=samples, voxel_size=VOXEL, orientation_resolution=res, self_collision=on, **options
    )
    return build_map(robot, settings=settings)


def baseplace_timed_build(robot: Robot, on: bool, budget_s: float, res: float) -> ReachabilityMap:
    """A map of as many 2^20-sample chunks as ``budget_s`` seconds allow (RM4D's way of timing).

    The chunks are those of a ``build_map`` of the same sample count (chunk k drawn from
    ``default_rng([seed, k])``), so the map is that build's.
    """
    settings = BuildSettings(
        samples=MAX_CHUNKS * CHUNK, voxel_size=VOXEL, orientation_resolution=res, self_collision=on
    )
    acc = MapAccumulator(robot, None, settings)
    start = time.perf_counter()
    k = 0
    while time.perf_counter() - start < budget_s and k < MAX_CHUNKS:
        acc.add_chunk(k)
        k += 1
    rmap = acc.result(time.perf_counter() - start)
    return dataclasses.replace(rmap, info=dataclasses.replace(rmap.info, samples=k * CHUNK))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rm4d", type=Path, required=True, help="checkout of RM4D's repository")
    parser.add_argument("--python", type=Path, required=True, help="Python with RM4D's dependencies")
    parser.add_argument("--budget", type=float, default=45.0, help="equal build time [s]")
    parser.add_argument("--heldout", type=int, default=10_000)
    parser.add_argument("--random", type=int, default=20_000)
    parser.add_argument(
        "--orientation-resolution",
        default="0.8",
        help="comma-separated baseplace orientation resolutions [rad], one column each (default 0.8)",
    )
    parser.add_argument(
        "--split",
        choices=["dev", "held-out"],
        default="held-out",
        help="seeds of the held-out and random poses: dev (5678, 8765) to choose settings, held-out (1234, 4321)",
    )
    parser.add_argument(
        "--build-option", action="append", default=[], help="KEY=VALUE, an extra BuildSettings field"
    )
    args = parser.parse_args()
    options: dict[str, Any] = {}
    fields = {f.name for f in dataclasses.fields(BuildSettings)}
    for kv in args.build_option:
        key, _, value = kv.partition("=")
        if key not in fields:
            raise SystemExit(f"error: BuildSettings has no field {key!r}; fields: {sorted(fields)}")
        options[key] = json.loads(value)
    resolutions = [float(x) for x in args.orientation_resolution.split(",")]
    seed_heldout, seed_random = (1234, 4321) if args.split == "held-out" else (5678, 8765)
    protocol_file = fixed_protocol(PROTOCOL_FILE, args.split)
    robot = panda(args.rm4d.resolve())
    arm = robot.arm()
    exact = SelfCollision(robot, num_threads=1)

    # held-out collision-free FK poses and random poses in the reach box
    Q = arm.sample(np.random.default_rng(seed_heldout), int(args.heldout * 1.1) + 100)
    Q = Q[~exact.colliding_arm(arm, Q)][: args.heldout]
    heldout = pin_fk(robot, Q)
    lo, hi = reach_bounds(arm.placements, arm.axes, arm.kinds, arm.T_last_tcp, arm.lower, arm.upper)
    rand = random_poses(lo, hi, args.random, np.random.default_rng(seed_random))
    r_xy = float(np.ceil(max(np.abs(lo[:2]).max(), np.abs(hi[:2]).max()) / VOXEL) * VOXEL)
    z_lo = float(np.floor((lo[2] + 0.01) / VOXEL) * VOXEL)  # RM4D's world: base at z = 0.01
    z_hi = float(np.ceil((hi[2] + 0.01) / VOXEL) * VOXEL)
    check_q = arm.sample(np.random.default_rng(5), 20)

    results: dict[str, Any] = {"modes": {}}
    with tempfile.TemporaryDirectory() as tmp:
        work = Path(tmp)
        np.save(work / "heldout.npy", heldout, allow_pickle=False)
        np.save(work / "random.npy", rand, allow_pickle=False)
        cfg = {
            "modes": ["off", "on"],
            "xy_limits": [-r_xy, r_xy],
            "z_limits": [z_lo, z_hi],
            "voxel": VOXEL,
            "seed": 42,
            "budget_s": args.budget,
            "rate_repeats": 3,
            "rate_samples": {"off": 10_000, "on": 2_000},
            "query_poses": 10_000,
            "fk_check_q": check_q.tolist(),
        }
        (work / "config.json").write_text(json.dumps(cfg))
        env = dict(os.environ, PYTHONPATH=str(args.rm4d.resolve()), MPLBACKEND="Agg")
        t = time.perf_counter()
        proc = subprocess.run(
            [str(args.python), str(Path(__file__).with_name("rm4d_runner.py")), str(work)],
            env=env,
            capture_output=True,
            text=True,
        )
        if proc.returncode:
            raise SystemExit(f"error: the RM4D runner failed:\n{proc.stderr[-3000:]}")
        rm4d_wall = time.perf_counter() - t
        rm = json.loads((work / "result.json").read_text())
        fk = np.array(rm["fk_check_world_pos_quat_xyzw"])
        ref = pin_fk(robot, check_q)
        pos_err = float(np.abs(fk[:, :3] - ref[:, :3, 3] - [0, 0, rm["base_z"]]).max())
        rot_err = float(
            (Rotation.from_quat(fk[:, 3:]).inv() * Rotation.from_matrix(ref[:, :3, :3])).magnitude().max()
        )
        if pos_err > 1e-6 or rot_err > 1e-6:
            raise SystemExit(
                f"error: RM4D's FK differs from pinocchio's ({pos_err:.2e} m, {rot_err:.2e} rad)"
            )
        preds = {
            f"rm4d_{m}": {
                s: np.load(work / f"rm4d_{m}_{s}.npy", allow_pickle=False) for s in ("heldout", "random")
            }
            for m in cfg["modes"]
        }

        for mode in cfg["modes"]:
            on = mode == "on"
            rate_n = (1 << 22) if on else (1 << 23)
            results["modes"][mode] = {
                "rm4d": {**rm["modes"][mode], "batched_query_per_s": rm["modes"][mode]["single_query_per_s"]}
            }
            for res in resolutions:
                baseplace_build(robot, on, 1 << 20, res, options)  # compile and warm up
                rates = []
                for _ in range(3):
                    m = baseplace_build(robot, on, rate_n, res, options)
                    rates.append(rate_n / m.info.build_time_s)
                rate = statistics.median(rates)
                if options:  # another build (e.g. certified): its median rate times the budget
                    m = baseplace_build(robot, on, int(rate * args.budget), res, options)
                else:
                    m = baseplace_timed_build(robot, on, args.budget, res)
                size = save_map(m, work / f"baseplace_{mode}_{res}.rmap")
                preds[f"baseplace {res}_{mode}"] = {
                    "heldout": m.reachability(heldout) > 0,
                    "random": m.reachability(rand) > 0,
                }
                one = heldout[:10_000]
                m.reachability(one[:1])
                t = time.perf_counter()
                for T in one:
                    m.reachability(T)
                single = len(one) / (time.perf_counter() - t)
                batch = np.concatenate([heldout] * (100_000 // len(heldout) + 1))[:100_000]
                t = time.perf_counter()
                m.reachability(batch)
                batched = len(batch) / (time.perf_counter() - t)
                results["modes"][mode][f"baseplace {res}"] = {
                    "orientation_resolution": res,
                    "rate_per_s_median": rate,
                    "rates_per_s": rates,
                    "equal_time_build": {"samples": m.info.samples, "time_s": m.info.build_time_s},
                    "file_bytes": size,
                    "single_query_per_s": single,
                    "batched_query_per_s": batched,
                    "cells_reached": m.n_reached,
                    "grid_cells": m.grid.n_cells,
                    "self_collision_checker": m.info.self_collision_checker,
                    "build_options": options,
                }
                del m

    # the IK oracle on every random pose any map calls reachable, and on 2,000 for the base rate
    positive = np.zeros(len(rand), dtype=bool)
    for p in preds.values():
        positive |= p["random"]
    base = np.zeros(len(rand), dtype=bool)
    base[:2000] = True
    todo = np.flatnonzero(positive | base)
    t = time.perf_counter()
    solved, free = ik_oracle(robot, rand[todo])
    ik_time = time.perf_counter() - t
    truth = {"off": np.zeros(len(rand), dtype=bool), "on": np.zeros(len(rand), dtype=bool)}
    truth["off"][todo], truth["on"][todo] = solved, free
    tools = ["rm4d"] + [f"baseplace {res}" for res in resolutions]
    for mode in ("off", "on"):
        for tool in tools:
            p = preds[f"{tool}_{mode}"]
            r = results["modes"][mode][tool]
            r["recall_heldout"] = float(p["heldout"].mean())
            r["called_reachable_random"] = float(p["random"].mean())
            r["precision_ik"] = float(truth[mode][p["random"]].mean()) if p["random"].any() else float("nan")
            r["n_called_reachable"] = int(p["random"].sum())
        results["modes"][mode]["ik_reachable_random"] = float(truth[mode][:2000].mean())
    results.update(
        heldout_poses=len(heldout),
        random_poses=len(rand),
        ik_solved=len(todo),
        ik_time_s=ik_time,
        rm4d_runner_wall_s=rm4d_wall,
        fk_agreement={"position_m": pos_err, "rotation_rad": rot_err},
        budget_s=args.budget,
        rm4d_grid={"xy_limits": cfg["xy_limits"], "z_limits": cfg["z_limits"], "voxel": VOXEL},
        baseplace_grid={"voxel": VOXEL, "orientation_resolution": BuildSettings().orientation_resolution},
    )
    print(table(results, tools))
    argv, prev = [sys.argv[0]], ""  # the command, without this machine's paths
    for a in sys.argv[1:]:
        argv.append({"--rm4d": "RM4D_CHECKOUT", "--python": "RM4D_VENV/bin/python"}.get(prev, a))
        prev = a
    report(
        "rm4d_side_by_side" + ("_dev" if args.split == "dev" else ""),
        results,
        split=args.split,
        used_seeds=[seed_heldout, seed_random, 42, 99],
        protocol=__doc__.split("Protocol (fixed before the first run):")[1].split("Usage:")[0].strip(),
        argv=argv,
        protocol_file=protocol_file,
    )


def table(r: dict[str, Any], tools: list[str]) -> str:
    """The README table (markdown)."""
    rows = [
        ("build rate [samples/s], median of 3", "rate_per_s_median", "{:,.0f}"),
        ("equal-time build: time [s]", None, None),
        ("equal-time build: samples", None, None),
        ("recall, held-out free FK poses", "recall_heldout", "{:.1%}"),
        ("precision against IK", "precision_ik", "{:.1%}"),
        ("random poses called reachable", "called_reachable_random", "{:.1%}"),
        ("single-pose queries [1/s]", "single_query_per_s", "{:,.0f}"),
        ("batched queries [poses/s]", "batched_query_per_s", "{:,.0f}"),
        ("map file [MB]", "file_bytes", None),
    ]

    def name(tool: str) -> str:
        return "RM4D" if tool == "rm4d" else f"baseplace {tool.split()[1]} rad"

    cols = [(mode, tool) for mode in ("off", "on") for tool in tools]
    head = (
        "| | "
        + " | ".join(f"{name(t)}, {'checks off' if m == 'off' else 'self-collision'}" for m, t in cols)
        + " |"
    )
    out = [head, "|---" * (len(cols) + 1) + "|"]
    for label, key, fmt in rows:
        cells = []
        for mode, tool in cols:
            x = r["modes"][mode][tool]
            if label.endswith("time [s]"):
                cells.append(f"{x['equal_time_build']['time_s']:.1f}")
            elif label.endswith("samples"):
                e = x["equal_time_build"]
                cells.append(f"{e.get('drawn', e.get('samples')):,}")
            elif key == "file_bytes":
                cells.append(f"{x[key] / 1e6:.2f}")
            else:
                cells.append(fmt.format(x[key]))
        out.append(f"| {label} | " + " | ".join(cells) + " |")
    gap = " |" * (len(tools) - 1)
    out.append(
        f"| share of random poses IK reaches | {r['modes']['off']['ik_reachable_random']:.1%} (any solution) |{gap} "
        f"{r['modes']['on']['ik_reachable_random']:.1%} (self-collision-free) |{gap}"
    )
    return "\n".join(out)


if __name__ == "__main__":
    main()
