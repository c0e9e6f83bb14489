"""Which of baseplace's files and functions one ``place`` query enters (issue 26's "walk").

Runs the query in this process under a profiler hook (``sys.setprofile``, and
``threading.setprofile`` for the service's threads) that counts every Python ``call`` event whose
code lies in the ``baseplace`` or ``baseplace_experiments`` packages. Import-time execution (a
module's ``<module>`` code, run once when it is first imported) is counted apart from calls of
functions. A call of a numba kernel counts once, for the file that defines it (the hook sees
the dispatcher's call); what the kernel runs compiled, and C code, never counts.

* ``cli``: ``baseplace.cli.main(ARGV)`` in a fresh interpreter, the hook set before
  ``baseplace.cli`` is imported, so the walk includes the imports a command line pays.
* ``service``: the app of ``baseplace serve`` (warm-up on, as ``baseplace serve`` runs it) in
  FastAPI's TestClient; the scene ``--cloud`` is uploaded, then only one ``POST /place`` of the
  targets is counted (what a query costs once the service is up).

Prints one JSON object: files and functions entered, each with and without import-time
execution, the call events, and with ``--list`` the files and their function counts.

Usage (a cached default map and, for the CLI, the cloud's cached segmentation make it a query):
    python bench/trace_walk.py cli place --cloud scene.ply --target "1.0 0.5 0.75 0 1.5708 0" --json
    python bench/trace_walk.py service --cloud scene.ply --target "1.0 0.5 0.75 0 1.5708 0"
    python bench/trace_walk.py service --queries 2 --cloud scene.ply --target "1.0 0.5 0.75 0 1.5708 0"
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import threading
from collections import Counter
from pathlib import Path
from types import FrameType
from typing import Any

PACKAGES = ("baseplace", "baseplace_experiments")


class Walk:
    """The call events into the packages' code, recorded while :attr:`on`."""

    def __init__(self) -> None:
        from importlib.util import find_spec

        roots = []
        for name in PACKAGES:  # found without importing them: their imports belong to the walk
            spec = find_spec(name)
            roots += [] if spec is None else list(spec.submodule_search_locations or ())
        self.roots = tuple(str(Path(r)) + "/" for r in roots)
        self.on = False
        self.calls: Counter[tuple[str, str, int]] = Counter()  # code run by calls once imported
        self.imports: Counter[tuple[str, str, int]] = Counter()  # code run while a module is imported
        self.entries: set[tuple[str, str, str]] = set()  # (file, caller file:function, callee function)
        self.lock = threading.Lock()

    def hook(self, frame: FrameType, event: str, arg: Any) -> None:
        if event != "call" or not self.on:
            return
        code = frame.f_code
        if not code.co_filename.startswith(self.roots):
            return
        at: FrameType | None = frame
        while at is not None and not (
            at.f_code.co_name == "<module>" and at.f_code.co_filename.startswith(self.roots)
        ):
            at = at.f_back
        key = (code.co_filename, code.co_qualname, code.co_firstlineno)
        back = frame.f_back
        with self.lock:
            (self.calls if at is None else self.imports)[key] += 1
            if at is None and back is not None and back.f_code.co_filename != code.co_filename:
                caller = back.f_code
                if caller.co_filename.startswith(self.roots):
                    self.entries.add(
                        (code.co_filename, f"{caller.co_filename}:{caller.co_qualname}", code.co_qualname)
                    )

    def start(self) -> None:
        threading.setprofile(self.hook)
        sys.setprofile(self.hook)

    def stop(self) -> None:
        sys.setprofile(None)
        threading.setprofile(None)  # type: ignore[arg-type]

    def summary(self, listing: bool) -> dict[str, Any]:
        def rel(path: str) -> str:
            for root in self.roots:
                if path.startswith(root):
                    return Path(root).name + "/" + path[len(root) :]
            return path

        entered = set(self.calls) | set(self.imports)
        functions = {k for k in entered if k[1] != "<module>"}
        out: dict[str, Any] = {
            "files_entered": len({k[0] for k in entered}),
            "files_entered_by_calls": len({k[0] for k in self.calls}),
            "modules_imported": sum(k[1] == "<module>" for k in entered),
            "functions_entered": len(functions),
            "functions_entered_by_calls": len(self.calls),
            "call_events": sum(self.calls.values()),
        }
        if listing:
            out["files"] = {rel(k[0]): [] for k in sorted(entered)}
            for k in sorted(entered):
                how = f"x{self.calls[k]}" if k in self.calls else "at import"
                out["files"][rel(k[0])].append(f"{k[1]}:{k[2]} {how}")
            out["entered_from"] = {rel(k[0]): [] for k in sorted(entered)}
            for file, caller, callee in sorted(self.entries):
                out["entered_from"][rel(file)].append(f"{callee} <- {rel(caller)}")
        return out


def run_cli(walk: Walk, argv: list[str]) -> int:
    walk.on = True
    with contextlib.redirect_stdout(io.StringIO()):
        from baseplace.cli import main

        code = main(argv)
    walk.on = False
    return code


def run_service(walk: Walk, cloud: str, targets: list[str], seed: int, queries: int = 1) -> int:
    from fastapi.testclient import TestClient

    from baseplace.serve.server import create_app
    from baseplace.serve.state import ServeSettings

    fmt = Path(cloud).suffix.lstrip(".")
    settings = ServeSettings(allow_hosts=("testserver",))
    with TestClient(create_app(settings)) as client:  # the lifespan warms the default robot up
        r = client.post("/scenes", params={"format": fmt}, content=Path(cloud).read_bytes(),
                        headers={"content-type": "application/octet-stream"})  # fmt: skip
        if r.status_code != 200:
            sys.stderr.write(f"scene upload: {r.status_code} {r.text}\n")
            return 1
        body = {"scene_id": r.json()["scene_id"], "targets": targets, "seed": seed}
        for k in range(queries):
            walk.on = k == queries - 1  # only the last query counts
            r = client.post("/place", json=body)
            walk.on = False
    if r.status_code != 200:
        sys.stderr.write(f"place: {r.status_code} {r.text[:300]}\n")
    return 0 if r.status_code == 200 else 1


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--list",
        action="store_true",
        help="also list the files entered, the functions entered in each, and where each file is entered from",
    )
    sub = parser.add_subparsers(dest="front", required=True)
    cli = sub.add_parser("cli", help="baseplace ARGV in this process")
    cli.add_argument("argv", nargs=argparse.REMAINDER)
    service = sub.add_parser("service", help="one POST /place after the scene's upload")
    service.add_argument("--cloud", required=True)
    service.add_argument("--target", action="append", required=True)
    service.add_argument("--seed", type=int, default=0)
    service.add_argument(
        "--queries", type=int, default=1, help="run the query this many times, count the last (default 1)"
    )
    args = parser.parse_args()
    walk = Walk()
    walk.start()
    try:
        if args.front == "cli":
            code = run_cli(walk, args.argv)
        else:
            code = run_service(walk, args.cloud, args.target, args.seed, args.queries)
    finally:
        walk.stop()
    print(json.dumps({"front": args.front, "exit_code": code, **walk.summary(args.list)}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
