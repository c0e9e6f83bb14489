"""The result contract: reports serialize to the JSON Schema, poses in one shape, headings wrapped."""

from __future__ import annotations

import math

import jsonschema
import numpy as np
import pytest

from baseplace.geometry.poses import BasePose, wrap_angle
from baseplace.jobs import report as rep
from baseplace.jobs import result_schema

REPORTS = [
    rep.PlaceReport, rep.CandidatesReport, rep.SurfaceMapReport, rep.SurfaceSamplesReport, rep.NavigateReport,
    rep.ReachReport, rep.SegmentReport, rep.DemoReport, rep.BuildMapReport, rep.RobotsReport,
    rep.RobotCheckReport, rep.OccupancyReport, rep.SceneReport,
]  # fmt: skip


@pytest.mark.parametrize(
    "angle", [0.0, 1.0, -1.0, math.pi, -math.pi, 5.328, -0.955, 7 * math.pi, -9.5, 100.0]
)
def test_wrap_angle_is_in_half_open_interval_and_same_direction(angle: float) -> None:
    wrapped = wrap_angle(angle)
    assert -math.pi < wrapped <= math.pi
    assert math.cos(wrapped) == pytest.approx(math.cos(angle), abs=1e-9)
    assert math.sin(wrapped) == pytest.approx(math.sin(angle), abs=1e-9)


def test_pose_record_matches_rotation_oracle() -> None:
    from scipy.spatial.transform import Rotation

    for yaw in [5.328, -0.955, 3.0, -3.2]:
        record = BasePose.from_xyyaw(1.0, -2.0, yaw, 0.3).to_json()
        R = Rotation.from_euler("z", yaw).as_matrix()
        np.testing.assert_allclose(np.asarray(record["base_pose"])[:3, :3], R, atol=1e-6)
        assert (
            record["yaw"] == pytest.approx(wrap_angle(yaw), abs=1e-4) and -math.pi < record["yaw"] <= math.pi
        )
        assert (record["x"], record["y"], record["z"]) == (1.0, -2.0, 0.3)
    assert BasePose.from_xyyaw(0, 0, 5.328).to_json()["yaw"] == pytest.approx(5.328 - 2 * math.pi, abs=1e-4)


@pytest.mark.parametrize("cls", REPORTS)
def test_every_kind_has_a_failure_shape_the_schema_accepts(cls: type[rep.Report]) -> None:
    obj = cls(inputs={"seed": 0}, failures={"ik": 3}).failed("no placement", 3).to_json()
    assert obj["schema"] == rep.SCHEMA_VERSION and obj["kind"] == cls.kind and obj["kind"] in rep.KINDS
    jsonschema.validate(obj, result_schema())


def test_schema_rejects_what_breaks_the_contract() -> None:
    good = rep.NavigateReport(
        start=BasePose.from_xyyaw(0, 0, 5.328),
        goal=BasePose.from_xyyaw(1, 0, 0),
        poses=[[0, 0, 0], [1, 0, 0]],
    ).to_json()
    jsonschema.validate(good, result_schema())
    for broken in [
        {**good, "poses": [[0, 0, 5.328]]},  # a heading outside (-pi, pi]
        {**good, "schema": "baseplace.result/0"},
        {**good, "exit_code": 3},  # success with a failing exit code
        {k: v for k, v in good.items() if k != "inputs"},
        {**good, "robot": "tiago"},  # the robot is an object
        {**good, "kind": "plan"},
    ]:
        with pytest.raises(jsonschema.ValidationError):
            jsonschema.validate(broken, result_schema())
    empty = rep.PlaceReport().to_json()  # success must carry a placement
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(empty, result_schema())


def test_timings_always_have_a_total() -> None:
    obj = rep.ReachReport(timings_ms={"load": 1.5, "query": 2.0}, values=[0.5]).to_json()
    assert obj["timings_ms"]["total"] == 3.5
    obj = rep.ReachReport(timings_ms={"query": 2.0, "total": 10.0}, values=[0.5]).to_json()
    assert obj["timings_ms"]["total"] == 10.0
