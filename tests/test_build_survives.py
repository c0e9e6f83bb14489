"""Builds that survive (issue 15): saves before the checkpoint goes, time-based checkpoints,
stray temporaries removed, one build at a time per output.

The oracle is an uninterrupted in-process build with the same settings (chunk k is drawn from
``default_rng([seed, k])``, so any correct resume gives identical arrays) and the files on disk.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from baseplace.files import atomic_write, output_lock
from baseplace.reachability.build import CHUNK, BuildSettings, build_map
from baseplace.reachability.checkpoint import default_checkpoint_path
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.reachability.storage import load_map
from test_scaleout import assert_same_map

DATA = Path(__file__).parent / "data"
PLANAR3 = str(DATA / "planar3.toml")
SETTINGS = BuildSettings(samples=3 * CHUNK + 777, seed=5)
SRC = str(Path(__file__).resolve().parents[1] / "src")


@pytest.fixture(scope="module")
def reference(planar3) -> ReachabilityMap:
    return build_map(planar3, None, SETTINGS)


def test_kill_during_the_save_keeps_the_checkpoint(planar3, reference, tmp_path, monkeypatch):
    import baseplace.reachability.storage as storage

    out = tmp_path / "m.rmap"
    ckpt = default_checkpoint_path(out)
    real_save = storage.save_map

    def interrupted_save(rmap: ReachabilityMap, path: Path) -> int:
        with atomic_write(path, "map") as tmp:
            tmp.write_bytes(b"half a map")
            raise KeyboardInterrupt  # Ctrl-C (or a kill) in the middle of the save

    monkeypatch.setattr(storage, "save_map", interrupted_save)
    with pytest.raises(KeyboardInterrupt):
        build_map(planar3, None, SETTINGS, checkpoint=ckpt, checkpoint_every=CHUNK, save_to=out)
    assert ckpt.is_file() and not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == [ckpt.name]  # no temporary, no lock
    monkeypatch.setattr(storage, "save_map", real_save)
    (tmp_path / f".{out.name}.deadbeef.tmp").write_bytes(b"left by a SIGKILLed save")
    rmap = build_map(planar3, None, SETTINGS, checkpoint=ckpt, save_to=out)
    assert_same_map(rmap, reference)
    assert_same_map(load_map(out), reference)
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]  # stray and checkpoint removed


def test_checkpoints_are_written_by_time(planar3, reference, tmp_path):
    ckpt = tmp_path / "m.rmap.partial"
    seen: list[bool] = []

    def slow(done: int) -> None:
        seen.append(ckpt.exists())
        time.sleep(0.3)

    # the sample interval alone would never checkpoint; 0.2 s of build time does
    rmap = build_map(
        planar3, None, SETTINGS, slow, checkpoint=ckpt, checkpoint_every=10**9, checkpoint_every_s=0.2
    )
    assert any(seen) and not ckpt.exists()
    assert_same_map(rmap, reference)


def test_output_lock_serialises_and_leaves_no_file(tmp_path):
    out = tmp_path / "x.rmap"
    child = (
        "import sys, time\n"
        "from baseplace.files import output_lock\n"
        "with output_lock(sys.argv[1]):\n"
        "    print('locked', flush=True)\n"
        "    time.sleep(1.5)\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", child, str(out)], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "PYTHONPATH": SRC})  # fmt: skip
    assert proc.stdout is not None and proc.stdout.readline().strip() == "locked"
    waited: list[bool] = []
    t0 = time.monotonic()
    with output_lock(out, lambda: waited.append(True)):
        held_after = time.monotonic() - t0
    proc.wait(timeout=30)
    assert waited == [True] and held_after > 0.5
    assert list(tmp_path.iterdir()) == []


def test_two_concurrent_builds_to_one_output_both_succeed(planar3, tmp_path):
    settings = BuildSettings(samples=6 * CHUNK, seed=11)
    out = tmp_path / "same.rmap"
    args = [sys.executable, "-m", "baseplace.cli", "build-map", "--robot", PLANAR3, "--samples", str(settings.samples),
            "--seed", str(settings.seed), "--out", str(out), "--json"]  # fmt: skip
    env = {**os.environ, "PYTHONPATH": SRC}
    procs = [
        subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
        for _ in range(2)
    ]
    results = [p.communicate(timeout=600) for p in procs]
    for p, (_, err) in zip(procs, results, strict=True):
        assert p.returncode == 0, err[-2000:]
    assert_same_map(load_map(out), build_map(planar3, None, settings))
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]
