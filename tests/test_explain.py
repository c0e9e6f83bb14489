"""``explain``: the checks of ``place`` at one base pose for one target (issue 29, item 6).

Oracles: the rejections ``place`` itself records (the verifier's own log of each candidate and
its first contact), pinocchio's frame placements for the TCP the returned joints reach, and the
result schema.
"""

from __future__ import annotations

import json
import math

import jsonschema
import numpy as np
import pinocchio as pin
import pytest

from baseplace.geometry.poses import matrix_to_rpy, pose_from_xyz_rpy
from baseplace.jobs import result_schema
from baseplace.jobs.explain import ExplainJob, explain_job
from baseplace.jobs.inputs import CloudInput
from baseplace.placement import pipeline
from baseplace.placement.pipeline import PlaceSettings, place
from baseplace.reachability.storage import save_map
from baseplace.robots.ik import DampedLeastSquaresIK
from conftest import run_cli
from test_grasped_object import THROUGH_B, A, B, cloud, tray_scene


def _validated(obj: dict) -> dict:
    jsonschema.validate(obj, result_schema())
    return obj


def _pose_text(T: np.ndarray) -> str:
    return " ".join(repr(float(v)) for v in [*T[:3, 3], *matrix_to_rpy(T[:3, :3])])


def _tcp_by_pinocchio(robot, joints: dict[str, float], T_world_base: np.ndarray) -> np.ndarray:
    """The world TCP pose of the arm joints, from pinocchio's own frame placements."""
    arm = robot.arm()
    q = np.array([joints[n] for n in arm.joint_names])
    model, data = robot.model, robot.model.createData()
    pin.framesForwardKinematics(model, data, arm.to_pinocchio(q, robot.q_reference))
    T_base_tcp = (
        data.oMf[model.getFrameId(arm.base_frame)].inverse() * data.oMf[model.getFrameId(arm.tcp_frame)]
    )
    return T_world_base @ T_base_tcp.homogeneous


@pytest.fixture(scope="module")
def refused(tiago, tiago_map):
    """place's refusals on the two-bottle tray (the hand lies across bottle B from every base pose):
    the base pose of each candidate the verifier rejected for a collision, with its first contact."""
    points = cloud(tray_scene(A, B))
    log: list[tuple[np.ndarray, tuple[str, str]]] = []

    class Recording(pipeline.Verifier):
        def _reject(self, T, reason, contact=None):
            super()._reject(T, reason, contact)
            if reason == "collision":
                log.append((T.copy(), contact))

    saved = pipeline.Verifier
    pipeline.Verifier = Recording
    try:
        result = place(tiago, tiago_map, points, THROUGH_B, PlaceSettings(tries=4, motion=None),
                       np.random.default_rng(0), grasped="auto")  # fmt: skip
    finally:
        pipeline.Verifier = saved
    assert not result.placements and log, dict(result.failures)
    return points, log


def test_explain_at_a_refused_pose_names_the_refusals_link_and_object(tiago, tiago_map, refused):
    points, log = refused
    T_refused, (link, touched) = log[0]
    yaw = math.atan2(T_refused[1, 0], T_refused[0, 0])
    report = explain_job(ExplainJob((T_refused[0, 3], T_refused[1, 3], yaw), _pose_text(THROUGH_B), tiago_map,
                                    tiago, cloud=CloudInput(points=points)))  # fmt: skip
    obj = _validated(report.to_json())
    # the very pose place checked: on the same region, at the same height
    assert np.allclose(obj["base"]["base_pose"], T_refused, atol=1e-6)
    assert obj["footprint"] == {"checked": True, "fits": True}
    assert obj["ik"]["solved"] and obj["ik"]["position_error"] < 1e-3
    assert {"link": link, "touched": touched, "kind": "scene"} in obj["collisions"], obj["collisions"]
    assert obj["verdict"]["failed_check"] == "collision" and obj["failures"] == {"collision": 1}
    assert f"{link}" in obj["verdict"]["summary"] and f"touched {touched}" in obj["verdict"]["summary"]
    assert not obj["motion"]["checked"]  # place checks no motion from a colliding grasp either
    assert obj["object"]["allowed"]["kind"] == "points"  # bottle A, the grasped object


