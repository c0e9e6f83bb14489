"""The README's and the docs' ``baseplace`` commands, run as written, in document order (issue 29).

Each command in a fenced block is run in a scratch folder shared by the commands of its document
(so ``scene generate ... --out scene.ply`` makes the ``scene.ply`` that later lines read); paths
under ``../shared/`` and the repository's ``examples/`` resolve as the README writes them, from
the repository root. A command must exit as its document says: 0, unless the document presents it
as a refusal, by ``exit N`` and the reason in quotes in its comment, or an ``error: ...`` output
line with ``(exit N`` below it; then stderr must hold that reason.

Not run: synopsis lines (``...``, ``[--option]``, ``a|b``, upper-case placeholders like
``RESULT.json``), commands that serve or open a browser, and commands reading a file that neither
the repository, the shared data nor an earlier command of the document provides. Commands that
build or load the default map (2e8 samples, about a minute on a fresh machine), experiments and
other long runs are marked slow.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass
from pathlib import Path

import pytest

from conftest import run_cli

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
OUTPUT_OPTIONS = {"--out", "--png", "--results", "--mcap", "--fused-out", "--write"}
INPUT_SUFFIXES = (".ply", ".pcd", ".bt", ".npy", ".xyz", ".rmap", ".smap", ".yaml", ".toml", ".mcap", ".txt",
                  ".json", ".db3", ".h5")  # fmt: skip
FROM_ROOT = ("examples/", "tests/", "bench/", "docs/")
PLACEHOLDER = re.compile(
    r"\.\.\.|\[|\]|\||<|>|^[A-Z][A-Z0-9_]{2,}(\.\w+)?$|/[A-Z][A-Z0-9_]{2,}|^[a-z]+( [a-z]+)+$"
)
INPUT_OPTIONS = {"--cloud", "--bag", "--map", "--occupancy", "--targets", "--bases"}
NEVER_RUN = ("serve",)  # a server: runs until stopped
SLOW_COMMANDS = ("experiment", "demo", "build-map", "surface-map", "navigate")
# without --map (or with --map default) these read the default map, built on a fresh machine
DEFAULT_MAP_COMMANDS = ("place", "explain", "candidates", "reach")


@dataclass(frozen=True)
class DocCommand:
    """One ``baseplace`` command of a document, with the exit it documents."""

    document: str
    line: int
    words: tuple[str, ...]
    exit_code: int
    reason: str | None
    runnable: bool
    slow: bool
    why_not: str = ""


def _fenced_blocks(text: str) -> list[tuple[int, list[str]]]:
    blocks, current, start, fence = [], [], 0, None
    for number, line in enumerate(text.splitlines(), 1):
        stripped = line.strip()
        if fence is None and stripped.startswith("```"):
            fence, start, current = stripped[3:].strip(), number + 1, []
        elif fence is not None and stripped.startswith("```"):
            if fence in ("", "sh", "bash", "console", "shell"):
                blocks.append((start, current))
            fence = None
        elif fence is not None:
            current.append(line)
    return blocks


def _documented_exit(comment: str, output: list[str]) -> tuple[int, str | None]:
    """The exit code and reason a command's comment or the output lines under it document."""
    found = re.search(r"\bexit (\d):", comment)
    if found:
        reason = re.search(r'"([^"]+)"|`([^`]+)`', comment[found.end() :])
        return int(found.group(1)), None if reason is None else (reason.group(1) or reason.group(2))
    text = " ".join(line.strip() for line in output)
    if text.startswith("error:"):
        code = re.search(r"\(exit (\d)", text)
        first = text[len("error:") :].split("...")[0].split("(exit")[0].strip()
        return (int(code.group(1)) if code else 2), first
    return 0, None


def _inputs(words: list[str]) -> list[str]:
    """The file arguments a command reads: positional paths and option values that are not outputs."""
    found = []
    for k, word in enumerate(words[1:], 1):
        if word.startswith("-") or words[k - 1] in OUTPUT_OPTIONS:
            continue
        if (
            word.endswith(INPUT_SUFFIXES)
            or word.startswith(("../", *FROM_ROOT))
            or words[k - 1] in INPUT_OPTIONS
        ):
            found.append(word)
    return found


def _outputs(words: list[str]) -> list[str]:
    return [words[k + 1] for k, w in enumerate(words[:-1]) if w in OUTPUT_OPTIONS]


