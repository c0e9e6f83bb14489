"""Self-collision in the build kernel: the sphere model (robots/spheres.py) against coal.

For TIAGo, TIAGo dual (right arm, the left one at its reference) and a Franka Panda (example-robot-data, TCP panda_hand_tcp), on random arm
configurations (seed 7, disjoint from the model's calibration seeds [19, 0] and [19, 1, k]):
- false-free rate: the sphere check passes, coal finds a collision (target <= 0.5 %);
- false-colliding rate: the sphere check rejects, coal finds the robot free;
- rates in one run, medians of interleaved rounds (5 on 2^20 configurations for the kernels, 3
  builds of 2^22 samples): the FK + binning kernel alone, the sphere check alone (also per
  CPU-second of all threads, as the machine is shared), both, and whole builds (``build_map``'s
  own build time: sampling, FK, binning, counting) without and with self-collision; the one-off
  setup of the sphere model; coal's rate on the accuracy configurations.

Usage: python bench/bench_self_collision.py [--configs 100000] [--robots tiago,tiago_dual,panda]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from baseplace.reachability.build import BuildSettings, build_map, grid_for
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
    args = parser.parse_args()
    print(
        "| robot | spheres | geometry pairs | false-free | false-colliding | coal colliding "
        "| FK+bin M/s | spheres M/s | spheres M/CPU-s | FK+bin+spheres M/s | build off M/s "
        "| build on M/s | model setup s | coal k/s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    rows = {}
    for name in args.robots.split(","):
        robot = panda() if name == "panda" else Robot(name)
        rows[name] = row(robot, args.configs)
        r = rows[name]
        print(
            f"| {name} | {r['spheres']} | {r['geometry_pairs']} | {100 * r['false_free']:.3f} % "
            f"| {100 * r['false_colliding']:.2f} % | {100 * r['coal_colliding']:.2f} % "
            f"| {r['fk_bin_per_s'] / 1e6:.2f} | {r['spheres_per_s'] / 1e6:.2f} "
            f"| {r['spheres_per_cpu_s'] / 1e6:.2f} | {r['kernels_per_s'] / 1e6:.2f} "
            f"| {r['build_off_per_s'] / 1e6:.2f} | {r['build_on_per_s'] / 1e6:.2f} "
            f"| {r['sphere_model_setup_s']:.1f} "
            f"| {r['coal_per_s'] / 1e3:.2f} |",
            flush=True,
        )
    report("self_collision", {"configs": args.configs, "robots": rows}, used_seeds=[7, 8])


def row(robot: Robot, n_configs: int) -> dict:
    """Accuracy against coal on ``n_configs`` configurations and the rates, ``robot``'s default arm."""
    from baseplace.robots.spheres import SphereModel

    arm = robot.arm()
    model = SphereModel(robot)
    exact = SelfCollision(robot, num_threads=1)
    Q = arm.sample(np.random.default_rng(7), n_configs)
    t = time.perf_counter()
    coal = exact.colliding_arm(arm, Q)
    coal_rate = len(Q) / (time.perf_counter() - t)
    fast = model.colliding_arm(arm, Q)
    grid = grid_for(arm, BuildSettings())
    kernels = arm_kernels(arm)
    B = arm.sample(np.random.default_rng(8), 1 << 20)
    cells = np.empty(len(B), dtype=np.int64)
    kernels.bin_chunk(B, *grid.params, cells)  # compile
    model.colliding_arm(arm, B[:10])
    n_build = 1 << 22
    build_map(robot, settings=BuildSettings(samples=1 << 20, self_collision=True))  # warm up

    def fk_only() -> None:
        kernels.bin_chunk(B, *grid.params, cells)

    def spheres_only() -> None:
        model.colliding_arm(arm, B)

    def both() -> None:
        fk_only()
        spheres_only()

    (fk, _), (sph, sph_cpu), (kern, _) = interleaved_rates((fk_only, spheres_only, both), len(B))
    # whole builds (sampling, FK, binning, counting), interleaved; the build time build_map
    # reports excludes the one-off setup (grid, kernels, the sphere model: timed on its own)
    build_times: dict[bool, list[float]] = {False: [], True: []}
    for _ in range(3):
        for on in (False, True):
            m = build_map(robot, settings=BuildSettings(samples=n_build, self_collision=on))
            build_times[on].append(m.info.build_time_s)
    off, on = (n_build / statistics.median(build_times[k]) for k in (False, True))
    t = time.perf_counter()
    SphereModel(robot)
    setup = time.perf_counter() - t
    return {
        "spheres": len(model.sphere_radius),
        "geometry_pairs": len(model.geom_pairs),
        "checker": model.description,
        "false_free": float((coal & ~fast).mean()),
        "false_colliding": float((~coal & fast).mean()),
        "coal_colliding": float(coal.mean()),
        "fk_bin_per_s": fk,
        "spheres_per_s": sph,
        "kernels_per_s": kern,
        "build_off_per_s": off,
        "build_on_per_s": on,
        "spheres_per_cpu_s": sph_cpu,
        "sphere_model_setup_s": setup,
        "coal_per_s": coal_rate,
    }


if __name__ == "__main__":
    main()
