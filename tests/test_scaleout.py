"""Scale-out builds: distributed (dask) and resumable (checkpoints) maps equal the plain build."""

from __future__ import annotations

import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.reachability.build import CHUNK, BuildSettings, MapAccumulator, build_map
from baseplace.reachability.checkpoint import default_checkpoint_path, load_checkpoint, save_checkpoint
from baseplace.reachability.distributed import build_map_distributed, connect, shard_chunks
from baseplace.reachability.rmap import MapInfo, ReachabilityMap
from baseplace.reachability.storage import save_map
from baseplace.robots.model import Robot

DATA = Path(__file__).parent / "data"
PLANAR3 = str(DATA / "planar3.toml")
SETTINGS = BuildSettings(samples=3 * CHUNK + 777, seed=5)  # 4 chunks, the last one short


def assert_same_map(a: ReachabilityMap, b: ReachabilityMap) -> None:
    """Everything equal but the build time."""
    assert a.grid == b.grid
    np.testing.assert_array_equal(a.cells, b.cells)
    np.testing.assert_array_equal(a.counts, b.counts)
    if a.manipulability is None or b.manipulability is None:
        assert a.manipulability is None and b.manipulability is None
    else:
        np.testing.assert_array_equal(a.manipulability, b.manipulability)
    assert untimed(a.info) == untimed(b.info)


def untimed(info: MapInfo) -> dict[str, object]:
    """The map's provenance without the wall times of its build and of its quality measurement."""
    fields = info.__dict__ | {"build_time_s": 0.0}
    if info.quality:
        fields["quality"] = {k: v for k, v in json.loads(info.quality).items() if k != "measure_time_s"}
    return fields


class Stop(Exception):
    """Raised from a progress callback to abandon a build part-way."""


def stop_after(samples: int):
    def progress(done: int) -> None:
        if done >= samples:
            raise Stop

    return progress


@pytest.fixture()
def ctrl_c():
    """Ctrl-C raising KeyboardInterrupt, as in a terminal, even where pytest was started with SIGINT
    ignored (a shell's background job): the build restores whatever handler it finds."""
    previous = signal.signal(signal.SIGINT, signal.default_int_handler)
    yield
    signal.signal(signal.SIGINT, previous)


@pytest.fixture(scope="module")
def reference(planar3: Robot) -> ReachabilityMap:
    return build_map(planar3, None, SETTINGS)


@pytest.fixture(scope="module")
def client():
    with connect("local", n_workers=2) as c:
        yield c


# -- distributed ---------------------------------------------------------------------------------


def test_two_workers_give_the_single_process_map(client, reference):
    for tasks in (4, 1):
        done: list[int] = []
        rmap = build_map_distributed(PLANAR3, None, SETTINGS, client, done.append, tasks_per_worker=tasks)
        assert_same_map(rmap, reference)
        assert len(done) == min(4, 2 * tasks) and done == sorted(done) and done[-1] == SETTINGS.samples


def test_two_workers_tiago_and_manipulability(client, tiago, planar3):
    s = BuildSettings(samples=3_000_000, seed=7)
    assert_same_map(build_map_distributed("tiago", "arm", s, client), build_map(tiago, "arm", s))
    m = BuildSettings(samples=CHUNK + 60_000, seed=2, manipulability=True)
    assert_same_map(build_map_distributed(Path(PLANAR3), None, m, client), build_map(planar3, None, m))


def test_distributed_build_checks_robot_and_arm_on_the_client(client):
    with pytest.raises(InputError, match="unknown arm"):
        build_map_distributed(PLANAR3, "nope", SETTINGS, client)
    with pytest.raises(InputError, match="unknown robot"):
        build_map_distributed("no_such_robot", None, SETTINGS, client)


def test_distributed_build_resumes_and_interrupts_with_checkpoints(
    client, planar3, reference, tmp_path, ctrl_c
):
    ckpt = tmp_path / "map.h5.partial"
    with pytest.raises(Stop):  # a local build leaves chunks 0-1
        build_map(planar3, None, SETTINGS, stop_after(3 * CHUNK), checkpoint=ckpt, checkpoint_every=1)

    def interrupt(done: int) -> None:  # Ctrl-C once the first task (chunk 2 or 3) is in
        if done > 2 * CHUNK:
            signal.raise_signal(signal.SIGINT)

    with pytest.raises(KeyboardInterrupt):
        build_map_distributed(PLANAR3, None, SETTINGS, client, interrupt, checkpoint=ckpt, tasks_per_worker=1)
    acc = MapAccumulator(planar3, None, SETTINGS)
    load_checkpoint(ckpt, acc)  # chunks 0, 1 and one of 2, 3: not necessarily a prefix
    assert acc.done.sum() == 3 and acc.done[:2].all()
    assert_same_map(build_map(planar3, None, SETTINGS, checkpoint=ckpt), reference)
    assert not ckpt.exists()


