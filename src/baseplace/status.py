"""A status line for steps that run longer than 2 s without a progress bar of their own.

Map builds and experiments report their progress through tqdm bars. Every other step (the first
run's kernel compilation, a placement search, a planner running to its time limit) shows, after
2 s, one line with the command and the elapsed time on a terminal's stderr, which gives way to
any real progress bar while that one runs. Nothing is printed when stderr is not a terminal (logs,
tests, pipes) or with ``--json``.
"""

from __future__ import annotations

import contextlib
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import Any

Progress = Callable[[str, int, int], None]
"""A job's progress callback: ``progress(step, done, total)``; ``step`` names a long step."""

QUIET_FOR = 2.0
"""Seconds a step may run before the status line appears."""
REFRESH = 0.5
"""Seconds between updates of the elapsed time."""


@contextlib.contextmanager
def elapsed_status(label: str, enabled: bool = True, stream: Any = None) -> Iterator[None]:
    """Show ``label: working, MM:SS`` on ``stream`` (default stderr) while the block runs past 2 s.

    Args:
        label: what runs, e.g. ``"baseplace place"``.
        enabled: False shows nothing (``--json``).
        stream: where to write; shown only if it is a terminal.
    """
    out = sys.stderr if stream is None else stream
    if not enabled or not getattr(out, "isatty", lambda: False)():
        yield
        return
    from tqdm import tqdm

    stop = threading.Event()
    started = time.time()

    def run() -> None:
        if stop.wait(QUIET_FOR):
            return
        bar: Any = None
        while True:
            others = [b for b in list(tqdm._instances) if b is not bar]
            if others and bar is not None:  # a real progress bar is running: give way to it
                bar.close()
                bar = None
            elif not others and bar is None:
                bar = tqdm(
                    total=None, desc=label, bar_format="{desc}: working, {elapsed}", file=out, leave=False
                )
                bar.start_t = started  # the time since the command started
            elif bar is not None:
                bar.refresh()
            if stop.wait(REFRESH):
                break
        if bar is not None:
            bar.close()

    thread = threading.Thread(target=run, name="baseplace-status", daemon=True)
    thread.start()
    try:
        yield
    finally:
        stop.set()
        thread.join()


class ProgressBars:
    """A job's progress callback (``progress(step, done, total)``) shown as one tqdm bar per step on stderr.

    A step's bar appears on its first update; nothing is shown when ``enabled`` is False (``--json``)
    or when the stream is not a terminal (a redirected stderr: a log gets no bars).
    """

    def __init__(self, enabled: bool = True, stream: Any = None) -> None:
        self.enabled, self.stream, self.bars = enabled, stream, dict[str, Any]()
        self.units: dict[str, str] = {}

    def __call__(self, step: str, done: int, total: int) -> None:
        """``done`` of ``total`` samples of ``step`` are done."""
        if not self.enabled:
            return
        if step not in self.bars:
            from tqdm import tqdm

            out = sys.stderr if self.stream is None else self.stream
            if not getattr(out, "isatty", lambda: False)():
                return
            unit = self.units.get(step, "samples")
            self.bars[step] = tqdm(
                total=total, desc=step, unit=unit, unit_scale=unit == "samples", file=out, leave=False
            )
        self.bars[step].update(done - self.bars[step].n)

    def counter(self, step: str, total: int, unit: str = "steps") -> Callable[[int], None]:
        """The callback ``count(k)`` of a loop that reports ``k`` more of ``total`` done in ``step``."""
        self.units[step] = unit
        done = 0

        def count(k: int) -> None:
            nonlocal done
            done += k
            self(step, done, total)

        return count

    def __enter__(self) -> ProgressBars:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def close(self) -> None:
        """Close every bar."""
        for bar in self.bars.values():
            bar.close()
        self.bars.clear()


def step_progress(progress: Progress | None, step: str, total: int) -> Callable[[int], None] | None:
    """The one-argument callback (samples done) of one step, or None without ``progress``."""
    if progress is None:
        return None
    return lambda done: progress(step, done, total)


def map_step(robot_name: str, arm: str) -> str:
    """The progress step of building one arm's reachability map: one bar per map, named by its arm."""
    return f"reachability map, {robot_name} {arm if arm.endswith('arm') else arm + ' arm'}"
