"""Distributed faults (issue 15): every dask worker (or the scheduler) killed mid-build ends in one
line within 60 s, with a checkpoint that resumes to the map of an uninterrupted build.

A real scheduler and two workers run as separate processes (``dask scheduler``, ``dask worker
--no-nanny``, so nothing restarts a killed worker); the CLI builds against them and the workers
are SIGKILLed once the first checkpoint is on disk. The oracle is an uninterrupted in-process
build with the same settings.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from baseplace.reachability.build import CHUNK, BuildSettings, MapAccumulator, build_map
from baseplace.reachability.checkpoint import load_checkpoint
from conftest import free_port
from test_scaleout import assert_same_map

SRC = str(Path(__file__).resolve().parents[1] / "src")
DASK = str(Path(sys.executable).with_name("dask"))


@pytest.mark.slow
@pytest.mark.parametrize("victim", ["workers", "scheduler"])
def test_all_workers_killed_gives_one_line_and_a_resumable_checkpoint(victim, tiago, tmp_path):
    settings = BuildSettings(samples=16 * CHUNK, seed=4)
    env = {**os.environ, "PYTHONPATH": SRC, "BASEPLACE_CACHE": os.environ.get("BASEPLACE_CACHE", "")}
    env = {k: v for k, v in env.items() if v}
    address = f"tcp://127.0.0.1:{free_port()}"
    quiet = {"stdout": subprocess.DEVNULL, "stderr": subprocess.DEVNULL, "env": env}
    scheduler = subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", address.rsplit(":", 1)[1],
                                  "--no-dashboard"], **quiet)  # type: ignore[call-overload]  # fmt: skip
    workers: list[subprocess.Popen[bytes]] = []
    try:
        workers = [
            subprocess.Popen(
                [DASK, "worker", address, "--no-nanny", "--nthreads", "1", "--no-dashboard"], **quiet
            )  # type: ignore[call-overload]
            for _ in range(2)
        ]
        out = tmp_path / "m.rmap"
        ckpt = tmp_path / "m.rmap.partial"
        build = subprocess.Popen(
            [sys.executable, "-m", "baseplace.cli", "build-map", "--robot", "tiago", "--samples", str(settings.samples),
             "--seed", str(settings.seed), "--scheduler", address, "--checkpoint-every", str(CHUNK), "--out", str(out),
             "--json"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
        )  # fmt: skip
        deadline = time.monotonic() + 240
        while not ckpt.exists():
            if build.poll() is not None or time.monotonic() > deadline:
                build.kill()
                pytest.fail(f"no checkpoint before the build ended: {build.communicate()[1][-2000:]}")
            time.sleep(0.05)
        for p in workers if victim == "workers" else [scheduler]:
            p.send_signal(signal.SIGKILL)
        killed = time.monotonic()
        _, stderr = build.communicate(timeout=120)
        elapsed = time.monotonic() - killed
    finally:
        for p in (*workers, scheduler):
            if p.poll() is None:
                p.kill()
            p.wait(timeout=30)
    assert elapsed < 60, elapsed
    if build.returncode == 0:  # the workers had finished every task before the kill landed
        pytest.skip("the build finished before the workers were killed")
    assert build.returncode == 2, stderr[-3000:]
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), stderr[-3000:]
    assert ("worker" if victim == "workers" else "scheduler") in lines[0]
    assert str(ckpt) in lines[0] and "resume" in lines[0]
    assert not out.exists()
    acc = MapAccumulator(tiago, None, settings)
    load_checkpoint(ckpt, acc)
    assert 0 < acc.done.sum() < acc.n_chunks
    resumed = build_map(tiago, None, settings, checkpoint=ckpt)
    assert_same_map(resumed, build_map(tiago, None, settings))
