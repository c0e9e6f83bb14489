"""Interactive 3D viewer of any baseplace result, in the browser (viser).

``baseplace view RESULT.json`` serves a three.js scene over HTTP and websocket. It reads the
``--json`` object of ``place``, ``candidates``, ``surface-map``, ``surface-sample``, ``navigate``,
``segment`` or ``demo`` (:mod:`baseplace.viz.result_view`) and the inputs that object names (cloud,
occupancy grid, surface map, robot), and draws them (:mod:`baseplace.viz.view_scene`):

* place / demo: the cloud (grey-blue by height) and its planar regions, the robot with its URDF
  meshes at the first placement's base pose and joint values, its reaching motion (the TCP's path,
  translucent copies at the start and pre-grasp configurations, a slider and Play button over the
  joint waypoints), the other placements as frames, targets and base paths;
* candidates: the occupancy grid, the cloud if any, the object, the ranked candidates (arrows, best
  darkest) with the robot and its motion at the best one, the rejected positions and the path;
* surface-map / surface-sample: the surface map's R_S heat map, the working surface, the samples
  (arrows) and the robot at the best one;
* navigate: the cloud, its regions, the path and the robot at the goal;
* segment: the cloud and the regions and borders of the JSON;
* point: the image with the hand's landmarks, the finger's line and the objects' image boxes (on the
  camera's frustum in the scene and in the panel), the objects' 3D boxes (the pointed-at one gold),
  the finger's 3D ray and, with a grid, the candidates to pick the object up as for candidates.

The demo's result also names a *view data* file (key ``"view_data"``, relative to the JSON's
directory or absolute): an ``.npz`` with the segmented scene and the OSRM heat map
(:mod:`baseplace.viz.view_data`)::

    data = view_data_from(terrain, result.osrm, points, robot_name)
    save_view_data(out_dir / "demo_view.npz", data)
    obj["view_data"] = "demo_view.npz"

The server binds to 127.0.0.1 unless told otherwise; it exposes the scene to whoever can reach
the port. A result is data: every string it carries (an error, a robot name, a file name) reaches
the page as text (:func:`markdown_text`), never as HTML or a link.
"""

from __future__ import annotations

import contextlib
import errno
import html
import io
import math
import socket
import string
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from baseplace.errors import InputError
from baseplace.geometry.poses import yaw_of
from baseplace.viz.result_view import ResultView, read_result, result_file
from baseplace.viz.view_scene import SceneInputs, build_scene, ground, load_inputs

if TYPE_CHECKING:
    import viser


def _check_port(host: str, port: int) -> None:
    """Raise a one-line InputError if ``host:port`` cannot be bound (in use, bad host)."""
    if not (0 <= port <= 65535):
        raise InputError(f"--port must be between 0 and 65535, got {port}")
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)
    except socket.gaierror as exc:
        raise InputError(f"cannot serve on host {host!r}: {exc.strerror}") from None
    family, kind, proto, _, address = infos[0]
    with socket.socket(family, kind, proto) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)  # as the server will
        try:
            sock.bind(address)
        except OSError as exc:
            if exc.errno == errno.EADDRINUSE:
                raise InputError(f"port {port} on {host} is in use; pick another with --port") from None
            raise InputError(f"cannot serve on {host}:{port}: {exc.strerror or exc}") from None


