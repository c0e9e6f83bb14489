"""Load test of ``baseplace serve`` (issue 18): bounded, loopback only.

Starts the service as a subprocess on a free loopback port, uploads generated 10 x 10 m scenes
(a floor and two inclined planes: three support regions; a box with objects) with an occupancy
grid rasterised from each, then:

1. warm ``place`` of one top-down target, one client, ``--warm`` queries with different seeds:
   server-side time (the ``x-server-time-ms`` header: request in to JSON out) median and p95,
   with the seed-000 checks (IK + collision at the exact pose, the issue's "verification") and
   with the CLI's defaults (reaching motion + robustness); the same queries through
   ``baseplace place`` from a new process (``--cli`` runs each), for the ratio;
2. ``--requests`` requests from ``--clients`` concurrent clients mixing place, candidates and
   reach (``--mix``), each with a time limit: latency p50/p95/p99, errors, the server's
   resident memory before, after the first 500 and after the last 500.

Usage: nice -n 10 python bench/bench_serve.py [--requests 2000] [--clients 8]
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import cv2
import httpx
import numpy as np

from baseplace.sim.scenes import SceneSettings, generate_scene
from baseplace.terrain.io import Cloud, save_cloud
from common import report

SEED000 = {"no_motion_check": True, "robustness_samples": 0}
UPLOAD = {"content-type": "application/octet-stream"}  # the service refuses an upload of any other type (415)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def scene_inputs(seed: int, folder: Path) -> dict[str, Any]:
    """A generated scene: cloud file, grid image, a top-down target over a plane, an object position."""
    rng = np.random.default_rng(seed)
    scene = generate_scene(SceneSettings(n_planes=2, extent=(10.0, 10.0)), rng)
    points = scene.sample_cloud(rng)
    cloud = folder / f"scene{seed}.ply"
    save_cloud(Cloud(points, source="bench_serve"), cloud)
    res = 0.05
    h = w = round(10.0 / res)
    ij = np.floor((points[:, :2] + 5.0) / res).astype(int)
    ok = (ij >= 0).all(axis=1) & (ij < w).all(axis=1) & (points[:, 2] > 0.05)
    occupied = np.zeros((h, w), dtype=bool)
    occupied[ij[ok, 1], ij[ok, 0]] = True
    image = np.where(occupied, 0, 254).astype(np.uint8)[::-1]  # map_server: first image row at max y
    ok_png, png = cv2.imencode(".png", image)
    assert ok_png
    plane = scene.planes[2]
    cx, cy = plane.center
    top = float(plane.z(np.array([[cx, cy]]))[0])
    obj = scene.objects[0]
    return {
        "seed": seed, "cloud": cloud, "png": png.tobytes(), "resolution": res,
        "target": f"{cx:.3f} {cy:.3f} {top + 0.75:.3f} 0 1.5708 0",
        "object": f"{obj.center[0]:.3f} {obj.center[1]:.3f} {obj.center[2]:.3f}",
        "base": f"{cx - 0.6:.3f} {cy:.3f} 0",
    }  # fmt: skip


def pct(values: list[float], q: float) -> float:
    return round(float(np.percentile(values, q)), 2) if values else float("nan")


def start_server(env: dict[str, str], timeout_s: float) -> tuple[subprocess.Popen[str], str, int]:
    """``baseplace serve`` on a free loopback port, request time limit ``timeout_s``: (process, url, port)."""
    port = free_port()
    server = subprocess.Popen([sys.executable, "-m", "baseplace.cli", "serve", "--port", str(port), "--timeout",
                               str(timeout_s)], env=env, stderr=subprocess.PIPE, text=True)  # fmt: skip
    return server, f"http://127.0.0.1:{port}", port


def wait_healthy(http: httpx.Client, server: subprocess.Popen[str], limit_s: float) -> float:
    """Seconds until ``/health`` answers 200; exits with the server's stderr if it dies or takes too long."""
    t0 = time.time()
    while True:
        try:
            if http.get("/health").status_code == 200:
                return round(time.time() - t0, 2)
        except httpx.TransportError:
            pass
        if server.poll() is not None or time.time() - t0 > limit_s:
            raise SystemExit(f"server did not start: {server.stderr.read() if server.stderr else ''}")
        time.sleep(0.2)


