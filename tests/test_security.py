"""Hostile files and paths (issue 15): no code from data, caches that names cannot steer.

Each test plays the attacker: the oracle is an observable side effect (a marker file the injected
code would create, a file outside the cache, the bytes on disk), never the code's own report.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from baseplace.errors import InputError
from conftest import run_cli as cli

DATA = Path(__file__).parent / "data"
SRC = str(Path(__file__).resolve().parents[1] / "src")


def _env(**extra: str) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": SRC, **extra}


def one_line(proc: subprocess.CompletedProcess[str], code: int = 2) -> str:
    assert proc.returncode == code, proc.stderr[-2000:]
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr[-2000:]
    return lines[0]


def _robot_dir(tmp_path: Path, name: str, arm: str = "arm") -> Path:
    shutil.copy(DATA / "planar3.urdf", tmp_path / "planar3.urdf")
    text = (DATA / "planar3.toml").read_text()
    text = text.replace('name = "planar3"', f"name = {name}").replace("[arms.arm]", f"[arms.{arm}]")
    (tmp_path / "robot.toml").write_text(text)
    return tmp_path / "robot.toml"


INJECT = """import os; open(os.environ["MARKER"], "w").write("pwned")"""


@pytest.mark.parametrize("where", ["name", "arm"])
@pytest.mark.parametrize("command", ["build-map", "surface-map"])
def test_injection_robot_file_is_refused_and_runs_nothing(tmp_path, where, command):
    # The name closes the generated module's docstring and appends code (the attack).
    payload = '"""\\n' + INJECT + '\\n"""'
    toml_string = '"' + payload.replace('"', '\\"') + '"'
    robot = (
        _robot_dir(tmp_path, toml_string)
        if where == "name"
        else _robot_dir(tmp_path, '"planar3"', toml_string)
    )
    marker = tmp_path / "marker"
    env = _env(MARKER=str(marker), BASEPLACE_CACHE=str(tmp_path / "cache"))
    if command == "build-map":
        args = ["build-map", "--robot", str(robot), "--samples", "1e5", "--out", str(tmp_path / "m.rmap")]
    else:
        args = [
            "surface-map",
            "--robot",
            str(robot),
            "--polygon",
            "0,0;1,0;1,1",
            "--height",
            "0.7",
            "--out",
            str(tmp_path / "s.smap"),
        ]
    proc = cli(*args, env=env)
    line = one_line(proc)
    assert "not a valid name" in line
    assert not marker.exists()
    assert not (tmp_path / "m.rmap").exists() and not (tmp_path / "s.smap").exists()
    kernels = tmp_path / "cache" / "kernels"
    assert not kernels.exists() or not any("pwned" in p.read_text() for p in kernels.glob("*.py"))


@pytest.mark.parametrize("name", ["../../escape", "a/b", "..", "x" * 65, "", "a b", "é", "a\nb", "1abc"])
def test_names_are_conservative_identifiers(tmp_path, name):
    from baseplace.robots.spec import load_spec

    robot = _robot_dir(tmp_path, '"' + name.replace("\n", "\\n") + '"')
    with pytest.raises(InputError, match="not a valid name"):
        load_spec(robot)
    robot = _robot_dir(tmp_path, '"ok"', '"' + name.replace("\n", "\\n") + '"')
    with pytest.raises(InputError, match="not a valid name"):
        load_spec(robot)


def test_map_cache_paths_are_hashes_inside_the_cache(tmp_path, monkeypatch, planar3):
    from baseplace.reachability.build import BuildSettings
    from baseplace.reachability.cache import cached_map

    monkeypatch.setenv("BASEPLACE_CACHE", str(tmp_path / "cache"))
    _, path, built = cached_map(planar3, BuildSettings(samples=200_000, voxel_size=0.1))
    assert built
    assert path.parent.resolve() == (tmp_path / "cache" / "maps").resolve()
    assert planar3.name not in path.name and "arm" not in path.name
    # every file the run wrote lies under the cache
    outside = [p for p in tmp_path.iterdir() if p.name != "cache"]
    assert outside == []


_KERNEL_SCRIPT = """
import sys
from baseplace.robots.model import Robot
from baseplace.robots.codegen import arm_kernels, cache_dir
robot = Robot(sys.argv[1])
mod = arm_kernels(robot.arm())
print(mod.__file__)
"""


def test_tampered_cached_kernel_is_regenerated_not_imported(tmp_path):
    marker = tmp_path / "marker"
    env = _env(BASEPLACE_CACHE=str(tmp_path / "cache"), MARKER=str(marker))
    first = subprocess.run([sys.executable, "-c", _KERNEL_SCRIPT, str(DATA / "planar3.toml")],
                           capture_output=True, text=True, env=env, timeout=300)  # fmt: skip
    assert first.returncode == 0, first.stderr
    kernel = Path(first.stdout.strip())
    original = kernel.read_bytes()
    assert kernel.parent == tmp_path / "cache" / "kernels"
    # an attacker (or a bad disk) edits the cached module, keeping its size to fool cheap checks
    evil = (INJECT + "\n").encode()
    kernel.write_bytes(evil + original[len(evil) :])
    second = subprocess.run([sys.executable, "-c", _KERNEL_SCRIPT, str(DATA / "planar3.toml")],
                            capture_output=True, text=True, env=env, timeout=300)  # fmt: skip
    assert second.returncode == 0, second.stderr
    assert not marker.exists()
    assert kernel.read_bytes() == original


def test_kernel_cache_of_another_user_or_open_to_others(tmp_path, monkeypatch):
    from baseplace.files import private_dir

    d = tmp_path / "k"
    d.mkdir(mode=0o777)
    os.chmod(d, 0o777)
    private_dir(d)
    assert d.stat().st_mode & 0o777 == 0o700


def test_mesh_outside_the_package_folders_is_refused(tmp_path, monkeypatch):
    from baseplace.robots.collision import check_mesh_paths
    from baseplace.robots.spec import load_spec

    robot = _robot_dir(tmp_path, '"planar3"')
    urdf = (tmp_path / "planar3.urdf").read_text()
    link = urdf.index("<link ")
    evil = '<link name="evil"><collision><geometry><mesh filename="file:///etc/passwd"/></geometry></collision></link>'
    (tmp_path / "planar3.urdf").write_text(urdf[:link] + evil + urdf[link:])
    spec = load_spec(robot)
    with pytest.raises(InputError, match="outside the robot's package folders"):
        check_mesh_paths(spec)
    for uri in ("package://../../../etc/passwd", "../outside.stl"):
        (tmp_path / "planar3.urdf").write_text(
            urdf[:link] + evil.replace("file:///etc/passwd", uri) + urdf[link:]
        )
        with pytest.raises(InputError, match="outside"):
            check_mesh_paths(load_spec(robot))
    monkeypatch.setenv("BASEPLACE_MESH_DIRS", "/etc")
    (tmp_path / "planar3.urdf").write_text(urdf[:link] + evil + urdf[link:])
    check_mesh_paths(load_spec(robot))  # the user allowed it


LONG = "x" * 300


@pytest.mark.parametrize(
    "args,fragment",
    [
        (["build-map", "--robot", "tiago", "--out", f"{LONG}.rmap"], "255"),
        (["build-map", "--robot", "tiago", "--out", "y" * 240 + ".rmap"], "temporary files"),
        (["build-map", "--robot", "tiago", "--out", "."], "suffix"),
        (["build-map", "--robot", "tiago", "--out", "map.txt"], "suffix"),
        (["build-map", "--robot", "tiago", "--out", "nodir/m.rmap"], "does not exist"),
        (["build-map", "--robot", "tiago", "--out", "adir.rmap"], "directory"),
        (
            [
                "surface-map",
                "--robot",
                "tiago",
                "--polygon",
                "0,0;1,0;1,1",
                "--height",
                "0.7",
                "--out",
                f"{LONG}/s.smap",
            ],
            "255",
        ),
        (
            [
                "place",
                "--robot",
                "tiago",
                "--cloud",
                "c.pcd",
                "--target",
                "1 0 1 0 0 0",
                "--out",
                f"{LONG}.png",
            ],
            "255",
        ),
        (["scene", "generate", "--out", f"{LONG}.ply"], "255"),
        (["demo", "--out", LONG], "255"),
        (
            [
                "navigate",
                "--cloud",
                "c.pcd",
                "--start",
                "0 0 0",
                "--goal",
                "1 0 0",
                "--out",
                "a/" + "z/" * 2100 + "p.png",
            ],
            "limit",
        ),
    ],
)
def test_odd_output_paths_fail_fast_with_one_line(tmp_path, args, fragment):
    (tmp_path / "adir.rmap").mkdir()
    proc = cli(*args, cwd=tmp_path, env=_env(BASEPLACE_CACHE=str(tmp_path / "cache")))
    line = one_line(proc)
    assert fragment in line
    assert sorted(p.name for p in tmp_path.iterdir()) == ["adir.rmap"]


UNWRITABLE = "/proc/1"  # not writable even by root (os.access says so for the checks too)
TARGET = "1 0 1 0 0 0"
SANDBOX = str(Path(__file__).resolve().parents[2] / "shared" / "data" / "maps" / "tb3_sandbox.yaml")


UNWRITABLE_CASES = [
        (["build-map", "--out", "U/m.rmap"], "--out"),
        (["surface-map", "--polygon", "0,0;1,0;1,1", "--height", "0.7", "--out", "U/s.smap"], "--out"),
        (["surface-map", "--polygon", "0,0;1,0;1,1", "--height", "0.7", "--out", "s.smap", "--png", "U/s.png"], "--png"),
        (["place", "--cloud", "c.pcd", "--target", TARGET, "--out", "U/p.png"], "--out"),
        (["place", "--cloud", "c.pcd", "--target", TARGET, "--mcap", "U/p.mcap"], "--mcap"),
        (["place", "--cloud", "c.pcd", "--target", TARGET, "--fuse", "--fused-out", "U/f.bt"], "--fused-out"),
        (["candidates", "--occupancy", SANDBOX, "--object", "1 2 0.5", "--png", "U/c.png"], "--png"),
        (["candidates", "--occupancy", SANDBOX, "--object", "1 2 0.5", "--mcap", "U/c.mcap"], "--mcap"),
        (["navigate", "--cloud", "c.pcd", "--start", "0 0 0", "--goal", "1 0 0", "--out", "U/n.png"], "--out"),
        (["navigate", "--cloud", "c.pcd", "--start", "0 0 0", "--goal", "1 0 0", "--mcap", "U/n.mcap"], "--mcap"),
        (["segment", "c.pcd", "--out", "U/s.png"], "--out"),
        (["scene", "generate", "--out", "U/s.ply"], "--out"),
        (["scene", "generate", "--out", "s.ply", "--truth", "U/t.json"], "--truth"),
        (["demo", "--out", "U/out"], "--out"),
        (["robot", "check", "tiago", "--png", "U/r.png"], "--png"),
]  # fmt: skip


@pytest.mark.skipif(os.access(UNWRITABLE, os.W_OK), reason="needs a folder this user cannot write")
@pytest.mark.parametrize("args,option", UNWRITABLE_CASES)
def test_an_unwritable_output_of_any_command_fails_before_any_work(tmp_path, args, option):
    """Issue 16 item 5: every output is checked first; no cloud is read (c.pcd does not exist), no map built."""
    args = [a.replace("U/", UNWRITABLE + "/") for a in args]
    proc = cli(*args, "--json", cwd=tmp_path, env=_env(BASEPLACE_CACHE=str(tmp_path / "cache")))
    assert one_line(proc) == f"error: {option} directory '{UNWRITABLE}' is not writable"
    assert json.loads(proc.stdout)["exit_code"] == 2
    assert list(tmp_path.iterdir()) == []  # nothing written, not even the cache


@pytest.mark.skipif(os.access(UNWRITABLE, os.W_OK), reason="needs a folder this user cannot write")
def test_an_unwritable_output_is_refused_before_the_heavy_libraries_load(tmp_path):
    """Before any work means before the robot model, numba, the plots or scipy are even imported."""
    cases = [[a.replace("U/", UNWRITABLE + "/") for a in args] for args, _ in UNWRITABLE_CASES]
    code = f"""
