"""Deep and huge URDFs (issue 28, defect 12): refused with one line before pinocchio parses them.

urdfdom and pinocchio recurse once per joint of a chain: 10,000 revolute joints segfaulted
``robot check`` (exit 139), 1,000 and 3,000 ended in MemoryError tracebacks. The CLI runs in a
fresh process under an address-space limit (code without the check fails there, not in the
machine's memory); the refusal must be exit 2, one line, quick, and under the memory cap.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest

from baseplace.errors import InputError
from peak_memory import CAP_MB, cli_peak


def chain_robot(folder: Path, n: int, extra: str = "") -> Path:
    """A robot file on a URDF of ``n`` revolute joints in one chain (``extra``: more XML in <robot>)."""
    parts = ['<?xml version="1.0"?>', '<robot name="deep">', '<link name="base_link"/>', extra]
    for i in range(n):
        parent = "base_link" if i == 0 else f"l{i - 1}"
        parts.append(f'<link name="l{i}"/><joint name="j{i}" type="revolute"><parent link="{parent}"/>'
                     f'<child link="l{i}"/><origin xyz="0 0 0.01"/><axis xyz="0 0 1"/>'
                     '<limit lower="-1" upper="1" effort="1" velocity="1"/></joint>')  # fmt: skip
    parts.append("</robot>")
    (folder / f"deep{n}.urdf").write_text("\n".join(parts))
    robot = folder / f"deep{n}.toml"
    robot.write_text(f'name = "deep{n}"\nurdf = "deep{n}.urdf"\nbase_frame = "base_link"\n'
                     'footprint = { radius = 0.25 }\n\n[arms.arm]\njoints = ["j0", "j1"]\ntcp_frame = "l1"\n')  # fmt: skip
    return robot


@pytest.mark.parametrize("n", [1000, 3000, 10_000])
def test_robot_check_refuses_a_deep_chain(tmp_path: Path, n: int) -> None:
    robot = chain_robot(tmp_path, n)
    code, err, seconds, peak_mb = cli_peak("robot", "check", str(robot), "--png", "x.png", cwd=tmp_path)
    assert code == 2, (code, err[-2000:])
    lines = err.strip().splitlines()
    assert lines == [f"error: URDF {tmp_path / f'deep{n}.urdf'} has {n + 1} links; the limit is 512"], err[
        -2000:
    ]
    assert seconds < 15.0 and peak_mb < CAP_MB, (seconds, peak_mb)
    assert not (tmp_path / "x.png").exists()


@pytest.mark.parametrize(
    "command",
    [
        ["build-map", "--robot", "ROBOT", "--samples", "1000", "--out", "x.rmap"],
        ["surface-map", "--robot", "ROBOT", "--polygon", "0,0;1,0;1,1", "--height", "0.7", "--out", "x.smap"],
    ],
    ids=["build-map", "surface-map"],
)
def test_other_commands_refuse_a_deep_chain(tmp_path: Path, command: list[str]) -> None:
    robot = chain_robot(tmp_path, 10_000)
    args = [str(robot) if a == "ROBOT" else a for a in command]
    code, err, seconds, peak_mb = cli_peak(*args, cwd=tmp_path)
    assert code == 2, (code, err[-2000:])
    assert len(err.strip().splitlines()) == 1 and "has 10001 links; the limit is 512" in err, err[-2000:]
    assert seconds < 15.0 and peak_mb < CAP_MB, (seconds, peak_mb)


def test_a_chain_deeper_than_the_limit_is_refused(tmp_path: Path) -> None:
    """300 joints (under the count limit) in one chain: over the depth limit of 256."""
    from baseplace.robots.model import Robot

    with pytest.raises(InputError, match=r"link 'l256' is 257 joints from the root; the limit is 256"):
        Robot(chain_robot(tmp_path, 300))


def test_joint_cycles_and_deep_xml_are_refused(tmp_path: Path) -> None:
    from baseplace.robots.model import Robot

    cycle = '<link name="a"/><link name="b"/><joint name="ab" type="fixed"><parent link="a"/><child link="b"/></joint>' \
            '<joint name="ba" type="fixed"><parent link="b"/><child link="a"/></joint>'  # fmt: skip
    with pytest.raises(InputError, match="the joints form a cycle"):
        Robot(chain_robot(tmp_path, 3, cycle))
    nested = '<link name="x"><visual>' + "<g>" * 100 + "</g>" * 100 + "</visual></link>"
    with pytest.raises(InputError, match="nested over 64 deep"):
        Robot(chain_robot(tmp_path, 3, nested))


def test_a_urdf_over_16_mb_is_refused_before_it_is_read(tmp_path: Path) -> None:
    from baseplace.robots.model import Robot

    robot = chain_robot(tmp_path, 3, "<!--" + " " * (16 << 20) + "-->")
    t0 = time.perf_counter()
    with pytest.raises(InputError, match=r"deep3.urdf is 167\d+ bytes; the limit is 16777216 \(16 MB\)"):
        Robot(robot)
    assert time.perf_counter() - t0 < 0.5


def test_a_real_robot_is_within_every_limit() -> None:
    from baseplace.robots.model import Robot

    for name in ("tiago", "pr2", "tiago_dual"):
        assert Robot(name).model.njoints > 1
