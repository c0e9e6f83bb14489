"""Self-collision in the build kernel: the sphere model (robots/spheres.py) against coal.

For TIAGo, TIAGo dual (right arm, the left one at its reference) and a Franka Panda (example-robot-data, TCP panda_hand_tcp), on random arm
configurations (seed 7, disjoint from the model's calibration seeds [19, 0] and [19, 1, k]):
- false-free rate: the sphere check passes, coal finds a collision (target <= 0.5 %);
- false-colliding rate: the sphere check rejects, coal finds the robot free;
- rates in one run, medians of interleaved rounds (5 on 2^20 configurations for the kernels, 3
  builds of 2^22 samples after one warm-up round): the FK + binning kernel alone, the sphere
  check alone, both, and whole builds (the chunk loop whose wall time ``build_map`` reports:
  sampling, FK, binning, counting) without self-collision and with it by the old kernel (the
  bounding hierarchy alone, ``SphereModel(pair_tables=False)``) and the new one (joint-pair
  tables first); wall rates and rates per CPU-second of all threads (the machine is shared:
  twice the CPU rate is what two idle cores would give at perfect scaling), the load average
  before and after each robot; the one-off setup of the sphere model; coal's rate on the
  accuracy configurations.

Usage: python bench/bench_self_collision.py [--configs 100000] [--robots tiago,tiago_dual,panda]
    [--name self_collision]
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np

from baseplace.reachability.build import BuildSettings, MapAccumulator, grid_for
from baseplace.robots.codegen import arm_kernels
from baseplace.robots.collision import SelfCollision
from baseplace.robots.model import Robot
from baseplace.robots.spec import ArmSpec, RobotSpec, _erd, example_robot_data_dir
from common import report


def panda() -> Robot:
    """A fixed Franka Panda: base panda_link0, TCP panda_hand_tcp, the SRDF's disabled pairs."""
    return Robot(
        RobotSpec(
            name="panda",
            urdf=_erd("panda_description/urdf/panda.urdf"),
            srdf=_erd("panda_description/srdf/panda.srdf"),
            base_frame="panda_link0",
            arms={"arm": ArmSpec(tuple(f"panda_joint{i}" for i in range(1, 8)), "panda_hand_tcp")},
            default_arm="arm",
            footprint_radius=0.1,
            package_dirs=(example_robot_data_dir(),),
        )
    )