def _camera(server: viser.ViserServer, view: ResultView, inputs: SceneInputs, layers: dict[str, Any]) -> None:
    """Look at the robot (or the result's poses) from behind the path's start, high enough to see the map."""
    robot_pose = layers.get("robot_pose")
    focus = [robot_pose[:3, 3]] if robot_pose is not None else []
    # with a robot, frame it and what it reaches for; paths may lead far away
    extent = [] if focus else [np.c_[p[:, :2], ground(inputs, p[:, :2])] for p in view.paths]
    extent += [np.c_[view.candidates[:, :2], np.zeros(len(view.candidates))]] if len(view.candidates) else []
    extent += [T[None, :3, 3] for T in [rp.T_world_base for rp in view.robots[1:]]]
    extent += [T[None, :3, 3] for T in view.targets]
    if view.pointing is not None:
        extent += [view.pointing.world_boxes.reshape(-1, 3)]
        if inputs.T_world_camera is not None:
            extent.append(inputs.T_world_camera[None, :3, 3])
    if view.object_xyz is not None:
        extent.append(view.object_xyz[None])
    if inputs.surface is not None:
        extent.append(
            np.c_[inputs.surface.polygon, np.full(len(inputs.surface.polygon), inputs.surface.height)]
        )
    for region in view.regions:
        extent += [np.c_[ext, np.zeros(len(ext))] for ext, _ in region.polygons]
    pts = np.concatenate([np.atleast_2d(f) for f in focus + extent]) if focus or extent else np.zeros((0, 3))
    if not len(pts):
        if inputs.data is not None:
            h, w = inputs.data.labels.shape
            o, res = inputs.data.origin, inputs.data.resolution
            pts = np.array([[o[0], o[1], 0.0], [o[0] + w * res, o[1] + h * res, 0.0]])
        elif len(inputs.points):
            pts = np.percentile(inputs.points, [5, 95], axis=0)
        elif inputs.grid is not None:
            g = inputs.grid
            pts = np.array([[*g.origin[:2], 0.0], [g.origin[0] + g.width * g.resolution,
                                                   g.origin[1] + g.height * g.resolution, 0.0]])  # fmt: skip
        else:
            pts = np.zeros((1, 3))
    centre = (pts.min(axis=0) + pts.max(axis=0)) / 2
    size = max(float(np.ptp(pts[:, :2], axis=0).max()) if len(pts) > 1 else 3.0, 2.2 if focus else 3.0)
    look = centre if not focus else 0.65 * centre + 0.35 * focus[0]
    direction = np.array([-0.55, -0.75, 0.65])
    if view.paths and len(view.paths[0]) >= 2 and focus:
        d = view.paths[0][0, :2] - focus[0][:2]
        if np.hypot(*d) > 1e-6:
            d = d / np.hypot(*d)
            side = np.array([-d[1], d[0]])
            horiz = 0.75 * d + 0.55 * side
            direction = np.array([horiz[0], horiz[1], 0.75])
    if view.pointing is not None and inputs.T_world_camera is not None and len(view.pointing.world_boxes):
        # from the side of the line camera -> objects: the frame, the objects and the robot side by side
        d = view.pointing.world_boxes.mean(axis=(0, 1))[:2] - inputs.T_world_camera[:2, 3]
        d = d / max(float(np.hypot(*d)), 1e-6)
        horiz = -0.35 * d + 0.9 * np.array([-d[1], d[0]])
        direction = np.array([horiz[0], horiz[1], 0.8])
    direction /= np.linalg.norm(direction)
    server.initial_camera.look_at = np.asarray(look, dtype=np.float64)
    server.initial_camera.position = np.asarray(look + direction * 1.05 * size, dtype=np.float64)


def markdown_text(text: str) -> str:
    """``text`` as markdown that shows it literally, on one line.

    viser's markdown passes raw HTML through (``<iframe srcdoc=...>`` would run), and markdown
    makes links, emphasis and code of punctuation: HTML's special characters become entities
    (:func:`html.escape`), every other ASCII punctuation is backslash-escaped (CommonMark's
    escapes: no link, image, autolink, emphasis, code or table), and line breaks and other
    control characters become spaces.
    """
    out = []
    for c in " ".join(text.split()):
        if c in "&<>\"'":
            out.append(html.escape(c))
        elif c in string.punctuation:
            out.append("\\" + c)
        else:
            out.append(c if c.isprintable() else " ")
    return "".join(out)


