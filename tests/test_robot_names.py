"""No robot names outside the robot files (issue 26): code works for any robot the specs describe.

Code outside ``src/baseplace/robots/`` may not use a built-in robot's name as a value (a string
that is just ``"tiago"``, ``"pr2"``, ``"tiago_dual"``) nor in an identifier; prose may (docstrings,
help texts, messages). The default robot is one constant,
:data:`baseplace.robots.defaults.DEFAULT_ROBOT`.
"""

from __future__ import annotations

import ast
import re
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SRC = ROOT / "src" / "baseplace"
NAME = re.compile(r"tiago|pr2", re.IGNORECASE)
BARE = re.compile(r"(tiago|pr2)\w*", re.IGNORECASE)

KNOWN: dict[str, int] = {}
"""Files whose robot names are still to go: the list only shrinks (the service's defaults went last,
to ``DEFAULT_ROBOT``)."""


def robot_names_in_code(path: Path) -> list[str]:
    """``line: what`` for every robot name used as a value or in an identifier in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Constant) and isinstance(node.value, str):
            if BARE.fullmatch(node.value.strip()):
                found.append(f"{node.lineno}: {node.value!r}")
        elif isinstance(node, ast.Name | ast.arg | ast.FunctionDef | ast.ClassDef | ast.Attribute):
            ident = getattr(node, "id", None) or getattr(node, "arg", None) or getattr(node, "name", None)
            ident = ident or getattr(node, "attr", "")
            if NAME.search(ident):
                found.append(f"{node.lineno}: {ident}")
    return found


def test_no_robot_names_outside_the_robot_files():
    counts: Counter[str] = Counter()
    details = {}
    for path in sorted(SRC.rglob("*.py")):
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith("src/baseplace/robots/"):
            continue
        found = robot_names_in_code(path)
        if found:
            counts[rel] = len(found)
            details[rel] = found
    new = {f: details[f] for f, n in counts.items() if n > KNOWN.get(f, 0)}
    assert not new, f"robot names in code outside src/baseplace/robots (use DEFAULT_ROBOT or the spec): {new}"
    fewer = {f: (KNOWN[f], counts[f]) for f in KNOWN if counts[f] < KNOWN[f]}
    assert not fewer, f"fewer robot names now: lower or strike them in KNOWN (known, now): {fewer}"


def test_the_scan_finds_a_name_used_as_a_value(tmp_path):
    """The oracle for the scan itself: values and identifiers count, prose does not."""
    code = tmp_path / "m.py"
    code.write_text(
        '"""TIAGo and the PR2 in a docstring."""\n'
        'robot = "tiago"\n'
        'if name == "tiago_dual":\n    pass\n'
        "_TIAGO_ARM = 1\n"
        'help_text = "built-in name or robot file (default: tiago)"\n'
        'title = "TIAGo: placement on the platform"\n'
    )
    assert sorted(int(f.split(":")[0]) for f in robot_names_in_code(code)) == [2, 3, 5]