def upload_scene(http: httpx.Client, scene: dict[str, Any]) -> dict[str, Any]:
    """Upload a scene's cloud; its id goes to ``scene["id"]``; the service's answer."""
    r = http.post("/scenes", params={"format": "ply"}, content=scene["cloud"].read_bytes(), headers=UPLOAD)
    r.raise_for_status()
    answer: dict[str, Any] = r.json()
    scene["id"] = answer["scene_id"]
    return answer


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--requests", type=int, default=2000)
    parser.add_argument("--clients", type=int, default=8)
    parser.add_argument("--scenes", type=int, default=3)
    parser.add_argument("--warm", type=int, default=40, help="sequential warm place queries per setting")
    parser.add_argument("--cli", type=int, default=3, help="CLI runs of the same query per setting")
    parser.add_argument("--mix", default="place:0.45,reach:0.45,candidates:0.10")
    parser.add_argument("--timeout", type=float, default=60.0, help="client time limit per request [s]")
    args = parser.parse_args()
    mix = {k: float(v) for k, v in (p.split(":") for p in args.mix.split(","))}
    folder = Path(tempfile.mkdtemp(prefix="bench-serve-"))
    scenes = [scene_inputs(seed, folder) for seed in range(1, args.scenes + 1)]
    env = dict(os.environ)
    server, url, _ = start_server(env, 120)
    result: dict[str, Any] = {"url": "loopback", "clients": args.clients, "requests": args.requests, "mix": mix,
                              "scenes": "generated 10 x 10 m, floor + 2 inclined planes (3 support regions), box "
                                        "with objects, 25 mm noise; seeds " + ", ".join(str(s["seed"]) for s in scenes)}  # fmt: skip
    try:
        http = httpx.Client(base_url=url, timeout=args.timeout)
        result["server_start_s"] = wait_healthy(http, server, 300)
        for s in scenes:
            s["regions"] = upload_scene(http, s)["regions"]
            r = http.post(f"/scenes/{s['id']}/grid", params={"resolution": s["resolution"], "format": "png",
                                                              "origin_x": -5.0, "origin_y": -5.0}, content=s["png"], headers=UPLOAD)  # fmt: skip
            r.raise_for_status()
        result["regions_per_scene"] = [s["regions"] for s in scenes]
        first = scenes[0]
        result["warm_place_target"] = first["target"]

        # 1. warm place, one client; the CLI on the same query
        for label, extra in (("seed000_checks", SEED000), ("cli_defaults", {})):
            server_ms, r2p, found = [], [], 0
            for q in range(args.warm):
                r = http.post(
                    "/place", json={"scene_id": first["id"], "targets": [first["target"]], "seed": q, **extra}
                )
                r.raise_for_status()
                server_ms.append(float(r.headers["x-server-time-ms"]))
                r2p.append(r.json()["timings_ms"]["request_to_placement"])
                found += bool(r.json()["placements"])
            cli_s = []
            flags = ["--no-motion-check", "--robustness-samples", "0"] if extra else []
            for q in range(args.cli):
                t = time.perf_counter()
                done = subprocess.run([sys.executable, "-m", "baseplace.cli", "place", "--cloud", str(first["cloud"]),
                                       "--target", first["target"], "--seed", str(q), "--json", *flags],
                                      capture_output=True, text=True, env=env)  # fmt: skip
                cli_s.append(time.perf_counter() - t)
                assert done.returncode in (0, 3), done.stderr
            med = float(np.median(server_ms))
            result[f"warm_place_{label}"] = {
                "queries": args.warm, "found": found,
                "server_ms_median": round(med, 2), "server_ms_p95": pct(server_ms, 95),
                "request_to_placement_ms_median": round(float(np.median(r2p)), 2),
                "request_to_placement_ms_p95": pct(r2p, 95),
                "cli_wall_s": [round(v, 2) for v in cli_s], "cli_wall_s_median": round(float(np.median(cli_s)), 2),
                "cli_over_server_ratio": round(float(np.median(cli_s)) * 1e3 / med, 1),
            }  # fmt: skip
            print(label, json.dumps(result[f"warm_place_{label}"]), flush=True)

        # 2. the load: fixed number of requests, a time limit each, 8 clients
        rng = np.random.default_rng(0)
        kinds = rng.choice(list(mix), size=args.requests, p=np.array(list(mix.values())) / sum(mix.values()))
        which = rng.integers(0, len(scenes), size=args.requests)
        lat: dict[str, list[float]] = {k: [] for k in mix}
        all_lat: list[float] = []
        errors: dict[str, int] = {}
        statuses: dict[str, int] = {}
        done_count = 0
        lock = threading.Lock()
        rss = {"before": rss_mb(server.pid)}
        next_index = iter(range(args.requests))

        def one(i: int, client: httpx.Client) -> None:
            nonlocal done_count
            s = scenes[int(which[i])]
            kind = str(kinds[i])
            if kind == "place":
                path, body = "/place", {"scene_id": s["id"], "targets": [s["target"]], "seed": i, **SEED000}
            elif kind == "reach":
                path, body = "/reach", {"targets": [s["target"]], "bases": [s["base"], "0 0 0", "1 1 1.57"]}
            else:
                path, body = "/candidates", {"scene_id": s["id"], "object": s["object"], "seed": i, **SEED000}
            t = time.perf_counter()
            try:
                r = client.post(path, json=body)
                code = str(r.status_code)
                if r.status_code != 200:
                    key = f"{kind} HTTP {r.status_code}: {r.text[:120]}"
                else:
                    key = None
            except httpx.HTTPError as exc:
                code, key = "transport", f"{kind} {type(exc).__name__}"
            elapsed = (time.perf_counter() - t) * 1e3
            with lock:
                statuses[code] = statuses.get(code, 0) + 1
                if key is not None:
                    errors[key] = errors.get(key, 0) + 1
                lat[kind].append(elapsed)
                all_lat.append(elapsed)
                done_count += 1
                if done_count == 500:
                    rss["after_first_500"] = rss_mb(server.pid)
                if done_count == args.requests - 500:
                    rss["before_last_500"] = rss_mb(server.pid)

        def worker() -> None:
            with httpx.Client(base_url=url, timeout=args.timeout) as client:
                while True:
                    with lock:
                        i = next(next_index, None)
                    if i is None:
                        return
                    one(i, client)

        t = time.perf_counter()
        threads = [threading.Thread(target=worker) for _ in range(args.clients)]
        for th in threads:
            th.start()
        for th in threads:
            th.join()
        wall = time.perf_counter() - t
        rss["after"] = rss_mb(server.pid)
        base = rss.get("after_first_500", rss["before"])
        growth = (rss["after"] - base) / base
        result["load"] = {
            "wall_s": round(wall, 1), "throughput_per_s": round(args.requests / wall, 2),
            "errors": sum(errors.values()), "error_kinds": errors, "statuses": statuses,
            "latency_ms_all": {"p50": pct(all_lat, 50), "p95": pct(all_lat, 95), "p99": pct(all_lat, 99)},
            "latency_ms": {k: {"n": len(v), "p50": pct(v, 50), "p95": pct(v, 95), "p99": pct(v, 99)}
                           for k, v in lat.items()},
            "server_rss_mb": {k: round(v, 1) for k, v in rss.items()},
            "rss_growth_first_to_last_500": round(growth, 4),
        }  # fmt: skip
        print(json.dumps(result["load"]), flush=True)
        result["goals"] = ("warm place server-side median <= 15 ms, p95 <= 40 ms (seed-000 checks); 0 errors; "
                           "RSS growth < 10 % between the first and the last 500 requests")  # fmt: skip
    finally:
        server.terminate()  # SIGTERM: graceful shutdown
        try:
            code = server.wait(timeout=60)
        except subprocess.TimeoutExpired:
            server.kill()
            code = -9
        result["server_exit_code_after_sigterm"] = code
    report("serve_load", result, used_seeds=[s["seed"] for s in scenes], protocol=__doc__.split("\n\n")[1])


if __name__ == "__main__":
    main()
