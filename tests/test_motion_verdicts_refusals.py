"""bench/bench_motion_verdicts.py refuses, in one argparse line and exit 2, before any scene is built.

The held-out split runs a protocol of ``PROTOCOLS`` (docs/protocols/motion_verdicts_vN.md) as
written, with its file committed; the dev split refuses the seeds experiments hold out, every
protocol's held-out seeds among them. Every call here stops at a refusal:
the robot, scene and placement functions of the bench are replaced by ones that fail the test, so a
refusal that went missing would fail here before any held-out seed were drawn.
"""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from baseplace_experiments import results

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "bench"))

import bench_motion_verdicts as bench

HELD_OUT_AS_WRITTEN = ["--split", "held-out", "--checkers", "product", "reference"]


class WorkStarted(Exception):
    """The bench went past its refusals."""


@pytest.fixture(autouse=True)
def no_work(monkeypatch):
    """The bench's first steps of work fail the test instead of running."""

    def started(*args, **kwargs):
        raise WorkStarted

    for name in ("Robot", "resolve_map", "scene", "place"):
        monkeypatch.setattr(bench, name, started)


def _refusal(capsys, argv: list[str]) -> str:
    """The argparse error line of the bench's refusal of ``argv`` (exit 2)."""
    with pytest.raises(SystemExit) as caught:
        bench.main(argv)
    assert caught.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[0].startswith("usage: ")
    assert err[-1].startswith(f"{Path(sys.argv[0]).name}: error: ")
    return err[-1]


@pytest.mark.parametrize(
    ("extra", "named"),
    [
        (["--seeds", "40"], "no --seeds, --cells or --max-checks"),
        (["--seeds", "0"], "no --seeds, --cells or --max-checks"),
        (["--cells", "2"], "no --seeds, --cells or --max-checks"),
        (["--max-checks", "3"], "no --seeds, --cells or --max-checks"),
        (["--checkers", "product", "product_500", "reference"], "--checkers product reference"),
        (["--checkers", "product"], "--checkers product reference"),
        (["--checkers", "reference", "product"], "--checkers product reference"),
        (["--grasps", "0", "2"], "default grasps"),
        (["--per-grasp", "2"], "--per-grasp"),
    ],
)
@pytest.mark.parametrize("version", sorted(bench.PROTOCOLS))
def test_held_out_runs_its_protocol_as_written(capsys, extra, named, version):
    line = _refusal(capsys, [*HELD_OUT_AS_WRITTEN, "--protocol", str(version), *extra])
    assert f"the held-out split runs protocol v{version} as written" in line
    assert named in line


def test_held_out_runs_the_newest_protocol_by_default(capsys):
    assert f"protocol v{max(bench.PROTOCOLS)} as written" in _refusal(
        capsys, [*HELD_OUT_AS_WRITTEN, "--cells", "2"]
    )


def test_held_out_refuses_the_default_checkers(capsys):
    assert "--checkers product reference" in _refusal(capsys, ["--split", "held-out"])


@pytest.mark.parametrize("seed", [*range(3, 38), *range(40, 50), *range(50, 70)])
def test_dev_refuses_held_out_seeds(capsys, seed):
    line = _refusal(capsys, ["--seeds", "0", str(seed)])
    assert f"seeds [{seed}] are held out by an experiment" in line


@pytest.mark.parametrize(
    ("commit", "state"),
    [("0" * 40, "has uncommitted changes"), (None, "is not in a git work tree or not committed")],
)
@pytest.mark.parametrize("version", sorted(bench.PROTOCOLS))
def test_held_out_refuses_a_protocol_file_not_committed(capsys, monkeypatch, commit, state, version):
    asked = []

    def record(file, where=None):
        asked.append(file)
        return results.ProtocolRecord(file, commit, False)

    monkeypatch.setattr(results, "protocol_record", record)
    line = _refusal(capsys, [*HELD_OUT_AS_WRITTEN, "--protocol", str(version)])
    file = f"docs/protocols/motion_verdicts_v{version}.md"
    assert asked == [file]
    assert f"protocol file {file} {state}" in line


@pytest.mark.parametrize("seeds", [["0"], ["1", "2"]])
def test_dev_seeds_pass_the_refusals(seeds):
    """The control: a dev run is refused nothing and reaches its work (stopped here by :func:`no_work`)."""
    with pytest.raises(WorkStarted):
        bench.main(["--seeds", *seeds])
