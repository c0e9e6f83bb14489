"""Results files written whole by the command that makes them.

Every experiment and benchmark stores its result through :func:`write_results`: one JSON object
holding the result and, under ``"provenance"``, what made it: the command line, the git commit of
the source (and whether the work tree had uncommitted changes), the seeds (development and
held-out, and which of them this run used), the protocol text fixed before the run, the wall time
and the UTC time it finished. The file is replaced atomically, so it is never half-written and
never edited by hand; the docs' tables are read from these files.
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


def git_commit(where: Path | None = None) -> dict[str, Any]:
    """The commit of the source tree ``where`` (default: this package's) and whether its code is dirty.

    Returns ``{"commit": None, ...}`` outside a git work tree (an installed package).
    """
    cwd = where or Path(__file__).resolve().parent

    def git(*args: str) -> str:
        return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, timeout=10,
                              check=True).stdout  # fmt: skip

    try:
        head = git("rev-parse", "HEAD").strip()
        top = git("rev-parse", "--show-toplevel").strip()
        # dirty: uncommitted changes to code; results files and docs being rewritten do not count
        status = git(
            "-C", top, "status", "--porcelain", "--untracked-files=no", "--", ".", ":!bench/results", ":!docs"
        )
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    return {"commit": head, "dirty": bool(status.strip())}


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
    argv: Sequence[str] | None = None,
) -> dict[str, Any]:
    """The provenance block of a results file (see the module docstring).

    Args:
        clock: started when the command started; its time so far is the run's wall time.
        seeds: the experiment's development and held-out seeds.
        split: which of them this run used ("dev", "held-out"), None for a custom seed.
        used_seeds: the seeds this run actually used.
        protocol: the protocol, written down before the held-out run.
        argv: the command line (default ``sys.argv``).
    """
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


__all__ = ["SPLITS", "RunClock", "SeedSplit", "git_commit", "provenance", "write_results"]
