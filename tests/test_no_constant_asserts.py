"""No test asserts something whose truth does not depend on the code under test.

:func:`constant_asserts` reads a test file with :mod:`ast` and reports every ``assert`` that holds
whatever the code does:

* a literal or an expression of literals only: ``assert True``, ``assert 1``, ``assert "x"``,
  ``assert 2 > 1``, ``assert not None``, ``assert [1] == [1]``;
* a non-empty tuple (always true): ``assert (x == 1, "message")``;
* a reflexive comparison of one expression with itself (``==``, ``is``, ``<=``, ``>=``, ``in`` on the
  same text on both sides), unless a side calls something: ``assert x == x``, ``assert a.b is a.b``;
  ``f() == f()`` checks that ``f`` is deterministic and is allowed;
* an ``or`` with a true literal: ``assert x or True``;
* a bound on a default, compared by an order or ``!=``: ``assert GroundTruth().grid > 0`` (a class built
  without arguments inside the assert, one of its attributes against a literal). Pinning a default
  by ``==`` (``assert Settings().limit == 4``) states the documented value and is allowed.

Everything else is a real check and is not reported.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

TESTS = Path(__file__).parent

_REFLEXIVE = (ast.Eq, ast.Is, ast.LtE, ast.GtE, ast.In)
_ORDER = (ast.Gt, ast.GtE, ast.Lt, ast.LtE, ast.NotEq)


def _is_literal(node: ast.expr) -> bool:
    """True when ``node`` is built from literals only (its value is fixed when the file is written)."""
    if isinstance(node, ast.Constant):
        return True
    if isinstance(node, (ast.Tuple, ast.List, ast.Set)):
        return all(_is_literal(e) for e in node.elts)
    if isinstance(node, ast.Dict):
        return all(k is not None and _is_literal(k) for k in node.keys) and all(map(_is_literal, node.values))
    if isinstance(node, ast.UnaryOp):
        return _is_literal(node.operand)
    if isinstance(node, ast.BinOp):
        return _is_literal(node.left) and _is_literal(node.right)
    if isinstance(node, ast.BoolOp):
        return all(_is_literal(v) for v in node.values)
    if isinstance(node, ast.Compare):
        return _is_literal(node.left) and all(_is_literal(c) for c in node.comparators)
    return False


def _calls(node: ast.AST) -> bool:
    return any(isinstance(n, ast.Call) for n in ast.walk(node))


def _default_of_bare_class(node: ast.expr) -> bool:
    """``C().attr`` with ``C`` a capitalised name called without arguments."""
    if not isinstance(node, ast.Attribute) or not isinstance(node.value, ast.Call):
        return False
    call = node.value
    return (
        isinstance(call.func, ast.Name) and call.func.id[:1].isupper() and not call.args and not call.keywords
    )


def why_constant(test: ast.expr) -> str | None:
    """Why the assert of ``test`` cannot fail (or always fails regardless of the code), None for a real check."""
    if _is_literal(test):
        return "asserts a literal"
    if isinstance(test, ast.Tuple) and test.elts:
        return "asserts a non-empty tuple (always true)"
    if isinstance(test, ast.BoolOp) and isinstance(test.op, ast.Or):
        if any(
            _is_literal(v) and bool(ast.literal_eval(v)) for v in test.values if isinstance(v, ast.Constant)
        ):
            return "an `or` with a true literal"
    if isinstance(test, ast.Compare) and len(test.ops) == 1:
        left, right, op = test.left, test.comparators[0], test.ops[0]
        if isinstance(op, _REFLEXIVE) and ast.dump(left) == ast.dump(right) and not _calls(left):
            return "compares an expression with itself"
        if isinstance(op, _ORDER) and (
            (_is_literal(right) and _default_of_bare_class(left))
            or (_is_literal(left) and _default_of_bare_class(right))
        ):
            return "bounds a class default against a literal"
    return None


def constant_asserts(source: str, filename: str = "<test>") -> list[str]:
    """``file:line: reason: text`` for every assert in ``source`` that does not depend on the code."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        if isinstance(node, ast.Assert):
            reason = why_constant(node.test)
            if reason is not None:
                found.append(f"{filename}:{node.lineno}: {reason}: assert {ast.unparse(node.test)}")
    return found


def test_no_test_file_asserts_a_constant():
    found = [
        hit for path in sorted(TESTS.rglob("*.py")) for hit in constant_asserts(path.read_text(), path.name)
    ]
    assert found == []


OLD_OSRM_TEST = """
def test_incline_only_scene_reachable_only_from_the_incline(tiago):
    rmap = build_map(tiago, None, BuildSettings(samples=300_000))
    _, scene, _, _ = experiment_scene(ExperimentSettings(seed=3), 7, 0)
    assert len(scene.planes) == 2 and scene.box is not None
    assert GroundTruth().grid > 0
"""
"""tests/test_osrm_experiment.py as commit d7d3fac left it (shortened): its last assert cannot fail."""


def test_the_check_catches_the_old_osrm_assert():
    assert constant_asserts(OLD_OSRM_TEST) == [
        "<test>:6: bounds a class default against a literal: assert GroundTruth().grid > 0"
    ]


@pytest.mark.parametrize(
    ("line", "reason"),
    [
        ("assert True", "asserts a literal"),
        ("assert 1", "asserts a literal"),
        ("assert 'text'", "asserts a literal"),
        ("assert not None", "asserts a literal"),
        ("assert 2 > 1", "asserts a literal"),
        ("assert [1, 2] == [1, 2]", "asserts a literal"),
        ("assert -1 < 0 < 1", "asserts a literal"),
        ("assert (x == 1, 'x is one')", "asserts a non-empty tuple (always true)"),
        ("assert x == x", "compares an expression with itself"),
        ("assert a.b[0] is a.b[0]", "compares an expression with itself"),
        ("assert ok or True", "an `or` with a true literal"),
        ("assert GroundTruth().grid > 0", "bounds a class default against a literal"),
        ("assert 0 < Settings().limit", "bounds a class default against a literal"),
    ],
)
def test_constant_asserts_are_caught(line, reason):
    assert constant_asserts(line) == [f"<test>:1: {reason}: {ast.unparse(ast.parse(line).body[0])}"]


@pytest.mark.parametrize(
    "line",
    [
        "assert x",
        "assert x == 1",
        "assert result['MR']['success_rate'] > 0",
        "assert f() == f()",  # determinism: two calls
        "assert x == y",
        "assert Settings().limit == 4",  # pins the documented default
        "assert Settings(limit=3).limit > 0",
        "assert ok or False",
        "assert not x",
        "assert (x, y) == (1, 2)",
        "assert len(found) == 0",
    ],
)
def test_real_checks_are_not_reported(line):
    assert constant_asserts(line) == []