import sys
from baseplace.cli import main
codes = [main(args) for args in {cases!r}]
print(codes, sorted(m for m in ("numba", "pinocchio", "matplotlib", "scipy", "ompl") if m in sys.modules))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=tmp_path,
                          env=_env(BASEPLACE_CACHE=str(tmp_path / "cache")), timeout=300)  # fmt: skip
    assert proc.stdout.strip() == f"{[2] * len(cases)} []", proc.stdout + proc.stderr[-2000:]
    assert proc.stderr.count("is not writable") == len(cases)


@pytest.mark.parametrize(
    "srdf",
    [
        "<robot name='planar3'><disable_collisions link1=",  # malformed XML
        "<robot name='planar3'><disable_collisions link1='nope' link2='tool0' reason='x'/></robot>",
        "\x00\x01\x02",
    ],
)
def test_bad_srdf_is_one_line(tmp_path, srdf):
    robot = _robot_dir(tmp_path, '"planar3"')
    (tmp_path / "bad.srdf").write_text(srdf)
    robot.write_text(
        robot.read_text().replace('urdf = "planar3.urdf"', 'urdf = "planar3.urdf"\nsrdf = "bad.srdf"')
    )
    proc = cli("build-map", "--robot", str(robot), "--samples", "1e4", "--self-collision", "--out",
               str(tmp_path / "m.rmap"), env=_env(BASEPLACE_CACHE=str(tmp_path / "cache")))  # fmt: skip
    if proc.returncode == 0:  # pinocchio ignores pairs of unknown links: then the build must succeed
        assert "nope" in srdf and (tmp_path / "m.rmap").is_file()
        return
    line = one_line(proc)
    assert "SRDF" in line