def _gui(server: viser.ViserServer, layers: dict[str, Any], view: ResultView, robot: str | None) -> None:
    """Checkboxes that show and hide each layer, and a line about the result."""
    groups = {
        "Point cloud": [layers.get("cloud")],
        "Occupancy grid": [layers.get("occupancy")],
        "Planar regions": layers.get("regions", []),
        "OSRM heat map": [layers.get("heatmap")],
        "Surface map": layers.get("surface_map", []),
        "Robot": [layers.get("robot")],
        "Candidates": layers.get("candidates", []),
        "Rejected": [layers.get("rejected")],
        "Path": layers.get("paths", []),
        "Camera image": [layers.get("camera")],
        "Objects": [*layers.get("objects", []), layers.get("ray")],
    }
    for label, handles in groups.items():
        handles = [h for h in handles if h is not None]
        if not handles:
            continue
        box = server.gui.add_checkbox(label, initial_value=True)

        def toggle(_: Any, box: Any = box, handles: list[Any] = handles) -> None:
            for h in handles:
                h.visible = box.value

        box.on_update(toggle)
    text = f"**{markdown_text(view.command)}**: {markdown_text(view.summary)}"
    T = layers.get("robot_pose")
    if T is not None:
        yaw = math.degrees(yaw_of(T))
        text += (
            f"; **{markdown_text(str(robot))}** at x = {T[0, 3]:.2f} m, y = {T[1, 3]:.2f} m, "
            f"z = {T[2, 3]:.2f} m, yaw = {yaw:.0f}°"
        )
    server.gui.add_markdown(text)


def _robot_to_draw(view: ResultView, inputs: SceneInputs) -> str | None:
    """The robot name or file to draw: the result's, else the view data's; None when nothing needs one."""
    robot = view.robot or (inputs.data.robot if view.inputs.view_data is not None and inputs.data else None)
    if view.robots and robot is None:
        raise InputError(
            f"{view.source} ({view.command} result) names no robot; rerun it with this version of baseplace"
        )
    return robot


def open_view(
    result_json: str | Path, given: dict[str, Any] | None = None
) -> tuple[ResultView, SceneInputs, str | None]:
    """Read a result and load the inputs it names (what :func:`serve` shows), without a server.

    Args:
        result_json: the result.
        given: input files given to the viewer in place of the result's (see
            :func:`baseplace.viz.result_view.read_result`).

    Raises:
        InputError: the result is not one the viewer shows, or an input is missing or malformed.
    """
    view = read_result(result_json, given=given)
    robot = view.robot
    # segment the cloud for the regions and ground heights, unless the result carries its own
    segment = view.kind in ("place", "navigate") and view.inputs.view_data is None
    inputs = load_inputs(view, robot or "", segment)
    return view, inputs, _robot_to_draw(view, inputs)


def serve(
    result_json: str | Path | None = None,
    host: str = "127.0.0.1",
    port: int = 8080,
    block: bool = True,
    given: dict[str, Any] | None = None,
) -> viser.ViserServer:
    """Serve the 3D view of a result JSON (the demo's ``out/demo.json`` if None).

    Args:
        result_json: the ``--json`` object of place, candidates, surface-map, surface-sample,
            navigate, segment or demo, saved to a file; the inputs it names are read too.
        host: interface to bind; 127.0.0.1 (this machine only) unless told otherwise.
        port: TCP port; 0 picks a free one (see ``server.get_port()``).
        block: wait until Ctrl-C, then stop the server; False returns the running server at once
            (call ``.stop()`` on it); its scene layers are in ``server.baseplace_layers``.
        given: input files given to the viewer in place of the result's: ``cloud`` and
            ``transform`` (lists), ``floor``, ``occupancy``, ``surface_map``, ``robot``.

    Returns:
        The viser server (already stopped when ``block`` is True).

    Raises:
        InputError: the result is missing, not a result or malformed, an input it names is
            missing, the URDF does not load, or the port is in use.
    """
    import viser

    path = result_file(result_json)
    view, inputs, robot = open_view(path, given)
    _check_port(host, port)
    with contextlib.redirect_stdout(io.StringIO()):  # viser's banner; serve prints its own line
        server = viser.ViserServer(host=host, port=port, label="baseplace", verbose=False)
    if port != 0 and server.get_port() != port:  # viser moves on to the next free port silently
        server.stop()
        raise InputError(f"port {port} on {host} is in use; pick another with --port")
    try:
        layers = build_scene(server, view, inputs, robot)
        _camera(server, view, inputs, layers)
        _gui(server, layers, view, robot)
        server.baseplace_layers = layers
    except BaseException:
        server.stop()
        raise
    if not block:
        return server
    shown = f"[{host}]" if ":" in host else host
    print(f"baseplace view: http://{shown}:{server.get_port()}/ ({path}, {view.command} result); Ctrl-C to stop",
          file=sys.stderr)  # fmt: skip
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        pass
    finally:
        server.stop()
    return server
