"""One planar base pose type (issue 26): reports give their poses as :class:`BasePose`."""

from __future__ import annotations

import dataclasses
import math
import typing

import numpy as np
import pytest

from baseplace.geometry.poses import BasePose, pose_json
from baseplace.jobs import report as rep


def test_reports_hold_base_poses_of_the_one_type():
    """Reports hold BasePose under its own name (the old alias PoseRecord is gone), and the API lists it."""
    import baseplace.jobs

    assert not hasattr(baseplace.jobs, "PoseRecord") and not hasattr(rep, "PoseRecord")
    assert "PoseRecord" not in baseplace.__all__ and "BasePose" in baseplace.__all__
    for cls, name in [(rep.NavigateReport, "start"), (rep.NavigateReport, "goal"),
                      (rep.CandidatesReport, "robot_pose"), (rep.DemoReport, "start")]:  # fmt: skip
        hints = typing.get_type_hints(cls)
        assert name in {f.name for f in dataclasses.fields(cls)}
        assert typing.get_args(hints[name]) == (BasePose, type(None)), (cls.__name__, name, hints[name])


@pytest.mark.parametrize("yaw", [5.328, -0.955, 3.0, -3.2])
def test_a_base_pose_at_a_height_serialises_its_matrix(yaw):
    pose = BasePose.from_xyyaw(np.float64(1.0), -2.0, yaw, 0.3)
    obj = pose.to_json()
    np.testing.assert_allclose(obj["base_pose"], pose.matrix(), atol=1e-6)
    assert (obj["x"], obj["y"], obj["z"]) == (1.0, -2.0, 0.3) and -math.pi < obj["yaw"] <= math.pi
    assert obj == pose_json(pose.matrix()) and type(pose.x) is float
    assert rep.NavigateReport(start=pose, goal=pose).to_json()["start"] == obj
