"""The jobs layer used as a library, without the CLI (issue 16: "the jobs layer's tests run without the CLI").

Each job is called with typed inputs (in-memory clouds, files) and checked against the scene's
generator truth or an independent reader; failures are exceptions, never exits.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from PIL import Image

import baseplace
from baseplace.errors import InputError
from conftest import SHARED

SANDBOX = SHARED / "maps" / "tb3_sandbox.yaml"


@pytest.fixture(scope="module")
def ramp_points() -> np.ndarray:
    from test_navigation import _ramp_scene

    return _ramp_scene(with_object=True).sample_cloud(np.random.default_rng(0))


def _valid(report: baseplace.Report) -> dict:
    obj = report.to_json()
    jsonschema.validate(obj, baseplace.result_schema())
    return obj


def test_navigate_job_on_loaded_points_wraps_the_goal_heading(ramp_points):
    """Goal heading 5.328 and -0.955 (2 pi apart but for 2e-4 rad): the same region path, up the ramp."""
    from test_navigation import _ramp_scene

    truth = _ramp_scene(with_object=True)
    out = {}
    for heading in (5.328, -0.955):
        job = baseplace.NavigateJob((-2.0, 0.6, 0.0), (1.7, 0.6, heading), baseplace.CloudInput(points=ramp_points),
                                    planner="regions")  # fmt: skip
        out[heading] = _valid(baseplace.navigate_job(job))
    a, b = out[5.328], out[-0.955]
    assert a["goal"]["yaw"] == pytest.approx(5.328 - 2 * math.pi, abs=1e-4)
    assert a["regions"] == b["regions"] and len(a["poses"]) == len(b["poses"])
    np.testing.assert_allclose(np.array(a["poses"])[:, :2], np.array(b["poses"])[:, :2], atol=1e-9)
    poses = np.array(a["poses"])
    assert poses[0, :2] == pytest.approx([-2.0, 0.6]) and poses[-1, :2] == pytest.approx([1.7, 0.6])
    # the goal stands on the ramp: the generator's height there is well above the floor
    assert float(truth.height(np.array([[1.7, 0.6]]))[0]) > 0.3 and len(a["regions"]) >= 2


def test_a_job_raises_instead_of_exiting(ramp_points):
    job = baseplace.NavigateJob(
        "-2 0.6 0", "9 9 0", baseplace.CloudInput(points=ramp_points), planner="regions"
    )
    with pytest.raises(InputError, match="goal"):
        baseplace.navigate_job(job)
    with pytest.raises(InputError, match="planner"):
        baseplace.navigate_job(baseplace.NavigateJob("0 0 0", "1 0 0", planner="astar"))


def test_scene_and_occupancy_jobs_against_their_files(tmp_path):
    cloud = tmp_path / "flat.npy"
    obj = _valid(baseplace.scene_job(baseplace.SceneJob(str(cloud), planes=0, box=False, extent=4.0, sigma=0.01,
                                                        seed=3)))  # fmt: skip
    points = np.load(cloud)
    assert obj["points"] == len(points) and obj["outputs"]["cloud"] == str(cloud)
    assert np.abs(points[:, 2]).max() < 0.06 and np.ptp(points[:, 0]) == pytest.approx(
        4.0, abs=0.1
    )  # a flat 4 m floor
    from baseplace.jobs.inputs import world_cloud

    # a cloud file given without a transform (the CLI always passes one, maybe None) is z up, as loaded
    np.testing.assert_array_equal(np.asarray(world_cloud(baseplace.CloudInput([str(cloud)]))), points)
    with pytest.raises(InputError, match="one --transform per --cloud"):
        world_cloud(baseplace.CloudInput([str(cloud)], ["0 0 1", "0 0 1"]))
    truth = json.loads(Path(obj["outputs"]["truth"]).read_text())
    assert truth and Path(obj["outputs"]["truth"]).parent == tmp_path
    grid = _valid(baseplace.occupancy_job(str(SANDBOX)))
    image = Image.open(SANDBOX.with_suffix(".pgm"))  # oracle: the image itself
    assert (grid["width"], grid["height"]) == image.size


def test_the_jobs_import_no_front_end(tmp_path):
    """Running jobs loads neither the CLI nor argparse's command table (a separate interpreter)."""
    code = f"""
import sys, baseplace
baseplace.scene_job(baseplace.SceneJob({str(tmp_path / "s.npy")!r}, planes=0, box=False, extent=3.0))
baseplace.occupancy_job({str(SANDBOX)!r})
print(sorted(m for m in sys.modules if m in ("baseplace.cli", "baseplace_experiments", "baseplace.viz.viewer")))
"""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, timeout=300
    )
    assert out.stdout.strip() == "[]"
