from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.sim.results import RunClock, SeedSplit, write_results
from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace.sim.segmentation_eval import noisy_height_map


def test_results_file_holds_command_commit_seeds_and_time(tmp_path):
    path = tmp_path / "r.json"
    split = SeedSplit(dev=(0,), held_out=(1, 2))
    written = write_results(path, {"rows": [1, 2]}, RunClock(), seeds=split, split="held-out", used_seeds=[1, 2],
                            protocol="fixed first", argv=["/some/where/baseplace", "experiment", "x"])  # fmt: skip
    stored = json.loads(path.read_text())
    assert stored == written and stored["rows"] == [1, 2]
    prov = stored["provenance"]
    assert prov["command"] == "baseplace experiment x"
    assert prov["seeds"] == {"dev": [0], "held_out": [1, 2]} and prov["seeds_used"] == [1, 2]
    assert prov["split"] == "held-out" and prov["protocol"] == ["fixed first"] and prov["wall_time_s"] >= 0
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True, text=True
    )
    if head.returncode == 0:
        assert prov["commit"] == head.stdout.strip()
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]  # no temporary file left behind


def test_results_file_never_half_written(tmp_path):
    path = tmp_path / "r.json"
    with pytest.raises(TypeError):
        write_results(path, {"x": object()}, RunClock())
    assert list(tmp_path.iterdir()) == []
    stored = write_results(path, {"x": [float("nan"), 1.0], "y": {"z": float("inf")}}, RunClock())
    assert json.loads(path.read_text()) == stored and stored["x"] == [None, 1.0] and stored["y"]["z"] is None
    assert stored["provenance"]["non_finite_written_as_null"] == 2
    with pytest.raises(InputError, match="overlap"):
        SeedSplit(dev=(0, 1), held_out=(1,))
    with pytest.raises(InputError, match="valid: dev, held-out"):
        SeedSplit(dev=(0,), held_out=(1,)).seeds("test")


def test_height_map_noise_is_the_seeds_model():
    """Noise on the height map: known cells of the floor deviate from the true height by sigma."""
    rng = np.random.default_rng(3)
    scene = generate_scene(SceneSettings(size_class="small", n_planes=2), rng)
    sigma = 0.025
    hmap = noisy_height_map(scene, np.random.default_rng(4), "heightmap", sigma)
    X, Y = hmap.cell_centres()
    xy = np.c_[X.ravel(), Y.ravel()]
    floor = (scene.surface_id(xy) == 0) & hmap.known.ravel()
    # the highest 25 mm voxel centre of a flat floor at z = 0 is 12.5 mm up, exactly
    residual = hmap.raw.ravel()[floor] - scene.height(xy[floor]) - 0.0125
    # robust spread: floor cells beside a wall also hold the wall's points
    spread = 1.4826 * np.median(np.abs(residual - np.median(residual)))
    assert abs(np.median(residual)) < 0.002 and abs(spread - sigma) < 0.002
    cloud = noisy_height_map(scene, np.random.default_rng(4), "cloud", sigma)
    lifted = cloud.raw.ravel()[floor]
    # the highest of ~16 noisy points per cell: biased up and less spread than the seed's noise
    assert np.median(lifted) >= 0.0125 + sigma - 1e-9
    assert 1.4826 * np.median(np.abs(lifted - np.median(lifted))) < 0.8 * sigma
    with pytest.raises(InputError, match="valid: cloud, heightmap"):
        noisy_height_map(scene, rng, "points")
