from __future__ import annotations

import json
import subprocess
from pathlib import Path

import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace_experiments.results import RunClock, SeedSplit, write_results
from baseplace_experiments.segmentation_eval import noisy_height_map
from conftest import run_cli


def test_results_file_holds_command_commit_seeds_and_time(tmp_path):
    path = tmp_path / "r.json"
    split = SeedSplit(dev=(0,), held_out=(1, 2))
    written = write_results(path, {"rows": [1, 2]}, RunClock(), seeds=split, split="dev", used_seeds=[1, 2],
                            protocol="fixed first", argv=["/some/where/baseplace", "experiment", "x"])  # fmt: skip
    stored = json.loads(path.read_text())
    assert stored == written and stored["rows"] == [1, 2]
    prov = stored["provenance"]
    assert prov["command"] == "baseplace experiment x"
    assert prov["seeds"] == {"dev": [0], "held_out": [1, 2]} and prov["seeds_used"] == [1, 2]
    assert prov["split"] == "dev" and prov["protocol"] == ["fixed first"] and prov["wall_time_s"] >= 0
    head = subprocess.run(
        ["git", "rev-parse", "HEAD"], cwd=Path(__file__).parent, capture_output=True, text=True
    )
    if head.returncode == 0:
        assert prov["commit"] == head.stdout.strip()
    assert [p.name for p in tmp_path.iterdir()] == ["r.json"]  # no temporary file left behind


def test_results_file_records_file_names_not_this_machines_folders(tmp_path):
    argv = [
        "bench/bench_x.py",
        "--map",
        "/tmp/x/tiago.rmap",
        "--out=/home/u/o.json",
        "--n",
        "3",
        "rel/a.rmap",
    ]
    written = write_results(tmp_path / "r.json", {}, RunClock(), argv=argv)
    assert written["provenance"]["command"] == "bench_x.py --map tiago.rmap --out=o.json --n 3 rel/a.rmap"


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


def test_experiment_command_writes_its_results_file(tmp_path):
    path = tmp_path / "seg.json"
    proc = run_cli("experiment", "segmentation", "--scenes", "1", "--noise", "heightmap", "--seed", "5",
                   "--results", str(path), "--json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    stored = json.loads(path.read_text())
    assert stored == json.loads(proc.stdout)  # the file is what the command printed, whole
    prov = stored["provenance"]
    assert prov["command"].endswith(
        f"experiment segmentation --scenes 1 --noise heightmap --seed 5 --results {path.name} --json"
    )
    assert prov["split"] is None and prov["seeds_used"] == [5]  # a custom seed is neither dev nor held-out
    assert prov["seeds"] == {"dev": [0], "held_out": [1]} and "height map" in prov["protocol"][0]
    assert list(stored["noise_models"]) == ["heightmap"] and stored["noise_models"]["heightmap"]["seed"] == 5


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (("segmentation", "--noise", "points"), "valid: heightmap, cloud"),
        (("segmentation", "--results", "no/such/dir/x.json"), "--results directory"),
        (("table-grid", "--surface-margin", "0.5"), "--surface-margin must be between 0 and 0.1 m"),
        (("table-grid", "--results", "no/such/dir/x.json"), "--results directory"),
    ],
)
def test_experiment_bad_input_is_one_line(args, fragment, tmp_path):
    proc = run_cli("experiment", *args, cwd=tmp_path)
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and fragment in lines[0], proc.stderr
    assert list(tmp_path.iterdir()) == []


def test_osrm_experiment_writes_the_same_provenance_as_every_experiment(tiago_map, tmp_path, capsys):
    """One provenance writer: the osrm experiment's results file carries the block the others do."""
    from baseplace.cli import main
    from baseplace.reachability.storage import save_map

    map_file, path = tmp_path / "tiago.rmap", tmp_path / "osrm.json"
    save_map(tiago_map, map_file)
    assert main(["experiment", "osrm", "--map", str(map_file), "--scenes", "1", "--grasps", "2", "--flat-only",
                 "--tries", "3", "--dev", "--results", str(path), "--json"]) == 0  # fmt: skip
    stored = json.loads(path.read_text())
    assert stored == json.loads(capsys.readouterr().out)
    prov = stored["provenance"]
    assert set(prov) >= {"command", "commit", "dirty", "finished_utc", "wall_time_s", "seeds", "seeds_used"}
    assert prov["split"] == "dev" and prov["seeds_used"] == [1000] and "run" not in stored
    assert prov["seeds"] == {"dev": [1000], "held_out": [2026]} and "Tables I and II" in prov["protocol"][0]
