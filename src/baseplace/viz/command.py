"""The ``baseplace view`` command's options (kept here so that cli.py stays a list of commands)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from baseplace.errors import InputError


def add_view_command(sub: Any) -> None:
    """Add ``view`` to ``baseplace``'s subparsers."""
    p = sub.add_parser("view", help="interactive 3D viewer of any result in the browser (viser)",
                       description="interactive 3D viewer of any result in the browser (viser)")  # fmt: skip
    p.set_defaults(func=cmd_view)
    p.add_argument(
        "result", nargs="?", default=None,
        help="the --json of place, candidates, surface-map, surface-sample, navigate, segment, point or demo, "
        "with the inputs it names (default: out/demo.json), or a reachability map (.rmap, .h5, .hdf5)",
    )  # fmt: skip
    p.add_argument(
        "--map", default=None, help="draw this reachability map (build-map's --out) instead of a result"
    )
    p.add_argument("--out", default=None,
                   help="with a map: write slices of it to this PNG (.png, .pdf, .svg) instead of serving a 3D view")  # fmt: skip
    p.add_argument("--port", type=int, default=8080, help="port (default 8080; 0: any free port)")
    p.add_argument(
        "--host", default="127.0.0.1", help="address to bind (default 127.0.0.1: this machine only)"
    )
    g = p.add_argument_group("inputs in place of those the result names (moved files, or none named)")
    g.add_argument("--cloud", action="append", default=None, help="point cloud; repeat for several")
    g.add_argument(
        "--transform", action="append", default=None, help="world_T_sensor file or up vector per --cloud"
    )
    g.add_argument(
        "--floor", type=float, default=None, help="floor height [m] added under the cloud, as --floor"
    )
    g.add_argument("--occupancy", default=None, help="occupancy grid (map_server YAML)")
    g.add_argument("--surface-map", default=None, help="surface map file (surface-map's --out)")
    g.add_argument("--robot", default=None, help="robot name or robot file")


def cmd_view(args: argparse.Namespace) -> int:
    """Serve the interactive 3D viewer of any result (the demo's by default) until Ctrl-C."""
    from baseplace.viz.viewer import serve

    if not (0 <= args.port <= 65535):
        raise InputError(f"--port must be between 0 and 65535, got {args.port}")
    if args.map is not None or (args.result is not None and Path(args.result).suffix.lower() in MAP_SUFFIXES):
        return _view_map(args)
    if args.out is not None:
        raise InputError("--out draws a reachability map: give the map (view MAP.rmap --out map.png)")
    given = {"cloud": args.cloud, "transform": args.transform, "floor": args.floor, "occupancy": args.occupancy,
             "surface_map": args.surface_map, "robot": args.robot}  # fmt: skip
    serve(Path(args.result) if args.result else None, host=args.host, port=args.port, block=True, given=given)
    return 0


MAP_SUFFIXES = (".rmap", ".h5", ".hdf5")  # baseplace.jobs.reach's, without importing it for --help


def _view_map(args: argparse.Namespace) -> int:
    """A reachability map: slices to ``--out``, else its voxels in the browser."""
    from baseplace.jobs.inputs import PLOT_SUFFIXES, out_path
    from baseplace.reachability.storage import load_map

    if args.map is not None and args.result is not None:
        raise InputError(f"give the map once: {args.result} or --map {args.map}")
    out = out_path(args.out, "--out", PLOT_SUFFIXES)  # before the map is read
    rmap = load_map(args.map or args.result)
    if out is not None:
        from baseplace.viz.map_view import plot_map_slices

        plot_map_slices(rmap, out)
        print(f"wrote {out}")
        return 0
    from baseplace.viz.map_view import serve_map

    print(f"serving the map's voxels on http://{args.host}:{args.port} (Ctrl-C to stop)")
    serve_map(rmap, args.host, args.port, block=True)
    return 0
