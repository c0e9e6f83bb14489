"""A full disk: an output ends in one line (exit 2), the previous file untouched and no temporary
left; a cache on a full disk costs a warning, never the command.

The full disk is a small tmpfs (the tests run as root in CI); where mounting is not allowed, the
command runs under RLIMIT_FSIZE with SIGXFSZ ignored instead, which fails its writes with EFBIG.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import resource
import shutil
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

from conftest import DATA, run_cli

PLANAR3 = str(DATA / "planar3.toml")
TARGET = "1.0 0.5 0.75 0 1.5708 0"
# refused by the free-space check, or failed while writing: ENOSPC on the tmpfs, EFBIG under RLIMIT_FSIZE
FULL = re.compile(
    r"it needs [\d.]+ [kM]B and .* has [\d.]+ [kM]B free|No space left on device|File too large"
)


def cli(
    *args: str, env: dict[str, str] | None = None, fsize: int | None = None
) -> subprocess.CompletedProcess[str]:
    """The CLI in a fresh process (a segfault is an exit code, not a dead test run)."""

    def limit() -> None:
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)  # a write past the limit fails with EFBIG
        resource.setrlimit(resource.RLIMIT_FSIZE, (fsize, fsize))

    return subprocess.run([sys.executable, "-m", "baseplace.cli", *args], capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=600, env={**os.environ, **(env or {})},
                          preexec_fn=limit if fsize is not None else None)  # fmt: skip


class SmallDisk:
    """A tmpfs of ``size_kb`` at ``path``; without the right to mount, a folder whose writes the
    command makes under RLIMIT_FSIZE (``fill`` then sets the limit instead of filling)."""

    def __init__(self, path: Path, size_kb: int) -> None:
        self.path = path
        path.mkdir()
        try:
            mount = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size_kb}k", "tmpfs", str(path)],
                                   capture_output=True, text=True)  # fmt: skip
            self.mounted = mount.returncode == 0
        except OSError:  # no mount command
            self.mounted = False
        self.fsize: int | None = None

    def fill(self, leave_kb: int) -> None:
        """Leave about ``leave_kb`` free (or let each file grow to that much)."""
        if not self.mounted:
            self.fsize = leave_kb * 1024
            return
        st = os.statvfs(self.path)
        free = st.f_bfree * st.f_frsize
        (self.path / "filler").write_bytes(b"\0" * max(0, free - leave_kb * 1024))

    def run(self, *args: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess[str]:
        return cli(*args, env=env, fsize=self.fsize)

    @contextlib.contextmanager
    def limited(self) -> Iterator[None]:
        """Writes of this process as full as the command's (a no-op on the tmpfs)."""
        if self.fsize is None:
            yield
            return
        soft, hard = resource.getrlimit(resource.RLIMIT_FSIZE)
        handler = signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (self.fsize, hard))
        try:
            yield
        finally:
            resource.setrlimit(resource.RLIMIT_FSIZE, (soft, hard))
            signal.signal(signal.SIGXFSZ, handler)

    def temporaries(self) -> list[str]:
        return sorted(p.name for p in self.path.rglob("*") if p.name.endswith(".tmp") or ".tmp." in p.name)

    def unmount(self) -> None:
        if self.mounted:
            subprocess.run(["umount", str(self.path)], check=True)


@pytest.fixture()
def small_disk(tmp_path) -> Iterator[contextlib.AbstractContextManager[SmallDisk]]:
    disks: list[SmallDisk] = []

    @contextlib.contextmanager
    def make(size_kb: int) -> Iterator[SmallDisk]:
        disk = SmallDisk(tmp_path / f"disk{len(disks)}", size_kb)
        disks.append(disk)
        yield disk

    yield make  # type: ignore[misc]
    for disk in disks:
        disk.unmount()


