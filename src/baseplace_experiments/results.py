"""Results files written whole by the command that makes them.

Every experiment and benchmark stores its result through :func:`write_results`: one JSON object
holding the result and, under ``"provenance"``, what made it: the command line, the git commit of
the source (and whether the work tree had uncommitted changes), the seeds (development and
held-out, and which of them this run used), the protocol fixed before the run, the wall time
and the UTC time it finished. The file is replaced atomically, so it is never half-written and
never edited by hand; the docs' tables are read from these files.

"Dirty" means the run's code differs from its commit: a tracked file changed anywhere but in
``bench/results`` and ``docs``, or an untracked file under ``src`` or ``bench`` (a new module
imports as well as a changed one); the paths are listed under ``dirty_paths``.

Each experiment names its protocol file (``docs/protocols/<experiment>.md``: scenes, counts, seeds,
success, what may touch what, the analysis). The rule for held-out seeds (:func:`fixed_protocol`):
the protocol file must be committed and unchanged in the work tree when the run starts and when
its results are written; the run records the last commit that changed the file, so the protocol
provably predates the results. A held-out run that breaks the rule, or that names no protocol
file, is refused with a one-line :class:`~baseplace.errors.InputError` before any work.
"""

from __future__ import annotations

import json
import math
import os
import platform
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from baseplace.errors import InputError
from baseplace.files import atomic_write

SPLITS = ("dev", "held-out")
"""Seed sets: ``dev`` chooses parameters, ``held-out`` gives the reported tables."""


@dataclass(frozen=True)
class SeedSplit:
    """The development and held-out seeds of one experiment, fixed before any held-out run.

    Attributes:
        dev: seeds used to choose parameters (and to debug); never reported as the result.
        held_out: seeds disjoint from ``dev`` that give the reported tables.
    """

    dev: tuple[int, ...]
    held_out: tuple[int, ...]

    def __post_init__(self) -> None:
        if not self.dev or not self.held_out:
            raise InputError("a seed split needs at least one development and one held-out seed")
        if set(self.dev) & set(self.held_out):
            raise InputError(
                f"development and held-out seeds overlap: {sorted(set(self.dev) & set(self.held_out))}"
            )

    def seeds(self, split: str) -> tuple[int, ...]:
        """The seeds of ``split`` ("dev" or "held-out")."""
        if split not in SPLITS:
            raise InputError(f"unknown split {split!r}; valid: {', '.join(SPLITS)}")
        return self.dev if split == "dev" else self.held_out


def _git(cwd: Path, *args: str) -> str:
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=10,
                          check=True).stdout  # fmt: skip


def _source_dir() -> Path:
    return Path(__file__).resolve().parent


def git_commit(where: Path | None = None) -> dict[str, Any]:
    """The commit of the source tree ``where`` (default: this package's) and whether its code is dirty.

    Dirty (see the module docstring) counts untracked files under ``src`` and ``bench`` too.
    Returns ``{"commit": None, "dirty": None}`` outside a git work tree (an installed package).
    """
    cwd = where or _source_dir()
    try:
        head = _git(cwd, "rev-parse", "HEAD").strip()
        top = Path(_git(cwd, "rev-parse", "--show-toplevel").strip())
        # results files and docs being rewritten do not count: they are outputs, not code
        tracked = _git(
            top, "status", "--porcelain", "--untracked-files=no", "--", ".", ":!bench/results", ":!docs"
        )
        untracked = _git(
            top, "ls-files", "--others", "--exclude-standard", "--", "src", "bench", ":!bench/results"
        )
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    paths = [line[3:] for line in tracked.splitlines() if line.strip()] + untracked.split()
    out: dict[str, Any] = {"commit": head, "dirty": bool(paths)}
    if paths:
        out["dirty_paths"] = sorted(paths)[:MAX_DIRTY_PATHS]
    return out


MAX_DIRTY_PATHS = 20
"""At most this many dirty paths are listed in a results file (``dirty`` says whether there are any)."""


@dataclass(frozen=True)
class ProtocolRecord:
    """The protocol file a run follows, as the run found it.

    Attributes:
        file: path relative to the repository's top (``docs/protocols/<experiment>.md``).
        commit: the last commit that changed the file; None when it was never committed or there is no git.
        clean: True when the work tree's file is the committed one (no staged or unstaged change).
    """

    file: str
    commit: str | None
    clean: bool
    root: Path | None = field(default=None, repr=False)
    """The repository's top on this machine: where the file is checked again, never stored."""

    def as_dict(self) -> dict[str, Any]:
        """The record as stored under ``provenance.protocol_file``."""
        return {"file": self.file, "commit": self.commit, "clean": self.clean}


def protocol_record(file: str, where: Path | None = None) -> ProtocolRecord:
    """The state of protocol ``file`` (relative to the top of the repository holding ``where``)."""
    cwd = where or _source_dir()
    try:
        top = Path(_git(cwd, "rev-parse", "--show-toplevel").strip())
        if not (top / file).is_file():
            return ProtocolRecord(file, None, False, top)
        commit = _git(top, "log", "-1", "--format=%H", "--", file).strip() or None
        changed = _git(top, "status", "--porcelain", "--untracked-files=all", "--", file).strip()
    except (OSError, subprocess.SubprocessError):
        return ProtocolRecord(file, None, False)
    return ProtocolRecord(file, commit, commit is not None and not changed, top)