def test_shards_are_contiguous_and_cover_every_chunk():
    chunks = np.arange(10, dtype=np.int64)
    for n in (1, 3, 10, 50):
        parts = shard_chunks(chunks, n)
        assert len(parts) == min(n, 10)
        np.testing.assert_array_equal(np.concatenate(parts), chunks)


def test_connect_rejects_bad_addresses():
    with pytest.raises(InputError, match="scheduler must be 'local'"):
        connect("not an address")
    start = time.perf_counter()
    with pytest.raises(InputError, match=r"cannot connect to dask scheduler tcp://127\.0\.0\.1:9"):
        connect("tcp://127.0.0.1:9", timeout_s=1.0)
    assert time.perf_counter() - start < 15


# -- checkpoints ---------------------------------------------------------------------------------


def test_resumed_build_equals_uninterrupted(planar3, reference, tmp_path):
    ckpt = default_checkpoint_path(tmp_path / "map.h5")
    assert ckpt.name == "map.h5.partial"
    with pytest.raises(Stop):  # stops after chunk 2, before its checkpoint: the file holds chunks 0-1
        build_map(planar3, None, SETTINGS, stop_after(3 * CHUNK), checkpoint=ckpt, checkpoint_every=CHUNK)
    acc = MapAccumulator(planar3, None, SETTINGS)
    load_checkpoint(ckpt, acc)
    np.testing.assert_array_equal(acc.done, np.arange(acc.n_chunks) < 2)
    seen: list[int] = []
    rmap = build_map(planar3, None, SETTINGS, seen.append, checkpoint=ckpt, checkpoint_every=CHUNK)
    assert_same_map(rmap, reference)
    assert seen[0] == acc.samples_done and seen[-1] == SETTINGS.samples
    assert not ckpt.exists() and list(tmp_path.iterdir()) == []


def test_sigint_in_process_writes_a_final_checkpoint(planar3, reference, tmp_path, ctrl_c):
    ckpt = tmp_path / "m.partial"

    def interrupt(done: int) -> None:
        if done == 2 * CHUNK:
            signal.raise_signal(signal.SIGINT)  # deferred to the end of the chunk

    with pytest.raises(KeyboardInterrupt):  # checkpoints every 5 chunks, so only the final one
        build_map(planar3, None, SETTINGS, interrupt, checkpoint=ckpt, checkpoint_every=5 * CHUNK)
    acc = MapAccumulator(planar3, None, SETTINGS)
    load_checkpoint(ckpt, acc)
    np.testing.assert_array_equal(acc.done, np.arange(acc.n_chunks) < 2)
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    assert_same_map(build_map(planar3, None, SETTINGS, checkpoint=ckpt), reference)


CHILD = """
import signal, sys, time
signal.signal(signal.SIGINT, signal.default_int_handler)  # not ignored even if the test runs in background
from baseplace.reachability.build import BuildSettings, build_map
from baseplace.robots.model import Robot
s = BuildSettings(samples=int(sys.argv[1]), seed=int(sys.argv[2]))
build_map(Robot(sys.argv[3]), None, s, lambda n: time.sleep(0.5), checkpoint=sys.argv[4], checkpoint_every=1)
"""


