"""The IRM search keeps a reach margin against the navigation error (issue 25, table-grid execution).

On the execution experiment's dev seeds the pickup took the pool's placement nearest the start,
at the far edge of the arm's reach (0.94 m from the bottle), and a 3 cm navigation error put the
bottle out of reach; a sixth of the other failures had the stowed arm refused at the drawn pose.
The search now verifies a (pose, grasp) pair only when the grasp is still reached from the pose
moved away from it by a margin taken from the base error model, and, with a motion check, the
stowed arm is clear at the poses that error reaches.

Oracles, independent of the search: the margin computed here from the error model's numbers, and
IK from the moved pose checked by pinocchio FK.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from baseplace.geometry.poses import BasePose
from baseplace.navigation.path import Path
from baseplace.placement.candidates import pickup
from baseplace.placement.irm_candidates import (
    IrmSettings,
    grasp_poses,
    grasp_standoff,
    irm_candidates,
    reach_margin,
)
from baseplace.placement.robustness import BaseErrorModel, RobustnessSettings
from baseplace.robots.ik import DampedLeastSquaresIK
from conftest import tcp_by_pinocchio

P_O = np.array(
    [0.0, 0.0, 1.0]
)  # a grasp point on a high shelf [m]: the map's best poses are at the edge of reach
K = 1.0  # the product's documented default margin, in standard deviations (docs/placement.md)


def _margin(lever: float, sigma_xy: float = 0.03, sigma_yaw_deg: float = 2.0, k: float = K) -> float:
    """Oracle: k standard deviations of the grasp's displacement along the base -> grasp line."""
    along = sigma_xy
    swing = lever * sigma_yaw_deg * math.pi / 180.0
    return k * math.sqrt(along * along + swing * swing)


def test_the_margin_follows_the_error_model():
    assert reach_margin(0.8, BaseErrorModel(), 2.0) == pytest.approx(_margin(0.8, k=2.0), abs=1e-12)
    assert _margin(0.8, k=2.0) == pytest.approx(0.08197, abs=1e-5)  # 8.2 cm at TIAGo's lever
    assert reach_margin(0.8, BaseErrorModel(), K) == pytest.approx(0.04099, abs=1e-5)
    wide = BaseErrorModel(sigma_xy=0.05, sigma_yaw=math.radians(5.0))
    got = reach_margin(np.array([0.0, 1.0]), wide, 3.0)
    assert got == pytest.approx([_margin(0.0, 0.05, 5.0, 3.0), _margin(1.0, 0.05, 5.0, 3.0)], abs=1e-12)
    # the product's default: 1 sigma of the error model the robustness score uses by default
    assert IrmSettings().reach_sigmas == K and IrmSettings().error == RobustnessSettings().error


def _keeps_margin(robot, placement, grasps) -> bool:
    """Oracle: IK reaches the placement's grasp from its pose moved the margin away, checked by pinocchio FK."""
    arm = robot.arm()
    G = grasps[placement.grasp]
    T = placement.pose.matrix()
    away = T[:2, 3] - G[:2, 3]
    lever = float(np.linalg.norm(away))
    T[:2, 3] += _margin(lever) * away / lever
    T_base_tcp = np.linalg.inv(T) @ G
    q = DampedLeastSquaresIK(arm, restarts=200).solve(T_base_tcp, np.random.default_rng(7))
    if q is None:
        return False
    reached = tcp_by_pinocchio(robot, arm, q)
    assert np.linalg.norm(reached[:3, 3] - T_base_tcp[:3, 3]) < 1e-3
    return True


@pytest.fixture(scope="module")
def grasps(tiago):
    arm = tiago.arm()
    return grasp_poses(P_O, n=8, standoff=grasp_standoff(tiago), approach_axis=arm.approach_axis)


def test_every_pooled_placement_keeps_the_reach_margin(tiago, tiago_map, grasps):
    found = irm_candidates(tiago, tiago_map, P_O, grasps, None, None, IrmSettings(count=4),
                           np.random.default_rng(0))  # fmt: skip
    assert len(found) == 4
    far = [round(math.dist(c.xy, P_O[:2]), 3) for c in found if not _keeps_margin(tiago, c, grasps)]
    assert not far, f"placements at the edge of reach (distance to the object [m]): {far}"


def test_pickup_takes_a_placement_with_the_margin_over_one_at_the_edge(tiago, tiago_map, grasps):
    """Both kinds exist; the one at the edge is nearer the start, yet the chosen one keeps the margin."""
    nominal = irm_candidates(tiago, tiago_map, P_O, grasps, None, None, IrmSettings(count=4, reach_sigmas=0.0),
                             np.random.default_rng(0))  # fmt: skip
    edge = [c for c in nominal if not _keeps_margin(tiago, c, grasps)]
    assert edge, "the scene must offer a placement at the edge of reach"
    out = (edge[0].xy - P_O[:2]) / np.linalg.norm(edge[0].xy - P_O[:2])
    start = BasePose(*(P_O[:2] + 3.0 * out), 0.0)  # beyond the edge placement, on its side

    def navigate(current: BasePose, goal: BasePose) -> Path:
        return Path(np.array([[current.x, current.y, 0.0], [goal.x, goal.y, 0.0]]), "test", 0.0, ())

    assert pickup(nominal, P_O, start, navigate).chosen in edge  # without the margin: the edge one
    pool = irm_candidates(tiago, tiago_map, P_O, grasps, None, None, IrmSettings(count=4),
                          np.random.default_rng(0))  # fmt: skip
    chosen = pickup(pool, P_O, start, navigate).chosen
    assert chosen is not None and _keeps_margin(tiago, chosen, grasps)


