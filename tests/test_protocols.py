"""Protocol files committed before held-out runs, and provenance that sees untracked code (issue 27 item 1)."""

from __future__ import annotations

import json
import subprocess
from pathlib import Path

import pytest

from baseplace.errors import InputError
from baseplace_experiments import results
from baseplace_experiments.results import RunClock, fixed_protocol, git_commit, protocol_record, write_results

PROTOCOL = "docs/protocols/x.md"


def _git(repo: Path, *args: str) -> str:
    return subprocess.run(["git", "-c", "user.name=t", "-c", "user.email=t@example.org", *args], cwd=repo,
                          check=True, capture_output=True, text=True).stdout  # fmt: skip


@pytest.fixture
def repo(tmp_path: Path) -> Path:
    """A git repository holding a committed protocol file and a source file."""
    _git(tmp_path, "init", "-q")
    (tmp_path / "docs" / "protocols").mkdir(parents=True)
    (tmp_path / PROTOCOL).write_text("seeds: dev 0, held-out 1\n")
    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "m.py").write_text("x = 1\n")
    _git(tmp_path, "add", ".")
    _git(tmp_path, "commit", "-q", "-m", "protocol")
    return tmp_path


def test_a_committed_protocol_is_recorded_with_its_commit(repo):
    record = fixed_protocol(PROTOCOL, "held-out", repo)
    assert record is not None and record.clean
    assert record.commit == _git(repo, "rev-parse", "HEAD").strip()
    assert record.as_dict() == {"file": PROTOCOL, "commit": record.commit, "clean": True}  # no folder stored


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ("edit", "has uncommitted changes"),
        ("stage", "has uncommitted changes"),
        ("new", "not committed"),
        ("missing", "not committed"),
    ],
)
def test_a_held_out_run_is_refused_unless_its_protocol_is_committed_and_clean(repo, change, message):
    name = PROTOCOL
    if change in ("edit", "stage"):
        (repo / PROTOCOL).write_text("seeds: dev 0, held-out 1, 2\n")
        if change == "stage":
            _git(repo, "add", PROTOCOL)
    elif change == "new":
        name = "docs/protocols/new.md"
        (repo / name).write_text("new\n")
    else:
        name = "docs/protocols/none.md"
    with pytest.raises(InputError, match=message) as caught:
        fixed_protocol(name, "held-out", repo)
    assert "\n" not in str(caught.value) and name in str(caught.value)
    record = fixed_protocol(name, "dev", repo)  # the dev split runs, and says the protocol was not clean
    assert record is not None and not record.clean


def test_a_held_out_run_needs_a_protocol_file():
    with pytest.raises(InputError, match="needs its protocol file"):
        fixed_protocol(None, "held-out")
    with pytest.raises(InputError, match="needs its protocol file"):
        write_results(Path("never.json"), {}, RunClock(), split="held-out")
    assert not Path("never.json").exists()
    assert fixed_protocol(None, "dev") is None and fixed_protocol(None, None) is None


def test_a_protocol_changed_during_the_run_stops_the_results(repo, tmp_path_factory):
    out = tmp_path_factory.mktemp("out") / "r.json"
    record = fixed_protocol(PROTOCOL, "held-out", repo)
    (repo / PROTOCOL).write_text("changed while running\n")
    _git(repo, "commit", "-q", "-am", "later")  # committed, but after the run started
    with pytest.raises(InputError, match="changed during the run"):
        write_results(out, {"rows": []}, RunClock(), split="held-out", protocol_file=record)
    assert not out.exists()
    now = fixed_protocol(PROTOCOL, "held-out", repo)
    written = write_results(out, {"rows": []}, RunClock(), split="held-out", protocol_file=now)
    assert (
        json.loads(out.read_text())["provenance"]["protocol_file"] == written["provenance"]["protocol_file"]
    )
    assert written["provenance"]["protocol_file"]["commit"] == _git(repo, "rev-parse", "HEAD").strip()


def test_dirty_counts_untracked_code_but_not_results_or_docs(repo):
    assert git_commit(repo)["dirty"] is False
    (repo / "bench" / "results").mkdir(parents=True)
    (repo / "bench" / "results" / "r.json").write_text("{}")
    (repo / "docs" / "notes.md").write_text("notes\n")
    assert git_commit(repo)["dirty"] is False
    (repo / "src" / "new_module.py").write_text("y = 2\n")  # untracked: imported all the same
    source = git_commit(repo)
    assert source["dirty"] is True and source["dirty_paths"] == ["src/new_module.py"]
    (repo / "src" / "new_module.py").unlink()
    (repo / "src" / "m.py").write_text("x = 2\n")
    assert git_commit(repo)["dirty_paths"] == ["src/m.py"]


def test_outside_git_the_protocol_cannot_be_checked(tmp_path):
    assert protocol_record(PROTOCOL, tmp_path).commit is None
    with pytest.raises(InputError, match="not in a git work tree or not committed"):
        fixed_protocol(PROTOCOL, "held-out", tmp_path)


def test_the_experiment_command_refuses_a_held_out_seed_before_any_work(
    repo, monkeypatch, capsys, tmp_path_factory
):
    """The command line checks the protocol first: one line, exit 2, no results file."""
    from baseplace.cli import main

    (repo / "docs" / "protocols" / "segmentation.md").write_text("committed\n")
    _git(repo, "add", ".")
    _git(repo, "commit", "-q", "-m", "segmentation protocol")
    (repo / "docs" / "protocols" / "segmentation.md").write_text("edited after the commit\n")
    monkeypatch.setattr(results, "_source_dir", lambda: repo)
    out = tmp_path_factory.mktemp("out") / "seg.json"
    code = main(
        ["experiment", "segmentation", "--scenes", "1", "--noise", "heightmap", "--results", str(out)]
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert "docs/protocols/segmentation.md has uncommitted changes" in err[0]
    assert not out.exists()


@pytest.mark.parametrize(
    "module",
    ["segmentation_eval", "table_grid", "osrm_experiment"],
)
def test_every_experiment_names_a_protocol_file_that_exists(module):
    import importlib

    path = importlib.import_module(f"baseplace_experiments.{module}").PROTOCOL_FILE
    top = Path(__file__).resolve().parents[1]
    assert (top / path).is_file(), path


def test_every_protocol_file_named_in_code_exists():
    """Every ``docs/protocols/...`` string in the experiments and benchmarks names a file that exists."""
    import ast

    top = Path(__file__).resolve().parents[1]
    named = {
        node.value
        for folder in ("src/baseplace_experiments", "bench")
        for path in (top / folder).glob("*.py")
        for node in ast.walk(ast.parse(path.read_text()))
        if isinstance(node, ast.Constant)
        and isinstance(node.value, str)
        and node.value.startswith("docs/protocols/")
    }
    assert len(named) >= 9
    assert sorted(p for p in named if not (top / p).is_file()) == []
