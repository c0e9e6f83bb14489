"""Honest clients beside hostile ones (issue 28): bounded, loopback only.

Starts ``baseplace serve`` as a subprocess on a free loopback port (as bench_serve.py does, with
its generated scene), then runs the same honest load twice in one run: ``--requests`` requests
from ``--clients`` clients, half warm ``place`` (IK + collision checks), half ``reach``, each
with a client time limit; first alone, then while hostile clients run:

* slowloris: ``--slowloris`` connections sending one header line a second, never the blank line;
* stalled bodies: ``--stalled`` connections declaring 50 MB, sending 20 MB, then silence;
* heavy placements: ``--heavy`` clients looping the largest ``/place`` the schema allows
  (16 targets, 1,000 tries, 1,024 robustness samples);
* malformed JSON: one client looping broken JSON, NaN, deep nesting and a wrong content type.

The hostile clients connect from ``--hostile-address`` (127.0.0.2), the honest ones from
127.0.0.1: the service shares its queues out by peer address. Honest p50/p95/p99 and errors,
with and without, and what the hostile clients got back.

Usage: nice -n 10 python bench/bench_serve_hostile.py [--requests 400] [--clients 4] [--small-map]
"""

from __future__ import annotations

import argparse
import os
import socket
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import httpx

from bench_serve import (
    SEED000,
    pct,
    rss_mb,
    scene_inputs,
    start_server,
    upload_scene,
    wait_healthy,
)
from common import report

HEAVY = {"tries": 1000, "placements": 1, "robustness_samples": 1024}
MALFORMED = [
    (b'{"targets": [', "application/json"),
    (b'{"targets": ["0 0 1 0 0 0"], "bases": ["0 0 NaN"], "robot": NaN}', "application/json"),
    (b"[" * 50_000 + b"]" * 50_000, "application/json"),
    (b'{"targets": ["\xff\xfe"], "bases": ["0 0 0"]}', "application/json"),
    (b'{"targets": ["0 0 1 0 0 0"], "bases": ["0 0 0"]}', "text/plain"),
]


