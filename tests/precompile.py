"""Compile the numba kernels that every test worker would otherwise compile at the same moment.

On a fresh machine numba's cache is empty, and both pytest workers reach the reaching-motion
check's state kernel and the IK solver within their first minutes: each compiled them, side by side
(a compile listener measured 2 x 48 s and 2 x 27 s of one core). ``conftest.py`` runs this script
in the xdist controller, before the workers start, as two processes side by side: ``motion`` (the
state kernel, about a minute and a half alone) and ``ik maps``, which in that time also compiles the
map build and lookups (one worker compiled those, later, while the other ran tests). They write
the kernels to numba's cache, from which the workers load them. With a warm cache it takes the
imports and the loads, a few seconds.

The calls are the library's own on small real inputs, so the compiled signatures are the ones the
tests use (a kernel called with other argument types would be compiled again).

    python tests/precompile.py PART...   (ik, maps, motion)
"""

from __future__ import annotations

import sys

import numpy as np

from baseplace.robots.fk import forward_kinematics
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot


def ik(robot: Robot) -> None:
    """The IK solver: one pose (``_solve_one``), a batch (``_solve_batch``), from given starts."""
    arm = robot.arm()
    rng = np.random.default_rng(0)
    T = np.stack([forward_kinematics(arm, q) for q in arm.sample(rng, 2)])
    solver = DampedLeastSquaresIK(arm, restarts=1)
    solver.solve(T[0], rng)
    solver.solve_batch(T, rng)
    solver.solve_from(T[0], arm.sample(rng, 2))


def maps(robot: Robot) -> None:
    """A map's build and its lookups: one pose, a batch, the inverse (serial and threaded), on a plane."""
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.reachability.rmap import SERIAL_BELOW

    arm = robot.arm()
    rmap = build_map(robot, None, BuildSettings(samples=100_000, seed=0))
    T = forward_kinematics(arm, arm.sample(np.random.default_rng(0), 1)[0])
    rmap.value(T)
    rmap.reachability(np.stack([T, T]))
    for n in (1, SERIAL_BELOW):
        rmap.inverse(T, np.stack([np.eye(4)] * n))
    rmap.inverse_on_plane(T, np.zeros((2, 2)), np.zeros(2), np.array([0.0, 0.0, 1.0]), 0.0)


def motion(robot: Robot) -> None:
    """The state kernel: states, lines, states at their own poses and contact proofs against a table scene, in both collision models."""
    from test_state_filter import _environments

    arm = robot.arm()
    rng = np.random.default_rng(0)
    target, transit, approach = _environments(robot, 0, (0, 0), 0)
    T_base = np.eye(4)
    T_base[:2, 3] = target[:2, 3] + (-0.62, 0.15)
    Q = arm.sample(rng, 2)
    for env in (transit, approach):
        env.colliding_arm(arm, Q[0], T_base)
        flt = env.state_filter(arm)
        flt.first_colliding_line(Q[0], Q[1], 8, 0.5, T_base)
        flt._touch_proven(Q[0], np.ones(len(flt._scene_rows), dtype=np.bool_), T_base @ flt._T_base_armbase)
        env.colliding_arm_poses(arm, Q, np.stack([T_base, T_base]))


if __name__ == "__main__":
    parts = {"ik": ik, "maps": maps, "motion": motion}
    if len(sys.argv) < 2 or not set(sys.argv[1:]) <= set(parts):
        sys.exit(f"usage: precompile.py PART... (parts: {', '.join(parts)})")
    tiago = Robot("tiago")
    for part in sys.argv[1:]:
        parts[part](tiago)