def test_without_a_pose_that_keeps_the_margin_the_nominal_ones_are_returned(tiago, tiago_map, grasps):
    huge = IrmSettings(count=2, error=BaseErrorModel(sigma_xy=0.5, xy_tolerance=2.0))  # a 1 m margin
    found = irm_candidates(tiago, tiago_map, P_O, grasps, None, None, huge, np.random.default_rng(0))
    assert len(found) == 2


def test_a_negative_or_infinite_margin_is_refused():
    from baseplace.errors import InputError

    for bad in (-1.0, math.inf, math.nan):
        with pytest.raises(InputError, match="reach_sigmas"):
            IrmSettings(reach_sigmas=bad)


def _table_ahead(robot, edge: float):
    """A table top (0.72 m high, 1 m deep) whose near edge is ``edge`` [m] ahead of a base at the origin."""
    from baseplace.terrain.voxels import VoxelMap
    from baseplace.world.environment import Environment

    X, Y = np.meshgrid(np.arange(0.0, 1.0, 0.01), np.arange(-1.0, 1.0, 0.01))
    top = np.stack([edge + X.ravel(), Y.ravel(), np.full(X.size, 0.72)], axis=1)
    return Environment(robot, VoxelMap.from_points(top, 0.01))


def test_a_pose_whose_stowed_arm_meets_the_table_after_a_navigation_error_is_refused(tiago):
    """The stowed arm clears the table edge at the nominal pose but not 2 sigma (6 cm) closer to it."""
    from baseplace.placement.irm_candidates import stowed_clear_under_error
    from baseplace.placement.motion import MotionChecker

    arm = tiago.arm()
    T_base = np.eye(4)
    target = np.eye(4)
    target[:3, 3] = (0.9, 0.0, 0.8)  # across the table, straight ahead
    closer = np.eye(4)
    closer[0, 3] = 2 * 0.03
    near = MotionChecker(tiago, arm, _table_ahead(tiago, 0.28))
    assert not near.environment.colliding_arm(arm, near.q_start, T_base)  # clear where it was sent
    assert near.environment.colliding_arm(arm, near.q_start, closer)  # not 6 cm closer
    assert not stowed_clear_under_error(near, T_base, target, BaseErrorModel(), 2.0)
    far = MotionChecker(tiago, arm, _table_ahead(tiago, 0.40))
    assert stowed_clear_under_error(far, T_base, target, BaseErrorModel(), 2.0)


def test_the_candidates_json_states_the_margin(tiago, tiago_map):
    from baseplace.jobs.candidates import CandidatesJob, candidates_job
    from conftest import SHARED

    job = CandidatesJob(object="-1.025 -0.775 0.6", occupancy=str(SHARED / "maps" / "tb3_sandbox.yaml"),
                        method="irm", robot=tiago, map=tiago_map)  # fmt: skip
    margin = candidates_job(job).settings["reach_margin"]
    assert margin["sigmas"] == K and margin["sigma_xy"] == 0.03
    assert margin["at_lever_0.8_m"] == pytest.approx(_margin(0.8), abs=1e-4)
    assert (
        candidates_job(CandidatesJob(**{**job.__dict__, "method": "radial"})).settings["reach_margin"] is None
    )


def test_the_search_and_its_json_take_the_margin_from_the_jobs_own_error_model(tiago, tiago_map, monkeypatch):
    """A job that states a wider navigation error (``--sigma-xy``, ``--sigma-yaw-deg``) gets a wider margin."""
    import baseplace.placement.object_search as object_search
    from baseplace.jobs.candidates import CandidatesJob, candidates_job
    from conftest import SHARED

    seen: list[IrmSettings] = []
    real = object_search.irm_candidates

    def spy(*args, **kwargs):
        seen.append(args[6])  # the search's settings, as object_search passes them
        return real(*args, **kwargs)

    monkeypatch.setattr(object_search, "irm_candidates", spy)
    wide = BaseErrorModel(sigma_xy=0.06, sigma_yaw=math.radians(4.0))
    job = CandidatesJob(object="-1.025 -0.775 0.6", occupancy=str(SHARED / "maps" / "tb3_sandbox.yaml"),
                        method="irm", robot=tiago, map=tiago_map,
                        robustness=RobustnessSettings(samples=0, error=wide))  # fmt: skip
    margin = candidates_job(job).settings["reach_margin"]
    assert margin["sigma_xy"] == 0.06
    assert margin["at_lever_0.8_m"] == pytest.approx(_margin(0.8, 0.06, 4.0), abs=1e-4)
    assert seen and all(s.error == wide for s in seen)