def one_line_error(proc: subprocess.CompletedProcess[str], *fragments: str) -> str:
    """The single ``error:`` line of a command that exited 2, with no traceback and no crash.

    Under RLIMIT_FSIZE a cache entry fails too: its ``warning: ... not cached`` line may come first.
    """
    assert proc.returncode == 2, (proc.returncode, proc.stderr[-3000:])
    lines = [
        line for line in proc.stderr.strip().splitlines() if not re.match(r"warning: .* not cached in ", line)
    ]
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr[-3000:]
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    assert FULL.search(lines[0]), lines[0]
    return lines[0]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> dict[str, Path]:
    """A flat floor, a small TIAGo map and a kernel cache warmed by building it."""
    d = tmp_path_factory.mktemp("inputs")
    env = {"BASEPLACE_CACHE": str(d / "warm")}
    cloud = d / "flat.ply"
    assert run_cli("scene", "generate", "--planes", "0", "--no-box", "--extent", "4", "--seed", "2",
                   "--out", str(cloud)).returncode == 0  # fmt: skip
    rmap = d / "tiago.rmap"
    proc = run_cli("build-map", "--samples", "1e6", "--seed", "1", "--out", str(rmap), "--json", env=env)
    assert proc.returncode == 0, proc.stderr
    return {"cloud": cloud, "map": rmap, "warm": d / "warm"}


def test_place_png_on_a_full_disk_is_one_line_and_keeps_the_previous_file(inputs, small_disk):
    with small_disk(64) as disk:
        png = disk.path / "x.png"
        previous = bytes(range(256)) * 4
        png.write_bytes(previous)
        disk.fill(leave_kb=4)  # the plot is about 35 kB
        proc = disk.run("place", "--cloud", str(inputs["cloud"]), "--target", TARGET, "--map", str(inputs["map"]),
                        "--placements", "1", "--tries", "100", "--robustness-samples", "0", "--out", str(png),
                        "--json", env={"BASEPLACE_CACHE": str(inputs["warm"])})  # fmt: skip
        one_line_error(proc, "cannot write PNG", "x.png", "is unchanged")
        assert json.loads(proc.stdout)["exit_code"] == 2
        assert png.read_bytes() == previous
        assert disk.temporaries() == []


def test_build_map_on_a_full_disk_keeps_the_map_and_the_checkpoint(small_disk):
    from baseplace.reachability.build import BuildSettings, MapAccumulator, build_map
    from baseplace.reachability.checkpoint import save_checkpoint
    from baseplace.reachability.storage import save_map
    from baseplace.robots.model import Robot

    robot = Robot(PLANAR3)
    with small_disk(1600) as disk:
        out = disk.path / "m.rmap"
        save_map(build_map(robot, None, BuildSettings(samples=1000, seed=9)), out)  # an earlier map
        acc = MapAccumulator(robot, None, BuildSettings(samples=3_000_000, seed=1))
        acc.add_chunk(0)
        checkpoint = disk.path / "m.rmap.partial"
        save_checkpoint(checkpoint, acc, 1.0)  # a build of 3 chunks stopped after the first (1.2 MB)
        before = {p: p.read_bytes() for p in (out, checkpoint)}
        disk.fill(leave_kb=64)  # the next checkpoint holds two chunks
        proc = disk.run("build-map", "--robot", PLANAR3, "--samples", "3e6", "--seed", "1", "--checkpoint-every",
                        "1e6", "--out", str(out), "--json")  # fmt: skip
        one_line_error(proc, "cannot write checkpoint", "m.rmap.partial", "is unchanged")
        assert {p: p.read_bytes() for p in before} == before
        assert disk.temporaries() == []


