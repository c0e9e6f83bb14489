"""``baseplace --version`` and the progress bar of a command's first, map-building run."""

from __future__ import annotations

import io
import re
import subprocess
import sys
from pathlib import Path

from baseplace.cli import main
from conftest import SHARED

ROOT = Path(__file__).resolve().parents[1]


class _Terminal(io.StringIO):
    """A stream that says it is a terminal, as a user's stderr is."""

    def isatty(self) -> bool:
        return True


def test_version_prints_the_project_version():
    proc = subprocess.run([sys.executable, "-m", "baseplace.cli", "--version"], capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=60)  # fmt: skip
    match = re.search(r'^version = "([^"]+)"', (ROOT / "pyproject.toml").read_text(), re.MULTILINE)
    assert match is not None
    version = match.group(1)
    assert proc.returncode == 0 and proc.stdout.strip() == f"baseplace {version}"


def test_first_candidates_run_shows_a_progress_bar_while_it_builds_the_map(monkeypatch, tmp_path, capsys):
    """The first ``candidates`` builds the default map (40 s at 5e7 samples): no longer silent."""
    import baseplace.reachability.build as build

    monkeypatch.setenv("BASEPLACE_CACHE", str(tmp_path / "cache"))
    import baseplace.reachability.cache as cache

    full = build.BuildSettings
    for module in (build, cache):  # a small "default" map
        monkeypatch.setattr(module, "BuildSettings", lambda: full(samples=300_000))
    args = ["candidates", "--occupancy", str(SHARED / "maps" / "tb3_sandbox.yaml"), "--object",
            "-1.025 -0.775 0.6"]  # fmt: skip
    terminal = _Terminal()
    monkeypatch.setattr(sys, "stderr", terminal)  # bars show on a terminal only
    code = main(args)
    assert code in (0, 3), terminal.getvalue()
    assert "reachability map, tiago arm" in terminal.getvalue() and "samples" in terminal.getvalue()
    assert list((tmp_path / "cache" / "maps").glob("map-*.rmap"))  # built and cached
    for run in (args, [*args, "--json"]):  # second run: the cached map, no bar; --json: nothing but the JSON
        terminal.seek(0)
        terminal.truncate()
        code = main(run)
        assert code in (0, 3) and "reachability map" not in terminal.getvalue()
    capsys.readouterr()


def test_help_lists_the_robot_command_and_version(capsys):
    import pytest

    with pytest.raises(SystemExit) as done:
        main(["--help"])
    assert done.value.code == 0
    lines = capsys.readouterr().out.splitlines()
    assert any(line.split()[:1] == ["robot"] and "check a robot file" in line for line in lines)
    assert any("--version" in line for line in lines)


def _stderr_on_a_terminal(*args: str) -> tuple[int, str, str]:
    """Run the CLI with stderr on a pseudo-terminal (100 columns); (exit code, stdout, stderr)."""
    import fcntl
    import os
    import pty
    import select
    import struct
    import termios

    master, slave = pty.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    proc = subprocess.Popen([sys.executable, "-m", "baseplace.cli", *args], stdout=subprocess.PIPE,
                            stderr=slave, stdin=subprocess.DEVNULL)  # fmt: skip
    os.close(slave)
    chunks = []
    while True:
        ready, _, _ = select.select([master], [], [], 0.2)
        if ready:
            try:
                data = os.read(master, 4096)
            except OSError:  # the child closed the terminal
                break
            if not data:
                break
            chunks.append(data)
        elif proc.poll() is not None:
            break
    os.close(master)
    assert proc.stdout is not None
    return proc.wait(timeout=60), proc.stdout.read().decode(), b"".join(chunks).decode(errors="replace")


def test_a_step_past_two_seconds_shows_a_status_line_on_a_terminal(tmp_path):
    import numpy as np

    from test_navigation import _ramp_scene

    cloud = tmp_path / "ramp.npy"
    np.save(cloud, _ramp_scene(with_object=True).sample_cloud(np.random.default_rng(0)))
    # the planner runs to its 3 s time limit and finds nothing: no progress bar of its own
    args = (
        "navigate",
        "--cloud",
        str(cloud),
        "--start",
        "-2 -1.9 0",
        "--goal",
        "0.5 -1.9 0",
        "--time-limit",
        "3",
    )
    code, _, err = _stderr_on_a_terminal(*args)
    assert code == 3 and "baseplace navigate: working, 00:0" in err and "error: no path" in err
    code, _, err = _stderr_on_a_terminal(*args, "--json")
    assert code == 3 and "working" not in err


def test_one_progress_bar_type_counts_loops_in_their_own_unit():
    """The experiments' loops use the jobs' ProgressBars (one type): ``count(k)`` adds k done."""

    from baseplace.status import ProgressBars

    out = _Terminal()
    with ProgressBars(stream=out) as bars:
        count = bars.counter("osrm experiment", 10, "scenes")
        count(3)
        count(4)
        bar = bars.bars["osrm experiment"]
        assert (bar.n, bar.total, bar.unit) == (7, 10, "scenes")
    assert bars.bars == {} and "osrm experiment" in out.getvalue() and "0.00/10.0" not in out.getvalue()
    with ProgressBars(enabled=False) as quiet:  # --json: nothing shown
        quiet.counter("x", 5)(5)
    assert quiet.bars == {}
    with ProgressBars(stream=io.StringIO()) as redirected:  # not a terminal (a log, a pipe): nothing shown
        redirected.counter("x", 5)(5)
    assert redirected.bars == {}
