"""One client cannot starve the others (issue 28): heavy placements in a lane of their own, shares per client.

A real ``baseplace serve`` on a free loopback port, its clients told apart by their loopback
addresses (127.0.0.1 honest, 127.0.0.2 hostile), and the app in process for the shares.
"""

from __future__ import annotations

import statistics
import threading
import time

import httpx
import pytest

pytest.importorskip("fastapi")
pytest.importorskip("uvicorn")

from fastapi.testclient import TestClient

import test_serve_hostile as hostile
from test_serve import UP, make_app, npy_bytes
from test_serve_hostile import CHEAP, HEAVY, RealServer, _error_json

serve_cache, tray_points = hostile.serve_cache, hostile.tray_points  # its fixtures


def test_a_client_looping_heavy_placements_does_not_hold_up_another_clients_place(serve_cache, tray_points):
    server = RealServer(serve_cache, 8.0, tray_points)  # a heavy /place runs past 8 s: answered 504
    try:
        honest = httpx.Client(base_url=server.url, timeout=60)
        hostile = httpx.Client(
            base_url=server.url, timeout=60, transport=httpx.HTTPTransport(local_address="127.0.0.2")
        )
        body = {"scene_id": server.scene, **CHEAP}

        def timed() -> float:
            t = time.perf_counter()
            r = honest.post("/place", json=body)
            assert r.status_code == 200 and r.json()["placements"], r.text[:300]
            return time.perf_counter() - t

        alone = [timed() for _ in range(5)]
        stop = threading.Event()
        heavy: list[int] = []

        def loop_heavy() -> None:
            while not stop.is_set():
                heavy.append(hostile.post("/place", json={"scene_id": server.scene, **HEAVY}).status_code)

        looper = threading.Thread(target=loop_heavy, daemon=True)
        looper.start()
        time.sleep(1.0)  # the first heavy placement computing
        beside = [timed() for _ in range(5)]  # spread over the heavy placement's 8 s
        # the same client's second heavy placement: over its share, told at once
        t = time.perf_counter()
        r = hostile.post("/place", json={"scene_id": server.scene, **HEAVY}, timeout=5)
        assert "one at a time per client" in _error_json(r, 429)
        assert r.headers["retry-after"].isdigit() and time.perf_counter() - t < 2.0
        stop.set()
        looper.join(30)
        print(f"honest /place alone: median {statistics.median(alone) * 1e3:.0f} ms, max {max(alone) * 1e3:.0f} ms; "
              f"beside a heavy loop: median {statistics.median(beside) * 1e3:.0f} ms, "
              f"max {max(beside) * 1e3:.0f} ms; heavy answers {heavy}")  # fmt: skip
        assert max(beside) < max(3.0, 10 * statistics.median(alone)), (alone, beside)
        assert heavy and set(heavy) <= {200, 504}, heavy
    finally:
        server.stop()


def test_a_client_past_its_share_of_a_lane_gets_429_json_and_others_do_not(tiago, tiago_map, tray_points):
    # heavy_work past the schema's limit: every /place is in the one placement lane
    app = make_app(tiago, tiago_map, timeout_s=3.0, max_client_queue=1, heavy_work=10**9)
    with TestClient(app, raise_server_exceptions=False) as c:
        r = c.post("/scenes", params={"format": "npy"}, content=npy_bytes(tray_points), headers=UP)
        scene_id = r.json()["scene_id"]
        assert c.post("/place", json={"scene_id": scene_id, **CHEAP}).status_code == 200  # warm
        answers: list[int] = []
        first = threading.Thread(
            target=lambda: answers.append(c.post("/place", json={"scene_id": scene_id, **HEAVY}).status_code)
        )
        first.start()
        time.sleep(0.5)  # the heavy one running
        r = c.post("/place", json={"scene_id": scene_id, **CHEAP})
        assert "--max-client-queue" in _error_json(r, 429) and r.headers["retry-after"] == "1"
        other = TestClient(app, raise_server_exceptions=False, client=("127.0.0.9", 40000))
        r = other.post("/place", json={"scene_id": scene_id, **CHEAP})  # another client: queued, answered
        assert r.status_code in (200, 504), r.text[:300]
        first.join(30)
        assert answers == [504], answers
        assert c.post("/place", json={"scene_id": scene_id, **CHEAP}).status_code == 200  # its share is back


def test_a_lane_takes_its_clients_in_turn():
    from baseplace.serve.lanes import FairLane

    lane = FairLane("test", 1)
    started, gate = threading.Event(), threading.Event()
    order: list[str] = []
    lane.submit_for("a", lambda: (started.set(), gate.wait(10)))  # holds the thread while the queue fills
    assert started.wait(10)
    futures = [lane.submit_for("a", order.append, f"a{k}") for k in range(4)]
    futures += [lane.submit_for("b", order.append, f"b{k}") for k in range(2)]
    futures.append(lane.submit_for("c", order.append, "c0"))
    gate.set()
    for f in futures:
        f.result(10)
    lane.shutdown()
    assert order == ["a0", "b0", "c0", "a1", "b1", "a2", "a3"], order
