from __future__ import annotations

import itertools

import coal
import numpy as np
import pinocchio as pin
import pytest

from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.placement.motion import (
    MOTION_FAILURES,
    MotionChecker,
    MotionSettings,
    bisection_order,
    stowed_configuration,
)
from baseplace.placement.verify import Candidate, Verifier, motion_failure_summary
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.terrain.polygons import footprint_outline
from baseplace.terrain.voxels import VoxelMap
from baseplace.world.environment import Environment
from conftest import tcp_by_pinocchio

RES = 0.025
TARGET = [0.75, -0.15, 0.85, 0.0, 0.0, 0.0]  # side grasp in front of the base, TCP x forward


def _empty() -> VoxelMap:
    return VoxelMap(RES, np.zeros((0, 3), dtype=np.int64))


@pytest.fixture(scope="module")
def wall_scene(tiago):
    """A wall across the wrist of the grasp configuration, with a hole cut 1.5 cm around the arm.

    The final configuration is free (the hole clears it), but the hand (its safety box is
    0.2 x 0.115 x 0.18 m) is beyond the wall and cannot pass the wrist-sized hole: every path
    from the stowed configuration, hand on the robot's side, runs into the wall.
    """
    arm = tiago.arm()
    target = pose_from_xyz_rpy(TARGET)
    q = DampedLeastSquaresIK(arm).solve(target, np.random.default_rng(0))
    assert q is not None
    ys, zs = np.arange(-1.5, 1.5, RES), np.arange(0.0, 1.8, RES)
    wall = np.array([[x, y, z] for x in (0.68, 0.705) for y in ys for z in zs])
    centres = VoxelMap.from_points(wall, RES).centres
    env0 = Environment(tiago, _empty())
    data, gdata = tiago.model.createData(), pin.GeometryData(env0.geom)
    pin.updateGeometryPlacements(tiago.model, data, env0.geom, gdata, arm.to_pinocchio(q, tiago.q_reference))
    near = np.flatnonzero((np.abs(centres[:, 1] + 0.15) < 0.3) & (np.abs(centres[:, 2] - 0.85) < 0.3))
    box, request = coal.Box(RES, RES, RES), coal.DistanceRequest()
    keep = np.ones(len(centres), dtype=bool)
    for k, obj in enumerate(env0.geom.geometryObjects):
        M = gdata.oMg[k]
        if M.translation[0] < 0.55:
            continue
        for i in near[keep[near]]:
            d = coal.distance(obj.geometry, coal.Transform3s(M.rotation, M.translation), box,
                              coal.Transform3s(np.eye(3), centres[i]), request, coal.DistanceResult())  # fmt: skip
            if d < 0.015:
                keep[i] = False
    hole = centres[~keep]
    assert 5 < len(hole) < 80  # a hole around the wrist, not a missing wall
    return target, q, VoxelMap.from_points(centres[keep], RES), env0


def test_caged_path_is_rejected_with_reason_motion(tiago, wall_scene):
    target, q, wall, _ = wall_scene
    arm = tiago.arm()
    env = Environment(tiago, wall)
    outline = footprint_outline(tiago.spec.footprint_radius, None)
    # Independent of the motion check: the final configuration and the stowed one are both free.
    assert not env.colliding(arm.to_pinocchio(q, tiago.q_reference), np.eye(4))
    assert not env.colliding(arm.to_pinocchio(stowed_configuration(tiago, arm), tiago.q_reference), np.eye(4))
    plain = Verifier(arm, DampedLeastSquaresIK(arm), env, target[None], {}, outline)
    assert plain.check(Candidate(np.eye(4), -1, 0.0), np.random.default_rng(0)) is not None
    # a short approach (3 cm) that stays clear of the wall: what is blocked is the way from stowed
    settings = MotionSettings(pregrasp_distance=0.03, time_limit=1.5)
    motion = MotionChecker(tiago, arm, env, settings=settings)
    assert motion.approach(q, target, np.eye(4)) is not None
    checked = Verifier(arm, DampedLeastSquaresIK(arm), env, target[None], {}, outline, motion=motion)
    assert checked.check(Candidate(np.eye(4), -1, 0.0), np.random.default_rng(0)) is None
    assert dict(checked.failures) == {"motion": 1}
    # the reason: both ends of the transit are free (above), so RRTConnect ran out of time
    assert motion.last_failure == "no_rrt_path" and dict(checked.motion_failures) == {"no_rrt_path": 1}
    assert motion_failure_summary(checked.motion_failures) == (
        "no reaching motion: no collision-free path to the pre-grasp within the time limit (1 candidate)"
    )


