"""A time limit that long jobs check at their loop boundaries (the service's requests, issue 28).

A Python thread cannot be stopped from outside, so a job past its time limit stops itself: the
service runs each job under a :class:`Deadline` (:func:`limited`), and the placement loops call
:func:`check` between candidates, error draws and targets. Outside a limit (the CLI, the
library) :func:`check` costs one context-variable read and never raises.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field


class DeadlineExceeded(Exception):
    """The job ran past its time limit or was cancelled.

    Not a :class:`~baseplace.errors.BaseplaceError`: no job turns it into a report; it ends the
    job and the front end that set the limit answers for it.
    """


@dataclass(eq=False)  # compared and hashed by identity: the service keeps a set of them
class Deadline:
    """When a job must stop: ``at`` on :func:`time.monotonic`'s clock [s], or earlier if cancelled."""

    at: float
    cancelled: threading.Event = field(default_factory=threading.Event)

    @classmethod
    def after(cls, seconds: float) -> Deadline:
        """A deadline ``seconds`` from now [s]."""
        return cls(time.monotonic() + seconds)

    def cancel(self) -> None:
        """Stop the job at its next check (a request answered 504, a client gone, a shutdown)."""
        self.cancelled.set()

    def expired(self) -> bool:
        """True once the time is up or the job was cancelled."""
        return self.cancelled.is_set() or time.monotonic() >= self.at


_current: ContextVar[Deadline | None] = ContextVar("baseplace_deadline", default=None)


def check() -> None:
    """Raise :class:`DeadlineExceeded` if the job running in this context is past its deadline."""
    if expired():
        raise DeadlineExceeded("the job ran past its time limit")


def active() -> bool:
    """True when the code running in this context runs under a deadline."""
    return _current.get() is not None


def expired() -> bool:
    """True when the job running in this context is past its deadline (False outside one)."""
    deadline = _current.get()
    return deadline is not None and deadline.expired()


@contextmanager
def limited(deadline: Deadline) -> Iterator[Deadline]:
    """Run the block under ``deadline`` (checked on entry and by every :func:`check` inside)."""
    token = _current.set(deadline)
    try:
        check()
        yield deadline
    finally:
        _current.reset(token)