def fixed_protocol(file: str | None, split: str | None, where: Path | None = None) -> ProtocolRecord | None:
    """The protocol record of a run, checked before the run's work (the rule in the module docstring).

    Args:
        file: the experiment's protocol file, relative to the repository's top; None for none.
        split: the run's seed set ("dev", "held-out", or None for a custom seed).
        where: a folder inside the repository (default: this package's).

    Raises:
        InputError: a held-out run without a protocol file, or whose file is missing, uncommitted or changed.
    """
    if file is None:
        if split == "held-out":
            raise InputError(
                "a held-out run needs its protocol file (docs/protocols/<experiment>.md); none was named"
            )
        return None
    record = protocol_record(file, where)
    if split == "held-out" and not record.clean:
        state = (
            "is not in a git work tree or not committed"
            if record.commit is None
            else "has uncommitted changes"
        )
        raise InputError(
            f"protocol file {file} {state}: commit it before a held-out run, or run the dev split"
        )
    return record


@dataclass
class RunClock:
    """Wall time and source commit of a run, taken when the command starts (before any work).

    The commit is read at the start: the code that runs is the code imported then, whatever
    changes in the work tree while it runs.
    """

    started: float = field(default_factory=time.perf_counter)
    source: dict[str, Any] = field(default_factory=lambda: git_commit())

    @property
    def seconds(self) -> float:
        """Seconds since the start [s]."""
        return time.perf_counter() - self.started


def _without_folders(arg: str) -> str:
    """A command-line argument with an absolute path cut to its file name (``--x=/a/b`` too).

    Results files are committed: the folders of the machine that ran them are not theirs to record.
    """
    key, eq, value = arg.partition("=") if arg.startswith("-") else ("", "", arg)
    if os.path.isabs(value):
        value = Path(value).name
    return f"{key}{eq}{value}" if eq else (Path(arg).name if os.path.isabs(arg) else arg)


def provenance(
    clock: RunClock,
    *,
    seeds: SeedSplit | None = None,
    split: str | None = None,
    used_seeds: Sequence[int] | None = None,
    protocol: str | Sequence[str] | None = None,
    protocol_file: ProtocolRecord | None = None,
    argv: Sequence[str] | None = None,
) -> dict[str, Any]:
    """The provenance block of a results file (see the module docstring).

    Args:
        clock: started when the command started; its time so far is the run's wall time.
        seeds: the experiment's development and held-out seeds.
        split: which of them this run used ("dev", "held-out"), None for a custom seed.
        used_seeds: the seeds this run actually used.
        protocol: the protocol's text or settings, as the run used them.
        protocol_file: the record :func:`fixed_protocol` returned when the run started; checked again
            here, so a protocol changed during a held-out run is refused.
        argv: the command line (default ``sys.argv``).
    """
    if split == "held-out":  # a held-out run's protocol: checked again now, as when it started
        pf = protocol_file
        now = fixed_protocol(None if pf is None else pf.file, split, None if pf is None else pf.root)
        if pf is not None and now != pf:
            raise InputError(f"protocol file {pf.file} changed during the run; the results are not written")
    args = list(sys.argv if argv is None else argv)
    args = [Path(args[0]).name, *(_without_folders(a) for a in args[1:])] if args else []
    out: dict[str, Any] = {
        "command": " ".join(args),
        **clock.source,
        "python": platform.python_version(),
        "machine": f"{platform.machine()} {platform.processor() or ''}".strip(),
        "finished_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "wall_time_s": round(clock.seconds, 1),
    }
    if seeds is not None:
        out["seeds"] = {"dev": list(seeds.dev), "held_out": list(seeds.held_out)}
    out["split"] = split
    if used_seeds is not None:
        out["seeds_used"] = [int(s) for s in used_seeds]
    if protocol is not None:
        out["protocol"] = [protocol] if isinstance(protocol, str) else list(protocol)
    if protocol_file is not None:
        out["protocol_file"] = protocol_file.as_dict()
    return out


def write_results(path: str | Path, result: dict[str, Any], clock: RunClock, **kwargs: Any) -> dict[str, Any]:
    """Write ``result`` with its :func:`provenance` (keyword arguments as there) to ``path``, atomically.

    Returns:
        The object written: ``result`` with a ``"provenance"`` entry added.
    """
    nulled = [0]
    whole = {**_finite(result, nulled), "provenance": provenance(clock, **kwargs)}
    if nulled[0]:
        whole["provenance"]["non_finite_written_as_null"] = nulled[0]
    text = json.dumps(whole, indent=1, allow_nan=False) + "\n"
    with atomic_write(path, "results file") as tmp:
        tmp.write_text(text)
    return whole


def _finite(value: Any, nulled: list[int]) -> Any:
    """``value`` with NaN and infinities as None (JSON has neither), counted in ``nulled[0]``."""
    if isinstance(value, float) and not math.isfinite(value):
        nulled[0] += 1
        return None
    if isinstance(value, dict):
        return {k: _finite(v, nulled) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v, nulled) for v in value]
    return value


__all__ = [
    "SPLITS",
    "ProtocolRecord",
    "RunClock",
    "SeedSplit",
    "fixed_protocol",
    "git_commit",
    "protocol_record",
    "provenance",
    "write_results",
]