def test_explain_through_the_cli_names_place_s_most_frequent_contact(tiago_map, refused, tmp_path):
    points, log = refused
    map_file, cloud_file = tmp_path / "tiago.rmap", tmp_path / "two_bottles.npy"
    save_map(tiago_map, map_file)
    np.save(cloud_file, points)
    target = _pose_text(THROUGH_B)
    placed = run_cli("place", "--cloud", str(cloud_file), "--map", str(map_file), "--target", target,
                     "--tries", "4", "--no-motion-check", "--robustness-samples", "0", "--json")  # fmt: skip
    assert placed.returncode == 3
    worst = json.loads(placed.stdout)["collisions"][0]
    assert f"link {worst['link']} touched {worst['touched']}" in placed.stderr
    T, _ = log[0]
    base = f"{float(T[0, 3])!r} {float(T[1, 3])!r} {math.atan2(T[1, 0], T[0, 0])!r}"
    proc = run_cli("explain", "--map", str(map_file), "--cloud", str(cloud_file), "--base", base, "--target",
                   target, "--no-motion-check", "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    obj = _validated(json.loads(proc.stdout))
    assert {"link": worst["link"], "touched": worst["touched"], "kind": "scene"} in obj["collisions"]
    assert obj["verdict"]["summary"].startswith("refused: ")
    text = run_cli("explain", "--map", str(map_file), "--cloud", str(cloud_file), "--base", base, "--target",
                   target, "--no-motion-check")  # fmt: skip
    assert text.returncode == 0 and text.stdout.splitlines()[0] == obj["verdict"]["summary"]
    assert f"collision: link {worst['link']} touched {worst['touched']}" in text.stdout


def test_explain_names_why_no_reaching_motion_was_found(tiago, tiago_map):
    """A top-down grasp 1.2 m up, 0.6 m ahead of the base over a bare floor: IK solves it, the
    pre-grasp 0.15 m above it is out of reach (tests/test_motion.py checks that with IK from 105
    starts); explain said "no path found in time" for this before it named the reason."""
    xs, ys = np.meshgrid(np.arange(-1.5, 2.5, 0.02), np.arange(-1.5, 2.5, 0.02))
    floor = np.c_[xs.ravel(), ys.ravel(), np.zeros(xs.size)]
    report = explain_job(ExplainJob("0.4 0.65 0", "1.0 0.5 1.2 0 1.5708 0", tiago_map, tiago,
                                    cloud=CloudInput(points=floor)))  # fmt: skip
    obj = _validated(report.to_json())
    assert obj["ik"]["solved"] and not obj["collisions"]
    assert obj["motion"]["checked"] and obj["motion"]["found"] is False
    assert obj["motion"]["reason"] == "approach_ik" and obj["motion"]["contacts"] == []
    assert obj["verdict"]["failed_check"] == "motion"
    assert "the straight approach leaves the arm's reach or joint limits" in obj["verdict"]["summary"]
    assert "no path found" not in obj["verdict"]["summary"]


def test_a_reachable_target_ik_solves_and_pinocchio_puts_the_tcp_there(tiago, tiago_map):
    arm = tiago.arm()
    T_world_base = pose_from_xyz_rpy([0.4, -0.3, 0.0, 0.0, 0.0, 0.7])
    q = arm.sample(np.random.default_rng(5), 1)[0]
    target = T_world_base @ (_tcp_by_pinocchio(tiago, dict(zip(arm.joint_names, q, strict=True)), np.eye(4)))
    obj = _validated(explain_job(ExplainJob("0.4 -0.3 0.7", _pose_text(target), tiago_map, tiago)).to_json())
    assert obj["ik"]["solved"] and obj["ik"]["starts"] == 81
    reached = _tcp_by_pinocchio(tiago, obj["ik"]["joints"], np.array(obj["base"]["base_pose"]))
    assert np.linalg.norm(reached[:3, 3] - target[:3, 3]) < 1e-3
    assert math.acos(np.clip((np.trace(reached[:3, :3].T @ target[:3, :3]) - 1) / 2, -1, 1)) < 2e-3
    assert obj["base"]["region"] == -1 and not obj["footprint"]["checked"] and not obj["motion"]["checked"]
    assert all(c["kind"] == "self" for c in obj["collisions"])  # no scene: only the robot itself
    assert obj["verdict"]["ok"] == (not obj["collisions"])


def test_an_unreachable_target_reports_the_best_residual(tiago, tiago_map):
    # 2.5 m ahead of the base: farther than TIAGo's arm reaches from any torso height
    obj = _validated(explain_job(ExplainJob("0 0 0", "2.5 0 0.8 0 0 0", tiago_map, tiago)).to_json())
    ik = obj["ik"]
    assert not ik["solved"] and ik["starts"] == 81
    assert ik["position_error"] > 2.5 - tiago_map.horizontal_reach - 0.1
    assert obj["map"]["value"] == 0.0 and obj["collisions"] == []
    assert (
        obj["verdict"]["failed_check"] == "no_ik" and "IK failed from 81 starts" in obj["verdict"]["summary"]
    )
    # the residual is that of the joints reported, measured by pinocchio
    reached = _tcp_by_pinocchio(tiago, ik["joints"], np.eye(4))
    assert np.linalg.norm(reached[:3, 3] - [2.5, 0.0, 0.8]) == pytest.approx(ik["position_error"], abs=1e-4)


def test_ik_attempt_answers_as_solve_and_its_residual_is_pinocchio_s(tiago):
    arm = tiago.arm()
    ik = DampedLeastSquaresIK(arm)
    reachable = _tcp_by_pinocchio(tiago, dict(zip(arm.joint_names, arm.sample(np.random.default_rng(1), 1)[0],
                                                  strict=True)), np.eye(4))  # fmt: skip
    far = pose_from_xyz_rpy([1.8, 0.2, 0.5, 0.3, 0.2, 0.1])
    for T in (reachable, far):
        solved = ik.solve(T, np.random.default_rng(4))
        attempt = ik.attempt(T, np.random.default_rng(4))
        assert attempt.solved == (solved is not None)
        if solved is not None:
            assert np.array_equal(attempt.q, solved)
        reached = _tcp_by_pinocchio(tiago, dict(zip(arm.joint_names, attempt.q, strict=True)), np.eye(4))
        assert np.linalg.norm(reached[:3, 3] - T[:3, 3]) == pytest.approx(attempt.position_error, abs=1e-9)
        assert arm.within_limits(attempt.q)
    assert attempt.position_error > 0.5  # the far pose


@pytest.mark.parametrize(
    ("args", "fragment"),
    [(["--target", "1 0 1 0 0 0"], "--base"), (["--base", "0 0 0"], "--target"),
     (["--base", "0 0", "--target", "1 0 1 0 0 0"], "base pose"),
     (["--base", "0 0 0", "--target", "1 0 1 0 0 0", "--floor", "0"], "--cloud")],
)  # fmt: skip
def test_bad_input_exits_2_with_one_line(args, fragment, tmp_path, tiago_map):
    map_file = tmp_path / "tiago.rmap"
    save_map(tiago_map, map_file)
    proc = run_cli("explain", "--map", str(map_file), *args)
    assert proc.returncode == 2 and proc.stdout == ""
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and fragment in lines[0], proc.stderr
