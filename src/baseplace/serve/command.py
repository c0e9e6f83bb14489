"""The ``baseplace serve`` command's options (kept here so that cli.py stays a list of commands)."""

from __future__ import annotations

import argparse
import os
import sys
from typing import Any

from baseplace.errors import InputError
from baseplace.serve.state import ServeSettings

MIB = 2**20
"""Bytes in a MiB: the command's sizes are in MiB, :class:`ServeSettings`' in bytes."""


def add_serve_command(sub: Any) -> None:
    """Add ``serve`` to ``baseplace``'s subparsers; every default is :class:`ServeSettings`' own."""
    d = ServeSettings()
    p = sub.add_parser("serve", help="HTTP/JSON service answering every job warm (place, candidates, reach, ...)",
                description="Serve the CLI's jobs over HTTP/JSON with robots, maps, kernels and "
                "uploaded scenes kept warm; OpenAPI docs at /docs. Loopback only unless --host says otherwise.")  # fmt: skip
    p.set_defaults(func=cmd_serve)
    p.add_argument("--host", default=d.host, help=f"address to bind (default {d.host}: this machine only)")
    p.add_argument("--port", type=int, default=d.port, help=f"TCP port (default {d.port}; 0: any free one)")
    p.add_argument("--robot", action="append", default=None,
                   help=f"robot to warm at start (built-in name; repeat; default {', '.join(d.robots)})")  # fmt: skip
    p.add_argument("--max-request-mb", type=float, default=d.max_request_bytes / MIB,
                   help=f"larger request bodies get 413 (default {d.max_request_bytes / MIB:g} MiB)")  # fmt: skip
    p.add_argument("--timeout", type=float, default=d.timeout_s,
                   help=f"per-request time limit [s] (default {d.timeout_s:g})")  # fmt: skip
    p.add_argument("--max-scenes", type=int, default=d.max_scenes,
                   help=f"scenes kept, least recently used dropped (default {d.max_scenes})")  # fmt: skip
    p.add_argument("--no-warm-up", action="store_true", help="skip the warm-up placement at start")
    p.add_argument("--token", default=None,
                   help="API token clients send as 'Authorization: Bearer TOKEN' (default $BASEPLACE_TOKEN; "
                        "required off loopback)")  # fmt: skip
    p.add_argument("--allow-host", action="append", default=[],
                   help="another name clients reach the service by (Host header; repeat)")  # fmt: skip
    p.add_argument("--allow-origin", action="append", default=[],
                   help="a web origin whose pages may call the service, e.g. https://ui.example:8443 (repeat)")  # fmt: skip
    p.add_argument("--max-queue", type=int, default=d.max_queue,
                   help=f"jobs waiting or running per lane; more get 503 (default {d.max_queue})")  # fmt: skip
    p.add_argument("--max-client-queue", type=int, default=d.max_client_queue,
                   help="jobs one client (peer address) may have waiting or running per lane; more get 429 "
                        f"(default {d.max_client_queue})")  # fmt: skip
    p.add_argument("--heavy-work", type=int, default=d.heavy_work,
                   help="a /place of more work, targets x (tries + placements x robustness samples), runs in "
                        f"the heavy lane, one at a time and one per client (default {d.heavy_work})")  # fmt: skip
    p.add_argument("--read-timeout", type=float, default=d.read_timeout_s,
                   help=f"request headers within, and no body stall over, this many seconds (default {d.read_timeout_s:g})")  # fmt: skip
    p.add_argument("--max-inflight-mb", type=float, default=d.max_inflight_bytes / MIB,
                   help=f"request bodies being received, all together; more get 503 (default {d.max_inflight_bytes / MIB:g} MiB)")  # fmt: skip
    p.add_argument("--max-connections", type=int, default=d.max_connections,
                   help=f"open connections; more get 503 (default {d.max_connections})")  # fmt: skip


def cmd_serve(args: argparse.Namespace) -> int:
    """Run the service until SIGINT/SIGTERM."""
    from baseplace.serve.server import serve

    for name in ("max_request_mb", "max_inflight_mb", "timeout", "read_timeout"):
        if not (getattr(args, name) > 0):  # NaN too
            raise InputError(f"--{name.replace('_', '-')} must be > 0, got {getattr(args, name)}")
    token = args.token if args.token is not None else os.environ.get("BASEPLACE_TOKEN") or None
    settings = ServeSettings(host=args.host, port=args.port, max_request_bytes=int(args.max_request_mb * MIB),
                             timeout_s=args.timeout, max_scenes=args.max_scenes,
                             robots=tuple(args.robot) if args.robot else ServeSettings.robots,
                             warm_up=not args.no_warm_up, token=token,
                             allow_hosts=tuple(args.allow_host), allow_origins=tuple(args.allow_origin),
                             max_queue=args.max_queue, max_client_queue=args.max_client_queue,
                             heavy_work=args.heavy_work, read_timeout_s=args.read_timeout,
                             max_inflight_bytes=int(args.max_inflight_mb * MIB),
                             max_connections=args.max_connections)  # fmt: skip
    warm = f"warming {', '.join(settings.robots)}, then " if settings.warm_up else ""
    sys.stderr.write(f"baseplace serve: {warm}http://{args.host}:{args.port} (docs at /docs)\n")
    serve(settings)
    return 0