def test_a_grasp_whose_pregrasp_is_out_of_reach_is_refused_for_the_approach(tiago):
    """A top-down grasp at 1.2 m that IK solves, whose pre-grasp 0.15 m above it IK solves from no start."""
    arm = tiago.arm()
    ik = DampedLeastSquaresIK(arm, restarts=20)
    target = pose_from_xyz_rpy([0.6, -0.15, 1.2, 0.0, np.pi / 2, 0.0])
    q = ik.solve(target, np.random.default_rng(0))
    assert q is not None
    np.testing.assert_allclose(tcp_by_pinocchio(tiago, arm, q), target, atol=1e-3)
    motion = MotionChecker(tiago, arm, Environment(tiago, _empty()))
    above = target.copy()
    above[2, 3] += motion.pregrasp_distance  # no grasped object: the approach has its whole length
    for seed in range(5):  # the oracle of "out of reach": IK from 5 x 21 starts
        assert ik.solve(above, np.random.default_rng(seed)) is None
    assert motion.check(q, np.eye(4), target) is None
    assert motion.last_failure == "approach_ik" and motion.last_contacts == []
    # a later motion found clears the reason
    low = pose_from_xyz_rpy([0.6, -0.15, 1.0, 0.0, np.pi / 2, 0.0])
    q_low = ik.solve(low, np.random.default_rng(0))
    assert q_low is not None and motion.check(q_low, np.eye(4), low) is not None
    assert motion.last_failure is None


def test_seed_004_candidates_refused_for_the_motion_carry_the_reason(tiago):
    """verify_candidates (the candidates job's check) keeps the motion check's reason per position."""
    from baseplace.geometry.poses import BasePose
    from baseplace.placement.candidates import RadialCandidate
    from baseplace.placement.irm_candidates import verify_candidates

    arm = tiago.arm()
    target = pose_from_xyz_rpy([0.6, -0.15, 1.2, 0.0, np.pi / 2, 0.0])  # the pre-grasp out of reach (above)
    env = Environment(tiago, _empty())
    motion = MotionChecker(tiago, arm, env)
    near = RadialCandidate(BasePose(0.0, 0.0, 0.0), 0.6)
    far = RadialCandidate(BasePose(-4.0, 0.0, 0.0), 4.6)  # no IK: nothing to move to
    verified, rejected = verify_candidates(tiago, None, [near, far], target[None], env,
                                           np.random.default_rng(0), motion)  # fmt: skip
    assert not verified
    assert [(c, why, reason) for c, why, reason in rejected] == [
        (near, "motion", "approach_ik"),
        (far, "no_ik", None),
    ]
    # without the motion check the near one passes: the refusal was the motion's
    verified, rejected = verify_candidates(tiago, None, [near], target[None], env, np.random.default_rng(0))
    assert len(verified) == 1 and not rejected


def test_the_candidates_result_schema_takes_motion_failures_by_code_only():
    import json
    from importlib import resources

    import jsonschema

    schema = json.loads(resources.files("baseplace.jobs").joinpath("result.schema.json").read_text())
    result = {"kind": "candidates", "version": 1, "candidates": [], "method": "radial", "object": [0, 0, 0],
              "rejected": [], "path": None, "motion_failures": {"approach_ik": 3}}  # fmt: skip
    branch = next(
        b for b in schema["allOf"] if b["if"].get("properties", {}).get("kind") == {"const": "candidates"}
    )
    check = {"$defs": schema["$defs"], **branch["then"]}
    jsonschema.validate(result, check)
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate({**result, "motion_failures": {"timeout": 1}}, check)


def test_every_motion_failure_has_a_phrase_and_is_in_the_result_schema():
    import json
    from importlib import resources

    schema = json.loads(resources.files("baseplace.jobs").joinpath("result.schema.json").read_text())
    codes = [c for c in schema["$defs"]["motion_failure"]["enum"] if c is not None]
    assert sorted(codes) == sorted(MOTION_FAILURES)
    assert all(phrase and "\n" not in phrase for phrase in MOTION_FAILURES.values())


