from __future__ import annotations

import contextlib
import io
import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

from baseplace.reachability.build import BuildSettings, build_map
from baseplace.robots.model import Robot

# CI draws the same examples every run, so a failure there can be rerun as it was; a developer's
# run draws new ones each time and so keeps finding edge cases
settings.register_profile("ci", derandomize=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

DATA = Path(__file__).parent / "data"
SHARED = Path(__file__).resolve().parents[2] / "shared" / "data"


PRECOMPILE_TIMEOUT_S = 600
"""The precompile step's limit [s]: about 75 s on this project's 2-core machine with an empty cache."""


def pytest_configure(config: pytest.Config) -> None:
    """With xdist workers: compile the kernels that they all use once, before they start.

    Two processes side by side (tests/precompile.py), in the controller only; the workers load the
    kernels from numba's cache. A part that fails, or runs past :data:`PRECOMPILE_TIMEOUT_S`, is
    reported and left to the tests that use it. Nothing is compiled when only collecting.
    """
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    if config.option.collectonly:
        return
    script = Path(__file__).with_name("precompile.py")
    parts = {
        part: subprocess.Popen([sys.executable, str(script), *part.split()]) for part in ("motion", "ik maps")
    }
    deadline = time.monotonic() + PRECOMPILE_TIMEOUT_S
    for part, proc in parts.items():
        try:
            why = f"exit {proc.wait(timeout=max(deadline - time.monotonic(), 0.0))}"
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
            why = f"still running after {PRECOMPILE_TIMEOUT_S} s, killed"
        if proc.returncode != 0:
            print(f"tests/precompile.py {part} failed ({why}); the workers compile it", file=sys.stderr)


@pytest.fixture(scope="session")
def tiago() -> Robot:
    return Robot("tiago")


@pytest.fixture(scope="session")
def pr2() -> Robot:
    return Robot("pr2")


@pytest.fixture(scope="session")
def planar3() -> Robot:
    return Robot(DATA / "planar3.toml")


@pytest.fixture(scope="session")
def tiago_map(tiago: Robot):
    """A small TIAGo map (2e6 samples): fast to build, enough for lookup tests."""
    return build_map(tiago, None, BuildSettings(samples=2_000_000, seed=3))


@pytest.fixture(scope="session")
def tiago_map_10m(tiago: Robot):
    """A TIAGo map of 1e7 samples, for placements that need a denser map (built once per session)."""
    return build_map(tiago, None, BuildSettings(samples=10_000_000, seed=1))


@pytest.fixture()
def rng() -> np.random.Generator:
    return np.random.default_rng(2024)


def tcp_by_pinocchio(robot: Robot, arm, q) -> np.ndarray:  # type: ignore[no-untyped-def]
    """Oracle: pinocchio FK of the arm's TCP (4, 4) in its base frame at arm joints q (n,), others at reference."""
    import pinocchio as pin

    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, arm.to_pinocchio(q, robot.q_reference))
    base = data.oMf[robot.model.getFrameId(arm.base_frame)]
    return (base.inverse() * data.oMf[robot.model.getFrameId(arm.tcp_frame)]).homogeneous


def free_port() -> int:
    """A TCP port on the loopback interface that nothing listens on now."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def run_cli(
    *args: str, env: dict[str, str] | None = None, cwd: Path | None = None
) -> subprocess.CompletedProcess[str]:
    """``baseplace ARGS`` in this process, as a fresh one would run it (its ``sys.argv``, ``env`` added
    to the environment, ``cwd`` its working folder); stdout and stderr captured. Saves the interpreter's
    start and the compiled kernels' loading, 2-4 s a call. Tests of what only a fresh process shows
    (imports, memory peaks, signals, file-size limits) start one."""
    from baseplace.cli import main

    out, err = io.StringIO(), io.StringIO()
    saved_env, saved_argv, saved_cwd = dict(os.environ), sys.argv, os.getcwd()
    os.environ.update(env or {})
    sys.argv = ["baseplace", *args]
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                code = main(list(args))
            except SystemExit as exc:  # argparse's errors, --help and --version exit
                code = exc.code if isinstance(exc.code, int) else 1
    finally:
        os.chdir(saved_cwd)
        sys.argv = saved_argv
        os.environ.clear()
        os.environ.update(saved_env)
    return subprocess.CompletedProcess(list(args), code, out.getvalue(), err.getvalue())