def honest_load(
    url: str, scene: dict[str, Any], requests: int, clients: int, timeout: float
) -> dict[str, Any]:
    """``requests`` honest requests (place / reach alternating) from ``clients`` threads."""
    lat: list[float] = []
    errors: dict[str, int] = {}
    lock = threading.Lock()
    index = iter(range(requests))

    def worker() -> None:
        with httpx.Client(base_url=url, timeout=timeout) as client:
            while True:
                with lock:
                    i = next(index, None)
                if i is None:
                    return
                if i % 2 == 0:
                    path = "/place"
                    body = {"scene_id": scene["id"], "targets": [scene["target"]], "seed": i, **SEED000}
                else:
                    path, body = "/reach", {"targets": [scene["target"]], "bases": [scene["base"], "0 0 0"]}
                t = time.perf_counter()
                try:
                    r = client.post(path, json=body)
                    key = None if r.status_code == 200 else f"{path} HTTP {r.status_code}"
                except httpx.HTTPError as exc:
                    key = f"{path} {type(exc).__name__}"
                with lock:
                    lat.append((time.perf_counter() - t) * 1e3)
                    if key is not None:
                        errors[key] = errors.get(key, 0) + 1

    t = time.perf_counter()
    threads = [threading.Thread(target=worker) for _ in range(clients)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    return {"requests": requests, "wall_s": round(time.perf_counter() - t, 2), "errors": sum(errors.values()),
            "error_kinds": errors, "latency_ms": {"p50": pct(lat, 50), "p95": pct(lat, 95), "p99": pct(lat, 99)}}  # fmt: skip


class Hostile:
    """The hostile clients, each a thread looping until :meth:`stop`; what they got back, counted."""

    def __init__(self, url: str, port: int, scene: dict[str, Any], args: argparse.Namespace) -> None:
        self.url, self.port, self.scene = url, port, scene
        self.address = args.hostile_address
        self.stopping = threading.Event()
        self.counts: dict[str, int] = {}
        self.lock = threading.Lock()
        self.threads = (
            [threading.Thread(target=self.slowloris) for _ in range(args.slowloris)]
            + [threading.Thread(target=self.stalled) for _ in range(args.stalled)]
            + [threading.Thread(target=self.heavy) for _ in range(args.heavy)]
            + [threading.Thread(target=self.malformed)]
        )

    def count(self, key: str) -> None:
        with self.lock:
            self.counts[key] = self.counts.get(key, 0) + 1

    def start(self) -> None:
        for th in self.threads:
            th.start()

    def stop(self) -> None:
        self.stopping.set()
        for th in self.threads:
            th.join(60)

    def _socket(self) -> socket.socket:
        s = socket.create_connection(("127.0.0.1", self.port), source_address=(self.address, 0))
        s.settimeout(1.0)
        return s

    def _transport(self) -> httpx.HTTPTransport:
        return httpx.HTTPTransport(local_address=self.address)

    def slowloris(self) -> None:
        while not self.stopping.is_set():
            t = time.perf_counter()
            try:
                with self._socket() as s:
                    s.sendall(b"GET /health HTTP/1.1\r\nHost: 127.0.0.1\r\n")
                    while not self.stopping.is_set():
                        s.sendall(b"X-Slow: 1\r\n")
                        try:
                            if s.recv(1024) == b"":
                                break
                        except TimeoutError:
                            pass
            except OSError:
                pass
            self.count("slowloris connections closed by the server")
            self.count(f"slowloris held {5 * round((time.perf_counter() - t) / 5)} s")

    def stalled(self) -> None:
        while not self.stopping.is_set():
            try:
                with self._socket() as s:
                    s.sendall(b"POST /scenes?format=npy HTTP/1.1\r\nHost: 127.0.0.1\r\nContent-Type: "
                              b"application/octet-stream\r\nContent-Length: 52428800\r\n\r\n")  # fmt: skip
                    for _ in range(20):
                        s.sendall(b"\0" * 2**20)
                    while not self.stopping.is_set():
                        try:
                            answer = s.recv(1024)
                        except TimeoutError:
                            continue
                        self.count(f"stalled body: {answer.split(b' ')[1].decode() if answer else 'closed'}")
                        break
            except OSError:
                self.count("stalled body: refused or reset")

    def heavy(self) -> None:
        with httpx.Client(base_url=self.url, timeout=120, transport=self._transport()) as client:
            while not self.stopping.is_set():
                body = {"scene_id": self.scene["id"], "targets": [self.scene["target"]] * 16, **HEAVY}
                try:
                    self.count(f"heavy place: HTTP {client.post('/place', json=body).status_code}")
                except httpx.HTTPError as exc:
                    self.count(f"heavy place: {type(exc).__name__}")

    def malformed(self) -> None:
        with httpx.Client(base_url=self.url, timeout=30, transport=self._transport()) as client:
            k = 0
            while not self.stopping.is_set():
                data, kind = MALFORMED[k % len(MALFORMED)]
                k += 1
                try:
                    r = client.post("/reach", content=data, headers={"content-type": kind})
                    json_body = r.headers.get("content-type", "").startswith("application/json")
                    self.count(f"malformed: HTTP {r.status_code}{'' if json_body else ' (not JSON)'}")
                except httpx.HTTPError as exc:
                    self.count(f"malformed: {type(exc).__name__}")
                time.sleep(0.05)


def small_map_cache(folder: Path) -> Path:
    """A cache whose default TIAGo map is a small one (2e6 samples, as the tests'): no default-map build."""
    from baseplace.reachability.build import BuildSettings, build_map
    from baseplace.reachability.cache import cached_map_path
    from baseplace.reachability.storage import save_map
    from baseplace.robots.codegen import cache_dir
    from baseplace.robots.model import Robot

    kernels = cache_dir()
    root = folder / "cache"
    root.mkdir(mode=0o700)
    if kernels.is_dir():
        (root / "kernels").symlink_to(kernels)
    os.environ["BASEPLACE_CACHE"] = str(root)
    robot = Robot("tiago")
    path = cached_map_path(robot, BuildSettings())
    path.parent.mkdir(parents=True, mode=0o700)
    save_map(build_map(robot, None, BuildSettings(samples=2_000_000, seed=3)), path)
    return root


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--requests", type=int, default=400)
    parser.add_argument("--clients", type=int, default=4)
    parser.add_argument("--timeout", type=float, default=30.0, help="client time limit per request [s]")
    parser.add_argument("--server-timeout", type=float, default=10.0, help="serve --timeout [s]")
    parser.add_argument("--slowloris", type=int, default=16)
    parser.add_argument("--stalled", type=int, default=8)
    parser.add_argument("--heavy", type=int, default=2)
    parser.add_argument(
        "--hostile-address", default="127.0.0.2", help="the hostile clients' loopback address"
    )
    parser.add_argument("--small-map", action="store_true", help="a small default map (no default-map build)")
    args = parser.parse_args()
    folder = Path(tempfile.mkdtemp(prefix="bench-serve-hostile-"))
    scene = scene_inputs(1, folder)
    env = dict(os.environ)
    if args.small_map:
        env["BASEPLACE_CACHE"] = str(small_map_cache(folder))
    server, url, port = start_server(env, args.server_timeout)
    result: dict[str, Any] = {"url": "loopback", "clients": args.clients, "requests_per_phase": args.requests,
                              "server_timeout_s": args.server_timeout, "small_map": args.small_map,
                              "hostile_address": args.hostile_address,
                              "hostile": {"slowloris": args.slowloris, "stalled_50mb_bodies": args.stalled,
                                          "heavy_place_clients": args.heavy, "malformed_json_clients": 1}}  # fmt: skip
    try:
        http = httpx.Client(base_url=url, timeout=300)
        wait_healthy(http, server, 600)
        upload_scene(http, scene)
        honest_load(url, scene, 20, 1, args.timeout)  # warm: the scene's first queries
        result["honest_alone"] = honest_load(url, scene, args.requests, args.clients, args.timeout)
        print("alone", result["honest_alone"], flush=True)
        hostile = Hostile(url, port, scene, args)
        rss_before = rss_mb(server.pid)
        hostile.start()
        time.sleep(2.0)  # the hostile clients in place
        result["honest_with_hostile"] = honest_load(url, scene, args.requests, args.clients, args.timeout)
        rss_peak = rss_mb(server.pid)
        hostile.stop()
        print("with hostile", result["honest_with_hostile"], flush=True)
        result["hostile_answers"] = dict(sorted(hostile.counts.items()))
        result["server_rss_mb"] = {
            "before_hostile": round(rss_before, 1),
            "end_of_hostile": round(rss_peak, 1),
        }
        t = time.perf_counter()
        r = http.post("/place", json={"scene_id": scene["id"], "targets": [scene["target"]], **SEED000})
        result["place_after_hostile_ms"] = round((time.perf_counter() - t) * 1e3, 1)
        result["place_after_hostile_status"] = r.status_code
    finally:
        t = time.perf_counter()
        server.terminate()
        try:
            code = server.wait(timeout=60)
        except subprocess.TimeoutExpired:
            server.kill()
            code = -9
        result["server_exit_after_sigterm"] = {"code": code, "seconds": round(time.perf_counter() - t, 2)}
    report("serve_hostile", result, used_seeds=[1], protocol=__doc__.split("\n\n")[1])


if __name__ == "__main__":
    main()
