"""The viewer job: a result (or a reachability map) in the browser, or a map's slices in a figure.

Unlike the other jobs it returns no report: it serves until Ctrl-C (or writes the figure), and
tells the front end where through ``announce`` before it blocks.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from baseplace.errors import InputError
from baseplace.jobs.inputs import PLOT_SUFFIXES, out_path
from baseplace.jobs.reach import MAP_SUFFIXES


@dataclass
class ViewJob:
    """The inputs of :func:`view_job`.

    Attributes:
        result: a result JSON (the demo's ``out/demo.json`` if None and no map), or a reachability
            map (by its suffix, :data:`~baseplace.jobs.reach.MAP_SUFFIXES`).
        map: a reachability map to draw instead of a result.
        out: with a map, write its slices to this figure (.png, .pdf, .svg) instead of serving.
        host: address to bind.
        port: TCP port (0: any free one).
        given: input files given in place of the result's (:func:`baseplace.viz.viewer.serve`).
    """

    result: str | None = None
    map: str | None = None
    out: str | None = None
    host: str = "127.0.0.1"
    port: int = 8080
    given: dict[str, Any] = field(default_factory=dict)


def view_job(job: ViewJob, announce: Callable[[str], None] = lambda line: None) -> int:
    """Serve the 3D view of a result or a map until Ctrl-C, or write a map's slices; returns 0.

    ``announce`` gets one line: the figure written, or where a map's voxels are served (the
    result viewer prints its own address on stderr, :func:`baseplace.viz.viewer.serve`).

    Raises:
        InputError: a bad port, the map given twice, ``out`` without a map or with another
            suffix, or a result or map that cannot be read.
    """
    if not (0 <= job.port <= 65535):
        raise InputError(f"--port must be between 0 and 65535, got {job.port}")
    if job.map is not None or (job.result is not None and Path(job.result).suffix.lower() in MAP_SUFFIXES):
        return _view_map(job, announce)
    if job.out is not None:
        raise InputError("--out draws a reachability map: give the map (view MAP.rmap --out map.png)")
    from baseplace.viz.result_view import result_file

    path = result_file(job.result)  # before the viewer's imports
    from baseplace.viz.viewer import serve

    serve(path, host=job.host, port=job.port, block=True, given=job.given)
    return 0


def _view_map(job: ViewJob, announce: Callable[[str], None]) -> int:
    """A reachability map: slices to ``out``, else its voxels in the browser."""
    from baseplace.reachability.storage import load_map

    if job.map is not None and job.result is not None:
        raise InputError(f"give the map once: {job.result} or --map {job.map}")
    out = out_path(job.out, "--out", PLOT_SUFFIXES)  # before the map is read
    path = job.map or job.result
    assert path is not None
    rmap = load_map(path)
    if out is not None:
        from baseplace.viz.map_view import plot_map_slices

        plot_map_slices(rmap, out)
        announce(f"wrote {out}")
        return 0
    from baseplace.viz.map_view import serve_map

    announce(f"serving the map's voxels on http://{job.host}:{job.port} (Ctrl-C to stop)")
    serve_map(rmap, job.host, job.port, block=True)
    return 0
