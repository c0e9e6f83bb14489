"""The ``--json`` failure object of every command against the result schema (docs/results.md).

The success objects of every kind, and the failures of the jobs that need a map or a cloud, are
checked in tests/test_view_results.py (they reuse its results); the demo's in tests/test_cli.py.
Here: a malformed command line (argparse's errors) and a bad input file or output path for every
command, each exit 2 with the same object on stdout and the one line on stderr.
"""

from __future__ import annotations

import argparse
import json

import jsonschema
import pytest

from baseplace.cli import KINDS, build_parser
from baseplace.jobs import result_schema
from conftest import run_cli


def _commands() -> dict[tuple[str, ...], argparse.ArgumentParser]:
    """Every command that prints a report: its words (``("robot", "check")``) -> its parser."""
    out = {}

    def walk(parser: argparse.ArgumentParser, words: tuple[str, ...]) -> None:
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    walk(sub, (*words, name))
        if "job" in {a.dest for a in parser._actions} or parser.get_default("job") is not None:
            out[words] = parser

    walk(build_parser(), ())
    return out


COMMANDS = _commands()


def _failure(args: list[str], kind: str | None) -> dict:
    proc = run_cli(*args)
    assert proc.returncode == 2, (args, proc.stderr)
    obj = json.loads(proc.stdout)
    try:
        jsonschema.validate(obj, result_schema())
    except jsonschema.ValidationError as exc:
        raise AssertionError(f"{args}: {exc.message} at {list(exc.absolute_path)}") from None
    assert obj["kind"] == kind and obj["exit_code"] == 2 and obj["error"], obj
    assert proc.stderr.strip().splitlines() == [f"error: {obj['error']}"], proc.stderr
    return obj


def test_every_command_that_prints_a_report_is_covered():
    assert {KINDS[words[0]] for words in COMMANDS} == set(KINDS.values())
    assert len(COMMANDS) == len(KINDS)


@pytest.mark.parametrize("words", sorted(COMMANDS), ids=" ".join)
def test_a_malformed_command_line_prints_the_failure_object(words):
    kind = KINDS[words[0]]
    obj = _failure([*words, "--json", "--no-such-option"], kind)
    assert "--no-such-option" in obj["error"] or "arguments are required" in obj["error"], obj["error"]
    assert obj["inputs"] == {"argv": [*words, "--json", "--no-such-option"]}
    # a value of the wrong type, found by the command's own parser
    typed = [a for a in COMMANDS[words]._actions if a.option_strings and callable(a.type)]
    if typed:
        option = typed[0].option_strings[-1]
        obj = _failure([*words, "--json", option, "not-a-value"], kind)
        assert option in obj["error"]


@pytest.mark.parametrize("argv", [["--json"], ["frobnicate", "--json"]])
def test_a_command_line_without_a_command_prints_the_failure_object_with_no_kind(argv):
    obj = _failure(argv, None)
    assert obj["inputs"] == {"argv": argv}
    bad = dict(obj, error=None, exit_code=0)  # kind null is allowed on failures only
    with pytest.raises(jsonschema.ValidationError):
        jsonschema.validate(bad, result_schema())


BAD_INPUTS = {
    "robots": None,  # takes no input: its only failure is the command line's
    "robot check": (["robot", "check", "nowhere.toml"], "does not exist"),
    "build-map": (["build-map", "--out", "map.txt"], "suffix"),
    "reach": (["reach", "--map", "nowhere.rmap", "--target", "1 0 1 0 0 0", "--base", "0 0 0"], "nowhere.rmap"),
    "place": (["place", "--cloud", "nowhere.ply", "--target", "1 0 1 0 0 0"], "does not exist"),
    "explain": (["explain", "--map", "nowhere.rmap", "--target", "1 0 1 0 0 0", "--base", "0 0 0"], "nowhere.rmap"),
    "candidates": (["candidates", "--occupancy", "nowhere.yaml", "--object", "1 2 0.5"], "not found"),
    "navigate": (["navigate", "--cloud", "nowhere.ply", "--start", "0 0 0", "--goal", "1 0 0"], "does not exist"),
    "surface-map": (["surface-map", "--polygon", "0,0;1,0", "--height", "0.7", "--out", "s.smap"], "polygon"),
    "surface-sample": (["surface-sample", "--map", "nowhere.smap"], "does not exist"),
    "occupancy": (["occupancy", "nowhere.yaml"], "not found"),
    "segment": (["segment", "nowhere.ply"], "does not exist"),
    "scene generate": (["scene", "generate", "--out", "scene.txt"], "suffix"),
    "demo": (["demo", "--out", "demo.json/x"], "not a directory"),
    "point": (["point", "--rgb", "nowhere.png", "--depth", "d.png", "--intrinsics", "1 1 0 0", "--transform", "0 0 1"],
              "does not exist"),
}  # fmt: skip


@pytest.mark.parametrize("command", sorted(BAD_INPUTS))
def test_a_bad_input_prints_the_failure_object_with_the_inputs(command, tmp_path, monkeypatch):
    assert {" ".join(w) for w in COMMANDS} == set(BAD_INPUTS)
    if BAD_INPUTS[command] is None:
        return
    monkeypatch.chdir(tmp_path)
    (tmp_path / "demo.json").write_text("{}")  # a file where demo wants a folder
    args, fragment = BAD_INPUTS[command]
    obj = _failure([*args, "--json"], KINDS[args[0]])
    assert fragment in obj["error"]
    assert obj["inputs"], obj  # the inputs echoed, not the argparse envelope
    assert sorted(p.name for p in tmp_path.iterdir()) == ["demo.json"]  # nothing written
