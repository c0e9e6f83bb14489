"""The sphere self-collision model against the exact coal check (the oracle)."""

from __future__ import annotations

import numpy as np
import pytest

from baseplace.robots.collision import SelfCollision
from baseplace.robots.model import Robot
from baseplace.robots.spheres import SphereModel


@pytest.mark.parametrize("name", ["tiago", "tiago_dual"])  # dual: the other arm at its reference
def test_sphere_model_misses_few_coal_collisions(name: str) -> None:
    robot = Robot(name)
    arm = robot.arm()
    model = SphereModel(robot)
    exact = SelfCollision(robot, num_threads=1)
    Q = arm.sample(np.random.default_rng(2024), 1000)  # not the calibration seed
    coal = exact.colliding_arm(arm, Q)
    fast = model.colliding_arm(arm, Q)
    assert 0.05 < coal.mean() < 0.5  # the sample holds collisions to miss
    false_free = float((coal & ~fast).mean())
    false_colliding = float((~coal & fast).mean())
    assert false_free <= 0.005, false_free
    assert false_colliding <= 0.2, false_colliding


def test_build_with_self_collision_drops_samples() -> None:
    from baseplace.reachability.build import BuildSettings, build_map

    robot = Robot("tiago")
    m = build_map(robot, settings=BuildSettings(samples=20_000, self_collision=True))
    assert 0.05 * 20_000 < m.info.dropped_self_collision < 0.5 * 20_000
    assert int(m.counts.sum()) == 20_000 - m.info.dropped_self_collision
    assert m.info.self_collision_checker.startswith("spheres-2: ")  # provenance of the drops
