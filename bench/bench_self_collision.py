"""Self-collision in the build kernel: the sphere model (robots/spheres.py) against coal.

For TIAGo, TIAGo dual (right arm, the left one at its reference) and a Franka Panda (example-robot-data, TCP panda_hand_tcp), on random arm
configurations (seed 7, disjoint from the model's calibration seed [19, 0]):
- false-free rate: the sphere check passes, coal finds a collision (target <= 0.5 %);
- false-colliding rate: the sphere check rejects, coal finds the robot free;
- rates, medians of 5 interleaved rounds on 2^20 configurations in one run: the FK + binning kernel alone (the
  build without self-collision, the baseline), the sphere check alone, and both (the
  self-collision-aware build), with coal's rate on a few hundred configurations.

Usage: python bench/bench_self_collision.py [--configs 100000] [--robots tiago,tiago_dual,panda]
"""

from __future__ import annotations

import argparse
import statistics
import time

import numpy as np

from baseplace.reachability.build import BuildSettings, grid_for
from baseplace.robots.codegen import arm_kernels
from baseplace.robots.collision import SelfCollision
from baseplace.robots.model import Robot
from baseplace.robots.spec import ArmSpec, RobotSpec, _erd, example_robot_data_dir


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


def interleaved_rates(fns, n: int, repeats: int = 5) -> list[float]:
    """Median rate [1/s] of each function over ``repeats`` rounds that run each once in turn.

    Interleaving makes the ratios robust to load from other processes on a shared machine.
    """
    times: list[list[float]] = [[] for _ in fns]
    for _ in range(repeats):
        for k, fn in enumerate(fns):
            t = time.perf_counter()
            fn()
            times[k].append(time.perf_counter() - t)
    return [n / statistics.median(ts) for ts in times]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--configs", type=int, default=100_000)
    parser.add_argument("--robots", default="tiago,tiago_dual,panda", help="comma-separated")
    args = parser.parse_args()
    print(
        "| robot | spheres | pairs | false-free | false-colliding | coal colliding | FK+bin M/s | spheres M/s | build with self-collision M/s | coal k/s |"
    )
    print("|---|---|---|---|---|---|---|---|---|---|")
    for name in args.robots.split(","):
        robot = panda() if name == "panda" else Robot(name)
        print(row(robot, args.configs), flush=True)


def row(robot: Robot, n_configs: int) -> str:
    """One table row: accuracy against coal and the three rates for ``robot``'s default arm."""
    from baseplace.robots.spheres import SphereModel

    arm = robot.arm()
    model = SphereModel(robot)
    exact = SelfCollision(robot, num_threads=1)
    Q = arm.sample(np.random.default_rng(7), n_configs)
    t = time.perf_counter()
    coal = exact.colliding_arm(arm, Q)
    coal_rate = len(Q) / (time.perf_counter() - t)
    fast = model.colliding_arm(arm, Q)
    false_free = float((coal & ~fast).mean())
    false_colliding = float((~coal & fast).mean())
    grid = grid_for(arm, BuildSettings())
    kernels = arm_kernels(arm)
    B = arm.sample(np.random.default_rng(8), 1 << 20)
    cells = np.empty(len(B), dtype=np.int64)
    kernels.bin_chunk(B, *grid.params, cells)  # compile
    model.colliding_arm(arm, B[:10])

    def fk_only() -> None:
        kernels.bin_chunk(B, *grid.params, cells)

    def spheres_only() -> None:
        model.colliding_arm(arm, B)

    def both() -> None:
        fk_only()
        spheres_only()

    fk, sph, build = interleaved_rates((fk_only, spheres_only, both), len(B))
    return (
        f"| {robot.name} | {len(model.sphere_radius)} | {len(model.geom_pairs)} | {100 * false_free:.3f} % "
        f"| {100 * false_colliding:.2f} % | {100 * coal.mean():.2f} % | {fk / 1e6:.2f} | {sph / 1e6:.3f} "
        f"| {build / 1e6:.3f} | {coal_rate / 1e3:.2f} |"
    )


if __name__ == "__main__":
    main()
