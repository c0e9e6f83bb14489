"""The service's lanes: threads that run jobs with each client served in turn (issue 28, fairness).

A :class:`FairLane` is an executor whose queue is split by client (the peer's address): its
threads take the first job of the next client in turn (round robin), so a client with many
jobs waiting delays another client's job by at most one of its own, not by all of them. How
many jobs a lane and a client may hold is the app's to decide (:mod:`baseplace.serve.app`);
the lane only orders them.
"""

from __future__ import annotations

import threading
from collections import OrderedDict, deque
from collections.abc import Callable
from concurrent.futures import Executor, Future
from typing import Any


class FairLane(Executor):
    """``workers`` daemon threads running submitted jobs, one client's next job after another's.

    Daemon threads: a job that does not stop at its deadline check is left to the process's exit.
    """

    def __init__(
        self,
        name: str,
        workers: int = 1,
        initializer: Callable[..., Any] | None = None,
        initargs: tuple[Any, ...] = (),
    ) -> None:
        self._waiting: OrderedDict[str, deque[tuple[Future[Any], Callable[[], Any]]]] = OrderedDict()
        self._ready = threading.Condition()
        self._closed = False
        self._initializer, self._initargs = initializer, initargs
        self.threads = [
            threading.Thread(target=self._work, name=f"baseplace-{name}-{k}", daemon=True)
            for k in range(workers)
        ]
        for thread in self.threads:
            thread.start()

    def submit_for(self, client: str, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        """Queue ``fn(*args, **kwargs)`` as ``client``'s job, behind its earlier ones."""
        future: Future[Any] = Future()
        with self._ready:
            if self._closed:
                raise RuntimeError("the lane is shut down")
            self._waiting.setdefault(client, deque()).append((future, lambda: fn(*args, **kwargs)))
            self._ready.notify()
        return future

    def submit(self, fn: Callable[..., Any], /, *args: Any, **kwargs: Any) -> Future[Any]:
        """Queue ``fn(*args, **kwargs)`` for no client in particular (the service's own work)."""
        return self.submit_for("", fn, *args, **kwargs)

    def waiting(self) -> int:
        """Jobs queued and not started."""
        with self._ready:
            return sum(len(q) for q in self._waiting.values())

    def shutdown(self, wait: bool = True, *, cancel_futures: bool = False) -> None:
        """No new jobs; with ``cancel_futures`` the queued ones are cancelled; with ``wait`` the threads joined."""
        with self._ready:
            self._closed = True
            if cancel_futures:
                for queue in self._waiting.values():
                    for future, _ in queue:
                        future.cancel()
                self._waiting.clear()
            self._ready.notify_all()
        if wait:
            for thread in self.threads:
                thread.join()

    def _next(self) -> tuple[Future[Any], Callable[[], Any]] | None:
        """The next client's first job (that client then goes last), or None once shut down and empty."""
        with self._ready:
            while not self._waiting:
                if self._closed:
                    return None
                self._ready.wait()
            client, queue = self._waiting.popitem(last=False)
            job = queue.popleft()
            if queue:
                self._waiting[client] = queue  # back in line, after every other client
            return job

    def _work(self) -> None:
        if self._initializer is not None:
            self._initializer(*self._initargs)
        while (job := self._next()) is not None:
            future, fn = job
            if not future.set_running_or_notify_cancel():
                continue
            try:
                result = fn()
            except BaseException as exc:  # the job's failure is its caller's to see
                future.set_exception(exc)
            else:
                future.set_result(result)