def interleaved_rates(fns, n: int, repeats: int = 5) -> list[tuple[float, float]]:
    """(wall, CPU) rates of each function: n / median time over ``repeats`` interleaved rounds.

    Interleaving makes the ratios robust to load from other processes on a shared machine; the
    CPU rate (per second of CPU time of all threads) is what two idle cores would give, halved.
    """
    wall: list[list[float]] = [[] for _ in fns]
    cpu: list[list[float]] = [[] for _ in fns]
    for _ in range(repeats):
        for k, fn in enumerate(fns):
            t, c = time.perf_counter(), time.process_time()
            fn()
            wall[k].append(time.perf_counter() - t)
            cpu[k].append(time.process_time() - c)
    return [(n / statistics.median(w), n / statistics.median(c)) for w, c in zip(wall, cpu, strict=True)]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", type=int, default=100_000)
    parser.add_argument("--robots", default="tiago,tiago_dual,panda", help="comma-separated")
    parser.add_argument("--name", default="self_collision", help="results file bench/results/NAME.json")
    args = parser.parse_args()
    print(
        "| robot | false-free (old) | false-colliding (old) | coal colliding | spheres M/CPU-s old "
        "| new | ratio | build on M/CPU-s old | new | ratio | build off M/CPU-s | build on M/s wall "
        "| setup s | load |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = {}
    for name in args.robots.split(","):
        robot = panda() if name == "panda" else Robot(name)
        load = os.getloadavg()[0]
        rows[name] = row(robot, args.configs)
        r = rows[name]
        r["load_before"], r["load_after"] = load, os.getloadavg()[0]
        print(
            f"| {name} | {100 * r['false_free']:.3f} % ({100 * r['false_free_old']:.3f} %) "
            f"| {100 * r['false_colliding']:.2f} % ({100 * r['false_colliding_old']:.2f} %) "
            f"| {100 * r['coal_colliding']:.2f} % "
            f"| {r['spheres_old_per_cpu_s'] / 1e6:.2f} | {r['spheres_per_cpu_s'] / 1e6:.2f} "
            f"| {r['spheres_per_cpu_s'] / r['spheres_old_per_cpu_s']:.2f} "
            f"| {r['build_on_old_per_cpu_s'] / 1e6:.2f} | {r['build_on_per_cpu_s'] / 1e6:.2f} "
            f"| {r['build_on_per_cpu_s'] / r['build_on_old_per_cpu_s']:.2f} "
            f"| {r['build_off_per_cpu_s'] / 1e6:.2f} | {r['build_on_per_s'] / 1e6:.2f} "
            f"| {r['sphere_model_setup_s']:.1f} | {load:.1f}-{r['load_after']:.1f} |",
            flush=True,
        )
    report(args.name, {"configs": args.configs, "robots": rows}, used_seeds=[7, 8])


def row(robot: Robot, n_configs: int) -> dict:
    """Accuracy against coal on ``n_configs`` configurations and the rates, ``robot``'s default arm.

    ``old``: the sphere model without its joint-pair tables (the bounding hierarchy alone, the
    kernel before the tables), measured in the same run as the model with them.
    """
    from baseplace.robots.spheres import SphereModel

    arm = robot.arm()
    t = time.perf_counter()
    model = SphereModel(robot)
    setup = time.perf_counter() - t
    t = time.perf_counter()
    old = SphereModel(robot, pair_tables=False)
    setup_old = time.perf_counter() - t
    exact = SelfCollision(robot, num_threads=1)
    Q = arm.sample(np.random.default_rng(7), n_configs)
    t = time.perf_counter()
    coal = exact.colliding_arm(arm, Q)
    coal_rate = len(Q) / (time.perf_counter() - t)
    fast, fast_old = model.colliding_arm(arm, Q), old.colliding_arm(arm, Q)
    grid = grid_for(arm, BuildSettings())
    kernels = arm_kernels(arm)
    B = arm.sample(np.random.default_rng(8), 1 << 20)
    cells = np.empty(len(B), dtype=np.int64)
    kernels.bin_chunk(B, *grid.params, cells)  # compile

    def fk_only() -> None:
        kernels.bin_chunk(B, *grid.params, cells)

    def spheres_old() -> None:
        old.colliding_arm(arm, B)

    def spheres_new() -> None:
        model.colliding_arm(arm, B)

    def both() -> None:
        fk_only()
        spheres_new()

    rates = interleaved_rates((fk_only, spheres_old, spheres_new, both), len(B))
    (fk, _), (sph_old, sph_old_cpu), (sph, sph_cpu), (kern, _) = rates
    # whole builds (sampling, FK, binning, counting: the loop whose wall time build_map reports
    # as build_time_s), interleaved; the one-off setup (grid, kernels, sphere model) is timed
    # on its own above
    n_build = 1 << 22
    checkers = {"off": None, "old": old, "new": model}
    wall: dict[str, list[float]] = {k: [] for k in checkers}
    cpu: dict[str, list[float]] = {k: [] for k in checkers}
    dropped: dict[str, int] = {}
    for r in range(4):  # round 0 warms up
        for key, checker in checkers.items():
            acc = MapAccumulator(robot, None, BuildSettings(samples=n_build))
            acc._checker = checker  # the same sphere models, built once
            t, c = time.perf_counter(), time.process_time()
            for k in range(acc.n_chunks):
                acc.add_chunk(k)
            if r:
                wall[key].append(time.perf_counter() - t)
                cpu[key].append(time.process_time() - c)
            dropped[key] = acc.dropped
    build = {k: n_build / statistics.median(v) for k, v in wall.items()}
    build_cpu = {k: n_build / statistics.median(v) for k, v in cpu.items()}
    return {
        "spheres": len(model.sphere_radius),
        "geometry_pairs": len(model.geom_pairs),
        "checker": model.description,
        "checker_old": old.description,
        "false_free": float((coal & ~fast).mean()),
        "false_colliding": float((~coal & fast).mean()),
        "false_free_old": float((coal & ~fast_old).mean()),
        "false_colliding_old": float((~coal & fast_old).mean()),
        "coal_colliding": float(coal.mean()),
        "fk_bin_per_s": fk,
        "spheres_per_s": sph,
        "spheres_per_cpu_s": sph_cpu,
        "spheres_old_per_s": sph_old,
        "spheres_old_per_cpu_s": sph_old_cpu,
        "kernels_per_s": kern,
        "build_off_per_s": build["off"],
        "build_on_per_s": build["new"],
        "build_on_old_per_s": build["old"],
        "build_off_per_cpu_s": build_cpu["off"],
        "build_on_per_cpu_s": build_cpu["new"],
        "build_on_old_per_cpu_s": build_cpu["old"],
        "build_dropped_share": {k: v / n_build for k, v in dropped.items()},
        "sphere_model_setup_s": setup,
        "sphere_model_old_setup_s": setup_old,
        "coal_per_s": coal_rate,
    }


if __name__ == "__main__":
    main()