def resolve(word: str) -> str:
    """A path as the README writes it: ``../shared/...`` and ``examples/...`` from the repository root."""
    if word.startswith("../shared/") or word.startswith(FROM_ROOT):
        return str((ROOT / word).resolve())
    return word


def doc_commands(path: Path) -> list[DocCommand]:
    """Every ``baseplace`` command of a document's shell blocks, in order."""
    commands: list[DocCommand] = []
    made: dict[str, bool] = {}  # file an earlier command writes -> whether that command is slow
    for start, lines in _fenced_blocks(path.read_text()):
        k = 0
        while k < len(lines):
            first, text = k, lines[k]
            while text.rstrip().endswith("\\") and k + 1 < len(lines):
                k += 1
                text = text.rstrip()[:-1] + " " + lines[k].strip()
            k += 1
            if not text.startswith("baseplace "):
                continue
            output = []
            while k < len(lines) and lines[k].strip() and not lines[k].startswith("baseplace "):
                output.append(lines[k])
                k += 1
            lexer = shlex.shlex(text, posix=True, punctuation_chars=False)
            lexer.whitespace_split, lexer.commenters = True, "#"
            words = list(lexer)
            comment = text.split("  #", 1)[1] if "  #" in text else ""
            code, reason = _documented_exit(comment, output)
            why_not, slow = "", False
            if any(PLACEHOLDER.search(w) for w in words) or "..." in text.split("  #")[0]:
                why_not = "a synopsis line"
            elif words[1] in NEVER_RUN or (words[1] == "view" and "--out" not in words):
                why_not = "serves until stopped"
            elif any(w.startswith("tcp://") for w in words):
                why_not = "needs a dask scheduler"
            elif any(w.startswith(FROM_ROOT) for w in _outputs(words)):
                why_not = "writes the repository's own results"
            for word in _inputs(words):
                if why_not:
                    break
                if word in made:
                    slow = slow or made[word]
                elif not Path(resolve(word)).exists():
                    why_not = f"reads {word}, which nothing provides"
            slow = slow or words[1] in SLOW_COMMANDS
            given_map = words[words.index("--map") + 1] if "--map" in words[:-1] else "default"
            if words[1] in DEFAULT_MAP_COMMANDS and given_map == "default":
                slow = True  # builds the 2e8-sample default map on a fresh machine
            for output_file in _outputs(words) if not why_not else ():
                made[output_file] = slow
            rel = str(path.relative_to(ROOT))
            commands.append(
                DocCommand(rel, start + first, tuple(words), code, reason, not why_not, slow, why_not)
            )
    return commands


ALL = [c for doc in DOCUMENTS for c in doc_commands(doc)]
RUNNABLE = [c for c in ALL if c.runnable]


@pytest.fixture(scope="module")
def workdirs(tmp_path_factory):
    return {doc.name: tmp_path_factory.mktemp(doc.stem) for doc in DOCUMENTS}


@pytest.mark.parametrize(
    "command",
    [
        pytest.param(c, marks=[pytest.mark.slow] if c.slow else [], id=f"{c.document}:{c.line}")
        for c in RUNNABLE
    ],
)
def test_documented_command_behaves_as_documented(command: DocCommand, workdirs, monkeypatch):
    monkeypatch.chdir(workdirs[Path(command.document).name])
    inputs = set(_inputs(list(command.words)))
    result = run_cli(*[resolve(w) if w in inputs else w for w in command.words[1:]])
    said = f"{' '.join(command.words)}\nexit {result.returncode}\nstderr: {result.stderr[-2000:]}"
    assert result.returncode == command.exit_code, said
    if command.exit_code != 0:
        assert command.reason, (
            f"{command.document}:{command.line} documents exit {command.exit_code} with no reason"
        )
        assert " ".join(command.reason.split()) in " ".join(result.stderr.split()), said


def test_the_readme_examples_on_real_data_are_run():
    """The README's lines on the shared clouds are runnable as written, not skipped as synopses."""
    readme = [c for c in ALL if c.document == "README.md"]
    on_real_data = [c for c in readme if any(w.startswith("../shared/data/") for w in c.words)]
    assert len(on_real_data) >= 3 and all(c.runnable for c in on_real_data), on_real_data
    assert {c.words[1] for c in readme if c.runnable} >= {"robots", "robot", "segment", "place", "scene"}


def test_every_refusal_in_the_docs_says_why():
    refusals = [c for c in ALL if c.exit_code != 0]
    assert refusals and all(c.reason for c in refusals), [c for c in refusals if not c.reason]
