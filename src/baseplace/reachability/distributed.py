"""Map builds spread over a dask.distributed cluster: the same map as :func:`build_map`, faster.

The chunks of a build (``build.py``: chunk ``k`` drawn from ``default_rng([seed, k])``) are split
into contiguous runs, about four tasks per worker. Each task builds its robot from the spec (a
built-in name or a robot file that every worker can read at the same path), runs a
:class:`~baseplace.reachability.sampling.MapAccumulator` over its chunks and returns the sparse
:class:`~baseplace.reachability.build.PartialMap`; the client adds the partials up. Counts are
integers and manipulability is a max, so the map is identical to the single-process one whatever
the number of workers, the task split or the order tasks finish in; only ``build_time_s`` differs.

Workers: one task at a time runs in a worker process, and its numba kernels use the worker
host's cores divided by the number of workers on that host (a ``LocalCluster`` of one process
per core gives one thread each). The compiled FK kernels come from the kernel cache
(``$BASEPLACE_CACHE`` or ``~/.cache/baseplace``) of each worker's machine; the first task on a
machine with a cold cache compiles them (tens of seconds). Each worker checks that its URDF has
the SHA-256 the client's has.

Connecting (:func:`connect`): ``None`` or ``"local"`` starts a ``LocalCluster`` of one
single-threaded process per core on this machine; ``"tcp://host:port"`` (or ``host:port``,
``tls://...``) connects to a running scheduler (``dask scheduler`` plus ``dask worker
tcp://host:port`` on each machine); a path to a ``.json`` file is a ``--scheduler-file``.
"""

from __future__ import annotations

import asyncio
import contextlib
import os
import re
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numba as nb
import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError
from baseplace.reachability.build import DEFAULT_CHECKPOINT_EVERY
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.reachability.sampling import MapAccumulator, PartialMap
from baseplace.reachability.settings import BuildSettings
from baseplace.robots.model import Robot

if TYPE_CHECKING:
    from distributed import Client, Future

LOCAL = "local"
TASKS_PER_WORKER = 4
_ADDRESS = re.compile(r"^(?:(?:tcp|tls|ws|wss|ucx)://)?(?:\[[0-9a-fA-F:]+\]|[A-Za-z0-9_.-]+):\d{1,5}$")
_POLL_S = 0.2  # how often the client looks for finished tasks (and for Ctrl-C)


def connect(scheduler: str | None = LOCAL, n_workers: int | None = None, timeout_s: float = 10.0) -> Client:
    """A dask client for a map build; close it (or use it in ``with``) when done.

    Args:
        scheduler: None or "local": a new ``LocalCluster`` on this machine, ``n_workers``
            processes (default: one per usable core) of one thread each, no dashboard; it shuts
            down with the client. "tcp://host:port", "host:port", "tls://host:port": a running
            scheduler. A path to an existing ``.json`` file: a scheduler file
            (``dask scheduler --scheduler-file``).
        n_workers: processes of a local cluster (ignored for a remote scheduler).
        timeout_s: how long to try to reach a remote scheduler [s].

    Returns:
        The connected client.

    Raises:
        InputError: ``scheduler`` is neither "local", an address nor a scheduler file, the
            scheduler cannot be reached within ``timeout_s``, or ``n_workers`` < 1.
    """
    from distributed import Client

    if scheduler is None or scheduler == LOCAL:
        n = _usable_cpus() if n_workers is None else int(n_workers)
        if n < 1:
            raise InputError(f"number of local workers must be at least 1, got {n_workers}")
        return Client(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=None)
    text = scheduler.strip()
    kwargs: dict[str, str] = {}
    if text.endswith(".json") and Path(text).is_file():
        kwargs["scheduler_file"] = text
    elif _ADDRESS.match(text):
        kwargs["address"] = text if "://" in text else f"tcp://{text}"
    else:
        raise InputError(
            f"scheduler must be 'local', an address like tcp://host:8786 or a scheduler .json file, "
            f"got {scheduler!r}"
        )
    try:
        return Client(**kwargs, timeout=timeout_s)
    except (OSError, TimeoutError) as exc:
        raise InputError(
            f"cannot connect to dask scheduler {text} within {timeout_s:g} s "
            f"({type(exc).__name__}); is `dask scheduler` running there?"
        ) from None


