"""Run the CLI in a fresh process under a memory cap and measure its own peak resident memory.

Linux carries a process's peak resident size across ``fork`` + ``exec``: a CLI started straight
from the test process reports pytest's peak (a gigabyte late in the suite), not its own. So the
CLI is started by a small wrapper interpreter, and the figure is the wrapper's
``RUSAGE_CHILDREN`` ``ru_maxrss``, whose only child is the CLI.
"""

from __future__ import annotations

import os
import resource
import signal
import subprocess
import sys
import time
from pathlib import Path

SRC = str(Path(__file__).resolve().parents[1] / "src")
CAP_MB = 512
ADDRESS_SPACE = 3 << 30  # bytes: unchecked code's allocations fail here, not in the machine's memory

# starts the CLI as its only child, then prints that child's peak resident set (kB)
_WRAP = (
    "import resource, subprocess, sys; code = subprocess.call(sys.argv[1:]); "
    "print(resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss); sys.exit(code)"
)


def _limit_address_space() -> None:
    resource.setrlimit(resource.RLIMIT_AS, (ADDRESS_SPACE, ADDRESS_SPACE))


def capped_env(cwd: Path | None = None) -> dict[str, str]:
    """The environment of a capped CLI run: this checkout's sources, the cap, a cache under ``cwd``."""
    env = {
        **os.environ,
        "PYTHONPATH": os.environ.get("PYTHONPATH") or SRC,
        "BASEPLACE_MAX_MEMORY_MB": str(CAP_MB),
    }
    if cwd is not None:
        env["BASEPLACE_CACHE"] = str(cwd / "cache")
    return env


def cli_peak(*args: str, cwd: Path | None = None, timeout: float = 120) -> tuple[int, str, float, float]:
    """(exit code, stderr, seconds, peak resident MB) of ``baseplace ARGS`` under the cap."""
    command = [sys.executable, "-c", _WRAP, sys.executable, "-m", "baseplace.cli", *args]
    t0 = time.perf_counter()
    proc = subprocess.Popen(command, cwd=cwd, env=capped_env(cwd), text=True, stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=_limit_address_space,
                            start_new_session=True)  # fmt: skip
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the CLI too, which a blocked open would keep alive
        proc.communicate()
        raise
    return proc.returncode, err, time.perf_counter() - t0, int(out.strip().splitlines()[-1]) / 1024