def start_child_and_wait_for_checkpoint(ckpt: Path) -> subprocess.Popen:
    args = [str(SETTINGS.samples), str(SETTINGS.seed), PLANAR3, str(ckpt)]
    proc = subprocess.Popen([sys.executable, "-c", CHILD, *args], stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 60
    while not ckpt.exists():
        if proc.poll() is not None or time.monotonic() > deadline:
            proc.kill()
            pytest.fail(f"the child build wrote no checkpoint: {proc.communicate()[1][-2000:]}")
        time.sleep(0.02)
    return proc


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT], ids=["SIGKILL", "SIGINT"])
def test_killed_build_resumes_to_the_same_map(sig, planar3, reference, tmp_path):
    ckpt = tmp_path / "map.h5.partial"
    proc = start_child_and_wait_for_checkpoint(ckpt)
    proc.send_signal(sig)
    _, stderr = proc.communicate(timeout=30)
    assert proc.returncode != 0
    if sig == signal.SIGINT:
        assert "KeyboardInterrupt" in stderr
    acc = MapAccumulator(planar3, None, SETTINGS)
    load_checkpoint(ckpt, acc)  # a valid checkpoint, whatever moment the signal hit
    assert 0 < acc.done.sum() < acc.n_chunks
    np.testing.assert_array_equal(acc.done, np.arange(acc.n_chunks) < acc.done.sum())
    assert_same_map(build_map(planar3, None, SETTINGS, checkpoint=ckpt), reference)
    assert list(tmp_path.iterdir()) == []  # checkpoint and any torn temporary file removed


@pytest.fixture()
def partial_checkpoint(planar3, tmp_path) -> Path:
    ckpt = tmp_path / "map.h5.partial"
    with pytest.raises(Stop):
        build_map(planar3, None, SETTINGS, stop_after(2 * CHUNK), checkpoint=ckpt, checkpoint_every=1)
    return ckpt


def test_mismatched_checkpoint_is_an_input_error(partial_checkpoint, planar3, tiago):
    other = BuildSettings(samples=SETTINGS.samples, seed=SETTINGS.seed + 1)
    with pytest.raises(InputError, match=r"from another build \(seed 5, now 6\); delete it"):
        build_map(planar3, None, other, checkpoint=partial_checkpoint)
    with pytest.raises(InputError, match=r"from another build \(robot 'planar3', now 'tiago'\)"):
        build_map(tiago, None, SETTINGS, checkpoint=partial_checkpoint)
    bigger = BuildSettings(samples=SETTINGS.samples + 1, seed=SETTINGS.seed)
    with pytest.raises(InputError, match="samples"):
        build_map(planar3, None, bigger, checkpoint=partial_checkpoint)
    assert partial_checkpoint.exists()  # never deleted behind the user's back


def test_corrupt_checkpoint_is_an_input_error(partial_checkpoint, planar3, reference, tmp_path):
    data = partial_checkpoint.read_bytes()
    truncated = tmp_path / "truncated.partial"
    truncated.write_bytes(data[: len(data) // 2])
    garbage = tmp_path / "garbage.partial"
    garbage.write_bytes(b"\x89HDF\r\n\x1a\n" + bytes(500))
    empty = tmp_path / "empty.partial"
    empty.write_bytes(b"")
    tampered = tmp_path / "tampered.partial"
    shutil.copy(partial_checkpoint, tampered)
    with h5py.File(tampered, "r+") as f:
        f["counts"][0] += 1
    for path in (truncated, garbage, empty, tampered):
        with pytest.raises(InputError, match="truncated or corrupt; delete it to start over"):
            build_map(planar3, None, SETTINGS, checkpoint=path)
    a_map = tmp_path / "a_map.h5"
    save_map(reference, a_map)
    with pytest.raises(InputError, match="not a baseplace build checkpoint"):
        build_map(planar3, None, SETTINGS, checkpoint=a_map)


def test_checkpoint_round_trip_keeps_manipulability_and_drops(planar3, tmp_path):
    s = BuildSettings(samples=CHUNK + 1000, seed=1, manipulability=True)
    acc = MapAccumulator(planar3, None, s)
    acc.add_chunk(1)
    save_checkpoint(tmp_path / "c", acc, 1.5)
    back = MapAccumulator(planar3, None, s)
    assert load_checkpoint(tmp_path / "c", back) == 1.5
    np.testing.assert_array_equal(back.done, [False, True])
    assert np.array_equal(back.counts, acc.counts) and np.array_equal(
        back.best, acc.best
    )  # dense: fast check
    with pytest.raises(InputError, match="repeats chunks"):
        back.merge(acc.partial())


def test_checkpoint_arguments_are_checked(planar3, tmp_path):
    with pytest.raises(InputError, match="directory"):
        build_map(planar3, None, SETTINGS, checkpoint=tmp_path / "missing" / "c.partial")
    with pytest.raises(InputError, match="at least 1 sample"):
        build_map(planar3, None, SETTINGS, checkpoint=tmp_path / "c.partial", checkpoint_every=0)