def _usable_cpus() -> int:
    """Cores this process may run on (the affinity mask, where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def _numba_threads(client: Client) -> dict[str, int]:
    """Numba threads per worker address: the host's cores shared among the workers on it."""
    workers = client.scheduler_info(n_workers=-1)["workers"]
    cpus = client.run(_usable_cpus)
    per_host: dict[str, int] = {}
    for info in workers.values():
        per_host[info["host"]] = per_host.get(info["host"], 0) + 1
    return {
        address: max(1, int(cpus.get(address, 1)) // per_host[info["host"]])
        for address, info in workers.items()
    }


def _wait_for_workers(client: Client, timeout_s: float) -> int:
    workers = client.scheduler_info(n_workers=-1)["workers"]
    if not workers:
        try:
            client.wait_for_workers(1, timeout=timeout_s)
        except (TimeoutError, OSError):
            address = getattr(client.scheduler, "address", "")
            raise InputError(
                f"dask scheduler {address} has no workers after {timeout_s:g} s; "
                "start some with `dask worker ADDRESS`"
            ) from None
        workers = client.scheduler_info(n_workers=-1)["workers"]
    return len(workers)


LOST_TIMEOUT_S = 20.0
MAX_RESUBMITS = 3
_HEALTH_EVERY_S = 2.0
_IDENTITY_TIMEOUT_S = 5.0
_RESULT_TIMEOUT_S = 5.0


def _lost_errors() -> tuple[type[BaseException], ...]:
    from distributed.comm.core import CommClosedError

    return (OSError, CommClosedError, asyncio.CancelledError)


def _killed_errors() -> tuple[type[BaseException], ...]:
    from distributed.scheduler import KilledWorker

    return (KilledWorker,)


class _ClusterHealth:
    """Asks the scheduler, at most every 2 s and with a deadline, whether the build can go on."""

    def __init__(self, client: Client, lost_timeout_s: float) -> None:
        self.client = client
        self.lost_timeout_s = lost_timeout_s
        self.address = getattr(client.scheduler, "address", "")
        self._last_check = time.monotonic()
        self._no_workers_since: float | None = None
        self._unreachable_since: float | None = None

    def progressed(self) -> None:
        self._no_workers_since = self._unreachable_since = None

    def check(self) -> str | None:
        """None while the build can go on, else why it cannot (one line)."""
        now = time.monotonic()
        if now - self._last_check < _HEALTH_EVERY_S:
            return None
        self._last_check = now
        try:
            scheduler: Any = self.client.scheduler
            identity = self.client.sync(
                scheduler.identity, n_workers=-1, callback_timeout=_IDENTITY_TIMEOUT_S
            )
            workers = len(identity.get("workers", {}))
            self._unreachable_since = None
        except Exception:  # unreachable, closed, timed out: all mean no answer
            self._unreachable_since = self._unreachable_since or now
            if now - self._unreachable_since >= self.lost_timeout_s or self.client.status == "closed":
                return f"lost the dask scheduler {self.address} (no answer for {now - self._unreachable_since:.0f} s)"
            return None
        if workers:
            self._no_workers_since = None
            return None
        self._no_workers_since = self._no_workers_since or now
        if now - self._no_workers_since >= self.lost_timeout_s:
            return f"every dask worker of {self.address} was lost (none for {self.lost_timeout_s:g} s)"
        return None


# One build task at a time per worker process: numba's parallel kernels already use the cores
# given to the process, and workers started with several threads must not oversubscribe them.
_TASK_LOCK = threading.Lock()
_ROBOTS: dict[str, Robot] = {}


def _worker_robot(robot_spec: str) -> Robot:
    if robot_spec not in _ROBOTS:
        _ROBOTS[robot_spec] = Robot(robot_spec)
    return _ROBOTS[robot_spec]


def build_chunks(
    robot_spec: str,
    urdf_sha256: str,
    arm_name: str,
    settings: BuildSettings,
    chunks: NDArray[np.int64],
    numba_threads: dict[str, int] | None = None,
) -> PartialMap:
    """One task of a distributed build (it runs on a worker): the partial map of ``chunks``.

    Args:
        robot_spec: built-in robot name or absolute path of a robot file.
        urdf_sha256: SHA-256 the robot's URDF must have (the client's).
        arm_name: the arm.
        settings: build settings.
        chunks: (C,) sorted chunk indices.
        numba_threads: numba threads per worker address (see module docstring), or None.

    Returns:
        The partial map of the chunks.

    Raises:
        InputError: this worker's URDF differs from the client's.
    """
    with _TASK_LOCK:
        threads = _threads_here(numba_threads)
        if threads is not None:
            nb.set_num_threads(min(threads, nb.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]
        robot = _worker_robot(robot_spec)
        if robot.spec.urdf_sha256 != urdf_sha256:  # the files may have changed since it was cached
            del _ROBOTS[robot_spec]
            robot = _worker_robot(robot_spec)
        if robot.spec.urdf_sha256 != urdf_sha256:
            raise InputError(
                f"a worker's URDF of robot {robot.name!r} differs from the client's "
                f"(sha256 {robot.spec.urdf_sha256[:12]} != {urdf_sha256[:12]}); "
                "give every machine the same robot files"
            )
        acc = MapAccumulator(robot, arm_name, settings)
        for k in chunks:
            acc.add_chunk(int(k))
        return acc.partial()


def _threads_here(numba_threads: dict[str, int] | None) -> int | None:
    if not numba_threads:
        return None
    try:
        from distributed import get_worker

        return numba_threads.get(get_worker().address)
    except ValueError:  # not running in a worker
        return None


def shard_chunks(chunks: NDArray[np.int64], n_tasks: int) -> list[NDArray[np.int64]]:
    """Split sorted chunk indices into at most ``n_tasks`` contiguous, near-equal, non-empty runs."""
    n = max(1, min(n_tasks, len(chunks)))
    return [part for part in np.array_split(chunks, n) if len(part)]


def build_map_distributed(
    robot_spec: str | Path,
    arm_name: str | None,
    settings: BuildSettings | None,
    client: Client,
    progress: Callable[[int], None] | None = None,
    checkpoint: str | Path | None = None,
    checkpoint_every: int = DEFAULT_CHECKPOINT_EVERY,
    tasks_per_worker: int = TASKS_PER_WORKER,
    worker_timeout_s: float = 60.0,
    save_to: str | Path | None = None,
    lost_timeout_s: float = LOST_TIMEOUT_S,
) -> ReachabilityMap:
    """Build a reachability map on a dask cluster; identical to :func:`build_map`'s map.

    Args:
        robot_spec: built-in robot name or robot file path; every worker loads the robot itself
            (a path is made absolute, and must be readable at that path on every machine).
        arm_name: which arm (the robot's default arm if None).
        settings: build settings (defaults as :func:`build_map`).
        client: a connected client (:func:`connect`).
        progress: called with the number of samples done after each finished task.
        checkpoint: checkpoint file, or None; as :func:`build_map` (tasks finish out of order,
            so a checkpoint holds the set of finished chunks; resuming runs only the others,
            and the file may be resumed by :func:`build_map` or by this function).
        checkpoint_every: samples between checkpoints, rounded up to whole chunks; saved when a
            finished task brings the unsaved chunks to it.
        tasks_per_worker: tasks per worker (more: finer progress and checkpoints, more overhead).
        worker_timeout_s: how long to wait for a first worker if the cluster has none [s].
        save_to: map file written before the checkpoint is removed (as :func:`build_map`).
        lost_timeout_s: how long the cluster may have no worker, or the scheduler be
            unreachable, before the build gives up [s]; it then saves a final checkpoint.

    Faults: a task whose worker dies is rescheduled by dask on another worker; one that dask
    gives up on (``KilledWorker``, lost) is submitted again, up to :data:`MAX_RESUBMITS` times.
    Every wait is bounded: the client polls, and every 2 s asks the scheduler (5 s deadline) how
    many workers it has.

    Returns:
        The map; ``info.build_time_s`` is the client's wall time (summed over resumed runs).

    Raises:
        InputError: unknown robot or arm, a worker's URDF differs, the cluster has no workers,
            every worker or the scheduler was lost for ``lost_timeout_s`` (with ``checkpoint``,
            after a final checkpoint the message names), or (with ``checkpoint``) as
            :func:`build_map`.
        KeyboardInterrupt: Ctrl-C; the tasks are cancelled (after a final checkpoint, if any).
    """
    from distributed import wait

    settings = settings or BuildSettings()
    spec = str(Path(robot_spec).resolve()) if Path(robot_spec).is_file() else str(robot_spec)
    robot = Robot(spec)
    acc = MapAccumulator(robot, arm_name, settings)  # checks the arm; the client adds the partials
    start = time.perf_counter()
    saver = None
    if checkpoint is not None:
        from baseplace.reachability.checkpoint import Checkpoints

        saver = Checkpoints(acc, checkpoint, checkpoint_every)
        if progress is not None and saver.resumed_chunks:
            progress(acc.samples_done)
    n_workers = _wait_for_workers(client, worker_timeout_s)
    threads = _numba_threads(client)
    shards = shard_chunks(acc.pending_chunks(), max(1, tasks_per_worker) * n_workers)
    futures: list[Future] = [
        client.submit(
            build_chunks, spec, robot.spec.urdf_sha256, acc.arm.name, settings, part, threads, pure=False
        )
        for part in shards
    ]
    shard_of = dict(zip(futures, shards, strict=True))
    resubmits = dict.fromkeys(futures, 0)
    remaining = set(futures)
    health = _ClusterHealth(client, lost_timeout_s)
    _LOST_ERRORS, _KILLED_ERRORS = _lost_errors(), _killed_errors()

    def give_up(why: str) -> InputError:
        saved = ""
        if saver is not None:
            with contextlib.suppress(Exception):
                saver.save()
            saved = (
                f"; progress ({acc.samples_done} of {settings.samples} samples) saved in {saver.path}: "
                "rerun the same command to resume"
            )
        return InputError(f"{why}{saved}")

    try:
        with saver if saver is not None else contextlib.nullcontext():
            while remaining:
                try:
                    done, _ = wait(list(remaining), timeout=_POLL_S, return_when="FIRST_COMPLETED")
                except TimeoutError:
                    done = set()
                except _LOST_ERRORS:
                    raise give_up(f"lost the dask scheduler {health.address}") from None
                for future in done:
                    try:
                        # re-raises a task's error here; bounded, since a result whose worker died
                        # after finishing is computed again and would block the wait until then
                        part = future.result(timeout=_RESULT_TIMEOUT_S)
                    except TimeoutError:
                        continue  # dask reschedules it; it comes back as done, or the health check ends it
                    except _KILLED_ERRORS:
                        # the task's workers died (KilledWorker) or it was lost: run its chunks again
                        if resubmits[future] >= MAX_RESUBMITS:
                            raise give_up(
                                f"a build task was lost with its dask worker {MAX_RESUBMITS + 1} times"
                            ) from None
                        again = client.submit(build_chunks, spec, robot.spec.urdf_sha256, acc.arm.name, settings,
                                              shard_of[future], threads, pure=False)  # fmt: skip
                        shard_of[again], resubmits[again] = shard_of[future], resubmits[future] + 1
                        remaining.discard(future)
                        remaining.add(again)
                        continue
                    except _LOST_ERRORS:
                        raise give_up(f"lost the dask scheduler {health.address}") from None
                    remaining.discard(future)
                    future.release()
                    acc.merge(part)
                    health.progressed()
                    if progress is not None:
                        progress(acc.samples_done)
                    if saver is not None:
                        saver.added(len(part.chunks))
                if saver is not None:
                    saver.check_interrupt()
                problem = health.check()
                if problem is not None:
                    raise give_up(problem)
            if saver is not None:
                return saver.finish(save_to)
    finally:
        if remaining and client.status == "running":
            with contextlib.suppress(Exception):
                client.cancel(list(remaining))
    rmap = acc.result(time.perf_counter() - start)
    if save_to is not None:
        from baseplace.reachability.storage import save_map

        save_map(rmap, save_to)
    return rmap
