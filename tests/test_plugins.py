"""The experiments are a plugin: baseplace never imports them, they register ``experiment`` through an entry point.

The shared development environment may hold an install made before the entry point existed, so
these tests register it themselves (a temporary ``.dist-info`` or a patched ``entry_points``)
instead of relying on what is installed.
"""

from __future__ import annotations

import argparse
import ast
import importlib.metadata
import os
import subprocess
import sys
from pathlib import Path

import tomllib

import baseplace.cli
from baseplace.cli import PLUGIN_GROUP, build_parser

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "baseplace"
EXPERIMENTS = "baseplace_experiments.cli:add_experiment_commands"


def _commands(parser: argparse.ArgumentParser) -> set[str]:
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return set(sub.choices)


def _docstrings(tree: ast.AST) -> set[int]:
    """ids of the string constants that are docstrings (prose may name the experiments)."""
    out = set()
    for node in ast.walk(tree):
        body = getattr(node, "body", None)
        if isinstance(body, list):
            for stmt in body:  # a docstring, or the string after an assignment (an attribute's docstring)
                if isinstance(stmt, ast.Expr) and isinstance(stmt.value, ast.Constant):
                    out.add(id(stmt.value))
    return out


def test_the_library_never_imports_the_experiments():
    """No import of baseplace_experiments, nor its name in code, anywhere under src/baseplace."""
    found = []
    for path in sorted(SRC.rglob("*.py")):
        tree = ast.parse(path.read_text(), str(path))
        prose = _docstrings(tree)
        for node in ast.walk(tree):
            names: list[str] = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                names = [node.module or ""]
            elif isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in prose:
                names = [node.value]  # importlib.import_module("baseplace_experiments...") and the like
            if any("baseplace_experiments" in n for n in names):
                found.append(f"{path.relative_to(ROOT)}:{node.lineno}")
    assert not found, f"the library names the experiments in code: {found}"


def test_the_experiment_command_comes_from_the_entry_point(monkeypatch):
    """With the entry point the parser has ``experiment``; without it, it does not (nothing hard-wired)."""
    ep = importlib.metadata.EntryPoint(name="experiment", value=EXPERIMENTS, group=PLUGIN_GROUP)

    def entry_points(**select: str) -> importlib.metadata.EntryPoints:
        assert select == {"group": PLUGIN_GROUP}
        return importlib.metadata.EntryPoints([ep, ep])  # a package installed twice adds its commands once

    monkeypatch.setattr(importlib.metadata, "entry_points", entry_points)
    assert {"experiment", "place", "view", "demo"} <= _commands(build_parser())
    monkeypatch.setattr(
        importlib.metadata, "entry_points", lambda **select: importlib.metadata.EntryPoints([])
    )
    commands = _commands(build_parser())
    assert "experiment" not in commands and {"place", "view", "demo"} <= commands


def test_a_broken_plugin_leaves_the_other_commands(monkeypatch, capsys):
    ep = importlib.metadata.EntryPoint(name="broken", value="no_such_module_h26:add", group=PLUGIN_GROUP)
    monkeypatch.setattr(
        importlib.metadata, "entry_points", lambda **select: importlib.metadata.EntryPoints([ep])
    )
    assert {"place", "demo"} <= _commands(baseplace.cli.build_parser())
    err = capsys.readouterr().err.strip().splitlines()
    assert (
        len(err) == 1
        and err[0].startswith("warning: the 'broken' commands")
        and "no_such_module_h26" in err[0]
    )


def test_pyproject_registers_the_experiments():
    """The wheel's entry point names the experiments' registration function, and it loads."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    group = project.get("entry-points", {}).get(PLUGIN_GROUP, {})
    assert group == {"experiment": EXPERIMENTS}
    ep = importlib.metadata.EntryPoint(name="experiment", value=EXPERIMENTS, group=PLUGIN_GROUP)
    assert callable(ep.load())


def test_baseplace_experiment_runs_when_the_entry_point_is_installed(tmp_path):
    """End to end, in a fresh interpreter: a distribution's entry point (a .dist-info on the path) adds it."""
    info = tmp_path / "baseplace_plugin_test-0.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: baseplace-plugin-test\nVersion: 0\n")
    (info / "entry_points.txt").write_text(f"[{PLUGIN_GROUP}]\nexperiment = {EXPERIMENTS}\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT / "src"), str(tmp_path)])}
    out = subprocess.run([sys.executable, "-m", "baseplace.cli", "experiment", "--help"], capture_output=True,
                         text=True, env=env, timeout=120)  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert "usage: baseplace experiment" in out.stdout and "table-grid" in out.stdout