def test_same_scene_without_the_wall_passes_with_a_valid_motion(tiago, wall_scene):
    target, _, _, env0 = wall_scene
    arm = tiago.arm()
    outline = footprint_outline(tiago.spec.footprint_radius, None)
    motion = MotionChecker(tiago, arm, env0)
    verifier = Verifier(arm, DampedLeastSquaresIK(arm), env0, target[None], {}, outline, motion=motion)
    placement = verifier.check(Candidate(np.eye(4), -1, 0.0), np.random.default_rng(0))
    assert placement is not None and placement.motions is not None
    m = placement.motions[0]
    np.testing.assert_allclose(m.path[0], stowed_configuration(tiago, arm))
    np.testing.assert_allclose(m.approach[-1], placement.joints[0])
    np.testing.assert_allclose(m.path[-1], m.approach[0])
    # Oracle: pinocchio FK. The approach runs straight along the TCP's x axis, ending on the grasp.
    tcp = np.array([tcp_by_pinocchio(tiago, arm, qa) for qa in m.approach])
    np.testing.assert_allclose(tcp[-1], target, atol=1e-3)
    back = (target[:3, 3] - tcp[:, :3, 3]) @ target[:3, 0]
    lateral = np.linalg.norm((target[:3, 3] - tcp[:, :3, 3]) - back[:, None] * target[:3, 0], axis=1)
    assert (
        back[0] == pytest.approx(motion.pregrasp_distance, abs=1e-3)
        and np.all(np.diff(back) < 0)
        and lateral.max() < 1e-3
    )
    for T in tcp:
        np.testing.assert_allclose(T[:3, :3], target[:3, :3], atol=5e-3)
    # Oracle: the full-configuration collision check on the densified path (not the arm-pruned one).
    for a, b in zip(m.waypoints[:-1], m.waypoints[1:], strict=True):
        for s in np.linspace(0, 1, 6):
            qs = arm.to_pinocchio(a + s * (b - a), tiago.q_reference)
            assert not env0.colliding(qs, np.eye(4))


def test_motion_settings_and_start_configuration_are_checked(tiago):
    from baseplace.errors import InputError

    env = Environment(tiago, _empty())
    with pytest.raises(InputError, match="pregrasp_distance"):
        MotionSettings(pregrasp_distance=-0.1)
    with pytest.raises(InputError, match="start configuration"):
        MotionChecker(tiago, tiago.arm(), env, settings=MotionSettings(q_start=(0.0,) * 3))


def test_bisection_order_visits_every_state_of_a_line_once():
    for n in (1, 2, 3, 7, 16, 33):
        order = bisection_order(n)
        assert sorted(order) == list(range(1, n + 1)) and order[0] == n
    assert bisection_order(8)[:3] == [8, 4, 2]


@pytest.fixture(scope="module")
def table_goal(tiago):
    """A table in front of the robot (its points as 25 mm voxels, and the true box 1 cm inside
    them) and a free goal over it whose straight joint line from stowed is blocked."""
    from baseplace_experiments.table_grid import TrueShape

    arm = tiago.arm()
    lo, hi = np.array([0.45, -0.6, 0.66]), np.array([1.2, 0.6, 0.72])
    g = [np.arange(a, b + 1e-9, 0.01) for a, b in zip(lo, hi, strict=True)]
    pts = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 3)
    env = Environment(tiago, VoxelMap.from_points(pts, RES))
    T = np.eye(4)
    T[:3, 3] = (lo + hi) / 2
    table = TrueShape("table", coal.Box(*(hi - lo - 0.02)), T)  # 1 cm inside the sampled points
    motion = MotionChecker(tiago, arm, env)
    rng = np.random.default_rng(5)
    for q in arm.sample(rng, 2000):
        p = tcp_by_pinocchio(tiago, arm, q)[:3, 3]
        if not (0.6 < p[0] < 0.9 and abs(p[1]) < 0.3 and 0.85 < p[2] < 1.0):
            continue
        if motion._free(q, np.eye(4)) and not motion._line_free(motion.q_start, q, np.eye(4)):
            return env, table, q
    raise AssertionError("no goal over the table")


def _free_by_coal(tiago, path, table) -> None:
    """Every state 1 cm of joint motion apart on every segment clears the true table (coal on its
    own pinocchio geometry, no voxels)."""
    from baseplace_experiments.table_grid import RobotShapes

    shapes = RobotShapes(tiago)
    for a, b in itertools.pairwise(path):
        steps = max(1, int(np.ceil(np.linalg.norm(b - a) / 0.01)))
        for s in np.linspace(0.0, 1.0, steps + 1):
            assert shapes.touching(a + s * (b - a), np.eye(4), [table]) is None


def test_planned_and_shortened_path_is_free_by_an_independent_check(tiago, table_goal):
    """A table in front of the robot blocks the straight joint line from stowed: RRTConnect plans
    (searching at ``search_step``, kept at ``point_step``) and the greedy shortcut shortens.
    Oracle: coal on the true table box, every state 1 cm of joint motion apart on every segment."""
    env, table, goal = table_goal
    motion = MotionChecker(tiago, tiago.arm(), env, settings=MotionSettings(time_limit=20.0))  # loaded CI
    path, planned = motion.joint_path(goal, np.eye(4), seed=3)
    assert planned and path is not None
    np.testing.assert_allclose(path[0], motion.q_start)
    np.testing.assert_allclose(path[-1], goal)
    _free_by_coal(tiago, path, table)


