"""Protocol v3 of Tables I/II: the method's collision model from the clean cloud, its wiring and refusals."""

from __future__ import annotations

import subprocess

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace_experiments import osrm_experiment, osrm_v2, osrm_v3
from baseplace_experiments.osrm_experiment import ExperimentSettings, experiment_scene
from conftest import run_cli


def test_the_clean_collision_cloud_is_the_noise_free_sample_and_the_segmentation_stays_the_noisy_clouds():
    rng_noisy, scene, noisy, terrain_noisy = experiment_scene(ExperimentSettings(seed=3), 0, 0)
    rng_clean, _, clean, terrain_clean = experiment_scene(
        ExperimentSettings(seed=3, collision_cloud="clean"), 0, 0
    )
    off_noisy = np.abs(noisy[:, 2] - scene.height(noisy[:, :2]))
    off_clean = np.abs(clean[:, 2] - scene.height(clean[:, :2]))
    assert np.median(off_clean) < 1e-9 < 0.005 < np.median(off_noisy)  # no z-noise on the method's cloud
    # the segmentation (noisy cloud), the collision voxels (clean cloud) and the grasp draws are v2's
    assert np.array_equal(terrain_noisy.segmentation.labels, terrain_clean.segmentation.labels)
    assert np.array_equal(terrain_noisy.voxels.keys, terrain_clean.voxels.keys)
    assert rng_noisy.random() == rng_clean.random()
    with pytest.raises(InputError, match="collision_cloud must be one of"):
        experiment_scene(ExperimentSettings(seed=3, collision_cloud="true"), 0, 0)


def test_protocol_v3_runs_v2_on_the_clean_cloud_with_fresh_held_out_seeds(tiago, monkeypatch):
    seen: list[ExperimentSettings] = []

    class Seen(Exception):
        pass

    def first_scene(robot, rmap, c, k, s, classes, oracle):
        seen.append(s)
        raise Seen

    monkeypatch.setattr(osrm_v2, "osrm_scene", first_scene)
    rmap = type("Map", (), {"info": type("Info", (), {"arm": None})()})()
    with pytest.raises(Seen):
        osrm_v3.run_osrm_v3(tiago, rmap, osrm_v3.SEEDS.dev, 1, 2, 5)
    assert [(s.collision_cloud, s.seed, s.grasps_per_scene, s.tries) for s in seen] == [("clean", 1000, 2, 5)]
    used = {
        *osrm_v2.SEEDS.dev,
        *osrm_v2.SEEDS.held_out,
        *osrm_experiment.SEEDS.dev,
        *osrm_experiment.SEEDS.held_out,
    }
    assert not set(osrm_v3.SEEDS.held_out) & used


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return run_cli("experiment", "osrm", "--protocol", "3", *args)


def test_a_held_out_v3_run_with_other_counts_mixed_seeds_or_a_v1_file_beside_is_refused_before_any_work(
    tmp_path,
):
    r = _cli("--split", "held-out", "--grasps", "5")
    assert r.returncode == 2 and "held-out protocol-v3 run uses --scenes 7 --grasps 3 --tries 100" in r.stderr
    r = _cli("--seeds", "1000,4201")
    assert r.returncode == 2 and "held-out seeds [4201, 4202, 4203] run only all together" in r.stderr
    v1 = tmp_path / "v1.json"
    v1.write_text('{"rows": [], "seed": 2026}')
    r = _cli("--split", "dev", "--beside", str(v1))
    assert r.returncode == 2 and "takes a protocol-2 results file" in r.stderr


def test_a_held_out_v3_run_is_refused_while_its_protocol_file_is_not_committed(monkeypatch, capsys):
    from baseplace.cli import main

    monkeypatch.setattr(osrm_v3, "PROTOCOL_FILE", "docs/protocols/osrm_v3_never_committed.md")
    assert main(["experiment", "osrm", "--protocol", "3", "--split", "held-out"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].endswith("osrm_v3_never_committed.md is not in a git work tree or not committed: commit it "
                            "before a held-out run, or run the dev split")  # fmt: skip


def test_v2s_rows_go_beside_by_class_and_strategy():
    v2 = {"protocol": 2, "seeds": [4101, 4102, 4103],
          "rows": [{"scene": "flat", "strategy": "MR", "allowed_grasps": 57, "success_allowed_N100": 59.6,
                    "ci95_allowed_N100": [44.8, 74.1]}]}  # fmt: skip
    result = {"rows": [{"scene": "flat", "strategy": "MR"}, {"scene": "flat", "strategy": "TO"}]}
    rows = osrm_v3.with_v2(result, v2)["rows"]
    assert rows[0]["v2"]["success_allowed_N100"] == 59.6 and rows[0]["v2"]["ci95_allowed_N100"] == [
        44.8,
        74.1,
    ]
    assert rows[0]["v2"]["allowed_grasps"] == 57 and rows[0]["v2"]["seeds"] == [4101, 4102, 4103]
    assert rows[1]["v2"] is None
    with pytest.raises(InputError, match="takes a protocol-2 results file"):
        osrm_v3.with_v2(result, {**v2, "protocol": 3})
