"""Loaders bounded before they parse (issue 28's loose ends): SRDF size and depth, ASCII PCD rows.

Each hostile file goes through the CLI (exit 2, one line) or a fresh process whose peak resident
memory (``VmHWM`` minus its resident set after the imports) is the oracle, as in
``tests/test_hostile_files.py``.
"""

from __future__ import annotations

import subprocess
from pathlib import Path

from test_hostile_files import probe
from test_security import _env, _robot_dir, cli, one_line


def _with_srdf(tmp_path: Path, text: str) -> Path:
    robot = _robot_dir(tmp_path, '"planar3"')
    (tmp_path / "hostile.srdf").write_text(text)
    robot.write_text(
        robot.read_text().replace('urdf = "planar3.urdf"', 'urdf = "planar3.urdf"\nsrdf = "hostile.srdf"')
    )
    return robot


def _self_collision_map(tmp_path: Path, robot: Path) -> subprocess.CompletedProcess[str]:
    return cli("build-map", "--robot", str(robot), "--samples", "1e4", "--self-collision", "--out",
               str(tmp_path / "m.rmap"), env=_env(BASEPLACE_CACHE=str(tmp_path / "cache")))  # fmt: skip


def test_a_deeply_nested_srdf_is_one_line_not_a_crash(tmp_path):
    n = 100_000  # 700 kB; pinocchio's SRDF reader recursed once per level and crashed (exit 139)
    robot = _with_srdf(tmp_path, "<robot name='planar3'>" + "<a>" * n + "</a>" * n + "</robot>")
    line = one_line(_self_collision_map(tmp_path, robot))
    assert "SRDF" in line and "nested over 64 deep" in line, line


def test_an_srdf_over_the_size_limit_is_refused_before_it_is_parsed(tmp_path):
    padding = "<!--" + " " * 17 * 2**20 + "-->"  # a valid SRDF of 17 MiB, all comment; the limit is 16
    robot = _with_srdf(tmp_path, "<robot name='planar3'>" + padding + "</robot>")
    line = one_line(_self_collision_map(tmp_path, robot))
    assert "SRDF" in line and "the limit is 16777216" in line, line


def test_ascii_pcd_rows_beyond_its_points_are_refused_before_they_are_read(tmp_path):
    header = ("# .PCD v0.7\nVERSION 0.7\nFIELDS x y z\nSIZE 8 8 8\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 1\n"
              "HEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 1\nDATA ascii\n")  # fmt: skip
    path = tmp_path / "rows.pcd"
    path.write_text(header + "0 0 0\n" * 4_000_000)  # 24 MB: 96 MB of rows for a 1-point header
    cap_mb = 64
    result = probe("cloud", path, BASEPLACE_MAX_MEMORY_MB=str(cap_mb))
    print(result)
    assert result["peak_mb"] < cap_mb / 2, result
    assert (
        result["outcome"].startswith("error: ")
        and "more rows than the header's 1 POINTS" in result["outcome"]
    )
    # an honest ASCII PCD still loads, a trailing blank line and a comment row included
    path.write_text(
        header.replace("WIDTH 1", "WIDTH 2").replace("POINTS 1", "POINTS 2") + "0 0 0\n# x\n1 1 1\n\n"
    )
    from baseplace.terrain.io import load_cloud

    assert len(load_cloud(path).points) == 2