def test_a_map_write_that_fails_midway_is_one_line(inputs, tmp_path):
    """Past the free-space check: HDF5 never meets the failing write (it crashed the process)."""
    out = tmp_path / "m.rmap"
    proc = cli("build-map", "--samples", "3e5", "--seed", "2", "--no-resume", "--out", str(out), "--json",
               env={"BASEPLACE_CACHE": str(inputs["warm"])}, fsize=20_000)  # fmt: skip
    one_line_error(proc, "cannot write map", "m.rmap", "File too large", "nothing was written")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_caches_on_a_full_disk_only_warn(inputs, small_disk, tmp_path):
    """The segmentation (place) and the map (surface-map) are computed; their entries are skipped."""
    kernels = inputs["warm"] / "kernels"
    size_kb = sum(p.stat().st_size for p in kernels.rglob("*") if p.is_file()) // 1024 + 128
    with small_disk(size_kb) as disk:
        cache = disk.path / "cache"
        shutil.copytree(kernels, cache / "kernels")  # compiled already: the test times the cache, not numba
        disk.fill(leave_kb=64)  # more than the surface map (10 kB), less than either cache entry
        env = {"BASEPLACE_CACHE": str(cache)}
        proc = disk.run("place", "--cloud", str(inputs["cloud"]), "--target", TARGET, "--map", str(inputs["map"]),
                        "--placements", "1", "--tries", "100", "--robustness-samples", "0", "--json", env=env)  # fmt: skip
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert json.loads(proc.stdout)["placements"]
        assert (
            proc.stderr.startswith("warning: the segmentation not cached in ")
            and "Traceback" not in proc.stderr
        )
        smap = tmp_path / "table.smap"
        proc = disk.run("surface-map", "--robot", "tiago", "--samples", "3e5", "--height", "0.7", "--resolution",
                        "0.1", "--polygon", "0,0;1.2,0;1.2,0.6;0,0.6", "--out", str(smap), "--json", env=env)  # fmt: skip
        assert proc.returncode == 0, proc.stderr[-3000:]
        assert smap.is_file() and json.loads(proc.stdout)["kind"] == "surface_map"
        assert "warning: the map not cached in " in proc.stderr and "Traceback" not in proc.stderr
        assert not list((cache / "maps").glob("*.rmap")) and disk.temporaries() == []


def test_writers_turn_a_full_disk_into_one_output_error(small_disk):
    """In process: the MCAP result, a figure and plain bytes, each refused with the previous file kept."""
    import matplotlib.pyplot as plt

    from baseplace.files import OutputError, write_bytes
    from baseplace.io.results import ResultMessages, write_result_mcap
    from baseplace.viz.figures import save_figure

    with small_disk(64) as disk:
        for name in ("r.mcap", "f.png", "b.bin"):
            (disk.path / name).write_bytes(b"old")
        disk.fill(leave_kb=0)
        many = [np.eye(4)] * 4000
        fig, ax = plt.subplots(figsize=(8, 8), dpi=100)
        ax.imshow(np.random.default_rng(0).random((400, 400)))
        with disk.limited():
            with pytest.raises(OutputError, match=r"r\.mcap: (No space left on device|File too large)"):
                write_result_mcap(
                    disk.path / "r.mcap", ResultMessages("map", 0, placements=many, candidates=many)
                )
            with pytest.raises(OutputError, match=r"f\.png: (No space left on device|File too large)"):
                save_figure(fig, disk.path / "f.png")
            with pytest.raises(
                OutputError, match=r"b\.bin: (it needs 100\.0 kB and .* has 0\.0 kB free|File too)"
            ):
                write_bytes(disk.path / "b.bin", b"x" * 100_000)
        assert all((disk.path / name).read_bytes() == b"old" for name in ("r.mcap", "f.png", "b.bin"))
        assert disk.temporaries() == []


def test_a_report_redirected_to_a_full_disk_is_one_line(small_disk):
    """``baseplace ... --json > FILE`` with FILE on a full disk: one line, not a traceback at exit."""
    with small_disk(64) as disk:
        disk.fill(leave_kb=0)
        with open(disk.path / "r.json", "w") as stdout:

            def limit() -> None:
                if disk.fsize is not None:
                    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
                    resource.setrlimit(resource.RLIMIT_FSIZE, (disk.fsize, disk.fsize))

            proc = subprocess.run([sys.executable, "-m", "baseplace.cli", "robots", "--json"], stdout=stdout,
                                  stderr=subprocess.PIPE, text=True, timeout=120, preexec_fn=limit)  # fmt: skip
        one_line_error(proc, "cannot write the report to stdout")