def test_a_search_path_that_touches_at_the_point_step_is_searched_again(tiago, table_goal):
    """A search step of 1 m checks each of the search's edges at a state or two, so the path it
    returns crosses the table; checked at ``point_step`` it is refused, and the search runs again at
    ``point_step``: the path returned is free by the independent check, and the search ran twice.
    Without the check of the search's path (its edges kept as searched), the test fails."""
    env, table, goal = table_goal
    settings = MotionSettings(time_limit=20.0, search_step=1.0)
    motion = MotionChecker(tiago, tiago.arm(), env, settings=settings)
    factors = []
    rrt = motion._rrt

    def counted(*args, **kwargs):  # type: ignore[no-untyped-def]
        factors.append(motion._search_factor)
        return rrt(*args, **kwargs)

    motion._rrt = counted  # type: ignore[method-assign]
    path, planned = motion.joint_path(goal, np.eye(4), seed=3)
    assert planned and path is not None
    assert factors == [100.0, 1.0]
    _free_by_coal(tiago, path, table)
    with pytest.raises(Exception, match="search_step"):
        MotionSettings(search_step=0.0)


def test_a_check_budget_stops_planning_before_the_time_limit(tiago, wall_scene):
    """In the caged scene no path exists, so RRTConnect runs until a limit: with a 60 s time limit
    and a budget of 200 validity checks it must stop on the budget (counted independently by
    wrapping the environment's collision check), a few checks of one extension past it at most."""
    _, q, wall, _ = wall_scene
    arm = tiago.arm()
    env = Environment(tiago, wall)
    counted = [0]
    colliding = env.colliding_arm

    def counting(*args, **kwargs):  # type: ignore[no-untyped-def]
        counted[0] += 1
        return colliding(*args, **kwargs)

    env.colliding_arm = counting  # type: ignore[method-assign]
    first_colliding = env.first_colliding_arm_line

    def counting_line(arm, a, b, n, travel, T):  # type: ignore[no-untyped-def]
        k, asked = first_colliding(arm, a, b, n, travel, T)  # a whole line: the states it asked
        counted[0] += asked
        return k, asked

    env.first_colliding_arm_line = counting_line  # type: ignore[method-assign]
    settings = MotionSettings(pregrasp_distance=0.03, time_limit=60.0, max_checks=200)
    motion = MotionChecker(tiago, arm, env, settings=settings)
    path, planned = motion.joint_path(q, np.eye(4), seed=1)
    assert path is None and planned
    line = motion.edge_states(motion.q_start, q)
    assert 200 <= counted[0] <= 200 + line + 2 + 100  # the straight line, the ends, one extension
    with pytest.raises(Exception, match="max_checks"):
        MotionSettings(max_checks=0)


def test_the_edge_validator_checks_the_new_end_of_an_edge_from_either_side(tiago, table_goal):
    """RRTConnect's goal tree asks for edges from a new state to the tree, and the planner's state
    validity checker no longer checks that state: the edge validator must. A free state and a
    colliding one a hair apart on the line from stowed into the table (by bisection: one checked
    state between them) are joined by an edge that is refused whichever end is the tree's, and the
    free state's edge back to stowed is accepted."""
    from ompl import base as ob

    from baseplace.placement.motion import _edge_validator

    env = table_goal[0]
    arm = tiago.arm()
    motion = MotionChecker(tiago, arm, env)
    T = np.eye(4)
    free, hit = (
        motion.q_start,
        next(q for q in arm.sample(np.random.default_rng(1), 500) if not motion._free(q, T)),
    )
    while np.max(np.abs(hit - free)) > 1e-4:  # the last free state before the first colliding one
        mid = 0.5 * (free + hit)
        free, hit = (mid, hit) if motion._free(mid, T) else (free, mid)
    assert motion.edge_states(free, hit) == 1 and motion._line_free(motion.q_start, free, T)
    space = ob.RealVectorStateSpace(arm.n_joints)
    bounds = ob.RealVectorBounds(arm.n_joints)
    for i in range(arm.n_joints):
        bounds.setLow(i, float(arm.lower[i]))
        bounds.setHigh(i, float(arm.upper[i]))
    space.setBounds(bounds)
    info = ob.SpaceInformation(space)

    def state(q):  # type: ignore[no-untyped-def]
        s = space.allocState()
        for i in range(arm.n_joints):
            s[i] = float(q[i])
        return s

    validator = _edge_validator(info, motion, T, (motion.q_start,))
    assert validator.checkMotion(state(motion.q_start), state(free))  # the start tree grows to `free`
    assert not validator.checkMotion(state(hit), state(free))  # a goal-tree edge from the new `hit`
    assert not validator.checkMotion(state(free), state(hit))
    fresh = _edge_validator(info, motion, T, (free,))
    assert not fresh.checkMotion(state(hit), state(free))
    assert not fresh.checkMotion(state(hit), state(hit + 1e-5))  # neither end known: both checked
