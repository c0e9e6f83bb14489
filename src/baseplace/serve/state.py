"""What the service keeps warm between requests: robots, maps, scenes (issue 18).

Robots are built once per name (their collision model and pair tables with them), maps loaded
once per (robot, arm), and each uploaded scene keeps its cloud, its segmentation and its
obstacle set and collision environments (:class:`~baseplace.placement.scene_cache.SceneCache`).
Placements run on one worker thread (:attr:`ServiceState.executor`): pinocchio's data and coal's
trees are not shared between threads. Heavy placements run on one more, on robots of their own
(``robot(name, lane="heavy")``); map lookups on two more (``lookups``); candidates, navigation
and surface maps, on robots of their own (``robot(name, lane="commands")``), on one more
(``commands``). Each is a :class:`~baseplace.serve.lanes.FairLane`: its clients take turns.
"""

from __future__ import annotations

import json
import shutil
import tempfile
import threading
import time
import uuid
import weakref
from collections import OrderedDict
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from baseplace.errors import BaseplaceError, InputError
from baseplace.robots.defaults import DEFAULT_ROBOT
from baseplace.serve.lanes import FairLane

CLOUD_FORMATS = ("ply", "pcd", "npy", "xyz")
"""Upload formats of a scene's cloud (the ``format`` query parameter)."""

BAG_FORMATS = ("mcap", "bag")
"""Upload formats of a ROS recording: a rosbag2 ``.mcap`` file or a ROS 1 ``.bag``."""


class UnknownSceneError(BaseplaceError):
    """A request named a scene id the service does not hold (HTTP 404)."""


@dataclass(frozen=True)
class ServeSettings:
    """How the service runs.

    Attributes:
        host: address to bind; 127.0.0.1 (loopback only) unless told otherwise.
        port: TCP port (0: any free one).
        max_request_bytes: larger request bodies are refused with 413 before they are read.
        timeout_s: a request still computing after this many seconds is answered 504 [s].
        max_scenes: scenes kept; the least recently used one goes when a new one comes.
        robots: robots (built-in names) made warm at start: model, collision model, default map,
            compiled kernels.
        warm_up: run one small placement per robot at start, so that no request pays numba's
            kernel loading or the first OSRM.
        kernel_threads: numba threads of each job's compiled kernels. The service runs its
            requests side by side on its own threads; a parallel kernel in each of them would
            oversubscribe the cores (on 2 shared cores a warm OSRM took 16 ms with numba's 2
            threads, 1.9 ms with 1).
        token: API token every request but /health and the docs must send as
            ``Authorization: Bearer TOKEN``; required when ``host`` is not loopback.
        allow_hosts: more names the ``Host`` header may give (besides loopback and ``host``).
        allow_origins: web origins (``https://app.example:8443``) whose pages may call the
            service; none by default (a browser page's own origin is the service's).
        max_queue: jobs waiting or running per lane (placements, heavy placements, commands,
            lookups); more get 503 with ``Retry-After``.
        max_client_queue: jobs one client (one peer address) may have waiting or running per
            lane; more get 429 with ``Retry-After``. In the heavy lane a client has one.
        heavy_work: a ``/place`` whose work, targets x (tries + placements x robustness
            samples), is over this runs in the heavy lane (one thread of its own), so that
            cheap placements never wait behind it.
        read_timeout_s: request headers must be complete, and a body must not stall, within
            this many seconds; a whole body within 4 times that [s].
        max_inflight_bytes: request bodies being received, all together; past it 503.
        max_connections: open connections, and requests in flight; a request past it gets 503
            (:class:`~baseplace.serve.guard.TimedH11Protocol`).
    """

    host: str = "127.0.0.1"
    port: int = 8000
    max_request_bytes: int = 64 * 1024 * 1024
    timeout_s: float = 30.0
    max_scenes: int = 16
    robots: tuple[str, ...] = (DEFAULT_ROBOT,)
    warm_up: bool = True
    kernel_threads: int = 1
    token: str | None = None
    allow_hosts: tuple[str, ...] = ()
    allow_origins: tuple[str, ...] = ()
    max_queue: int = 16
    max_client_queue: int = 8
    heavy_work: int = 500
    read_timeout_s: float = 10.0
    max_inflight_bytes: int = 256 * 1024 * 1024
    max_connections: int = 128

    def __post_init__(self) -> None:
        if not (0 <= self.port <= 65535):
            raise InputError(f"port must be in 0..65535, got {self.port}")
        if self.max_request_bytes < 1024:
            raise InputError(f"max_request_bytes must be >= 1024, got {self.max_request_bytes}")
        if not (self.timeout_s > 0):
            raise InputError(f"timeout_s must be > 0, got {self.timeout_s}")
        if self.kernel_threads < 1:
            raise InputError(f"kernel_threads must be >= 1, got {self.kernel_threads}")
        if self.max_scenes < 1:
            raise InputError(f"max_scenes must be >= 1, got {self.max_scenes}")
        if self.max_queue < 1:
            raise InputError(f"max_queue must be >= 1, got {self.max_queue}")
        if self.max_client_queue < 1:
            raise InputError(f"max_client_queue must be >= 1, got {self.max_client_queue}")
        if self.heavy_work < 1:
            raise InputError(f"heavy_work must be >= 1, got {self.heavy_work}")
        if not (self.read_timeout_s > 0):
            raise InputError(f"read_timeout_s must be > 0, got {self.read_timeout_s}")
        if self.max_inflight_bytes < self.max_request_bytes:
            raise InputError(
                f"max_inflight_bytes ({self.max_inflight_bytes}) must be >= max_request_bytes "
                f"({self.max_request_bytes}): one request of the largest size must fit"
            )
        if self.max_connections < 1:
            raise InputError(f"max_connections must be >= 1, got {self.max_connections}")
        if self.token is not None and len(self.token) < 16:
            raise InputError("the API token must be at least 16 characters (e.g. python -c "
                             "'import secrets; print(secrets.token_urlsafe())')")  # fmt: skip
        if not is_loopback(self.host) and self.token is None:
            raise InputError(
                f"serving on {self.host} (reachable from other machines) needs an API token: "
                "--token or $BASEPLACE_TOKEN"
            )


def is_loopback(host: str) -> bool:
    """True for an address only this machine reaches (127.0.0.0/8, ::1, localhost)."""
    import ipaddress

    if host.strip("[]").lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


@dataclass
class Scene:
    """An uploaded scene: its cloud (also as a file, for commands that read one) and its cache."""

    id: str
    folder: Path
    cache: Any  # SceneCache
    points: int
    source: str
    created: float = field(default_factory=time.time)
    grid_yaml: Path | None = None
    grid: Any = None  # the OccupancyGrid read from grid_yaml
    segmentation_error: str | None = None  # why the cloud has no regions (a scene with a grid only)
    obstacles: tuple[str, ...] = ()  # boxes and cylinders given on upload, checked in every job on the scene
    _cloud: Any = field(default=None, repr=False)

    @property
    def cloud(self) -> Any:
        """The scene's points as a :class:`~baseplace.terrain.io.Cloud`, checked once."""
        if self._cloud is None:
            from baseplace.terrain.io import Cloud

            self._cloud = Cloud(self.cache.points, source="points")
        return self._cloud

    @property
    def cloud_file(self) -> Path:
        """The scene's cloud as an .npy file (N, 3) float64 [m]."""
        return self.folder / "cloud.npy"


def _kernel_threads(n: int) -> None:
    """Numba's threads for the kernels this thread calls (numba keeps the number per thread)."""
    import numba

    numba.set_num_threads(min(n, numba.config.NUMBA_NUM_THREADS))  # type: ignore[attr-defined]


class ServiceState:
    """Robots, maps and scenes of one running service."""

    def __init__(self, settings: ServeSettings) -> None:
        self.settings = settings
        self.started = time.time()
        n = (settings.kernel_threads,)
        self.executor = FairLane("job", 1, _kernel_threads, n)
        # a placement over settings.heavy_work: on a thread and robots of its own, so that the
        # cheap ones never wait behind it
        self.heavy = FairLane("heavy", 1, _kernel_threads, n)
        # map lookups only read the map: they need not wait behind a placement
        self.lookups = FairLane("lookup", 2, _kernel_threads, n)
        # candidates, navigation and surface maps: one at a time, beside the placements, on robots of their own
        self.commands = FairLane("command", 1, _kernel_threads, n)
        self.folder = Path(tempfile.mkdtemp(prefix="baseplace-serve-"))
        # deleted by close(), or when the state is collected or the process exits without it
        self._remove_folder = weakref.finalize(self, shutil.rmtree, str(self.folder), ignore_errors=True)
        self._robots: dict[str, Any] = {}
        self._lane_robots: dict[str, dict[str, Any]] = {}  # lane -> robots of its own thread
        self._maps: dict[tuple[str, str | None], Any] = {}
        self._scenes: OrderedDict[str, Scene] = OrderedDict()
        self._lock = threading.Lock()  # scenes are added from the worker and read from the loop
        self.requests = 0
        self.inflight_bytes = 0  # request bodies being received (the event loop's count)
        self.queued: dict[str, int] = {
            "jobs": 0,
            "heavy": 0,
            "commands": 0,
            "lookups": 0,
        }  # waiting or running
        self.client_queued: dict[tuple[str, str], int] = {}  # (lane, client) -> its jobs waiting or running
        self.deadlines: set[Any] = set()  # of the jobs submitted and not ended: cancelled at shutdown
        self.closing = False

    def stop_jobs(self) -> None:
        """Shutting down: every job stops at its next deadline check, no new one starts (any thread)."""
        self.closing = True
        for deadline in list(self.deadlines):
            deadline.cancel()

    # ---- robots and maps (worker thread only) ----
    def robot(self, name: str, lane: str = "jobs") -> Any:
        """The robot of a built-in name, built once per lane.

        ``lane``: "jobs" (the worker thread's robots) or "commands" (the command thread's own
        copies: pinocchio's data and coal's trees are not shared between threads).
        """
        from baseplace.robots.spec import BUILTIN_ROBOTS

        if name not in BUILTIN_ROBOTS:
            raise InputError(f"unknown robot {name!r}; valid: {', '.join(BUILTIN_ROBOTS)}")
        robots = self._robots if lane == "jobs" else self._lane_robots.setdefault(lane, {})
        if name not in robots:
            from baseplace.robots.model import Robot

            robots[name] = Robot(name)
        return robots[name]

    def reach_map(self, robot: Any, arm: str | None) -> Any:
        """The robot's cached default map for ``arm`` (default arm: None), loaded once (read only: any thread)."""
        key = (robot.name, arm)
        if key not in self._maps:
            from baseplace.reachability.cache import map_or_default

            if arm is not None and arm not in robot.spec.arms:
                raise InputError(f"unknown arm {arm!r} of {robot.name}; valid: {', '.join(robot.spec.arms)}")
            self._maps[key] = map_or_default(robot, None, arm)
            self._maps[key].tables  # noqa: B018  the lookup tables, built now, not in a query
        return self._maps[key]

    def use_map(self, robot: Any, rmap: Any) -> None:
        """Answer ``robot``'s requests for the map's arm (and the default arm, if it is that) with ``rmap``."""
        from baseplace.reachability.storage import check_map_matches

        check_map_matches(rmap, robot, rmap.info.arm, "the given map")
        self._robots[robot.name] = robot
        self._maps[(robot.name, rmap.info.arm)] = rmap
        if rmap.info.arm == robot.spec.default_arm:
            self._maps[(robot.name, None)] = rmap

    def is_warm(self, robot: str, arm: str | None) -> bool:
        """True when the robot and its map for ``arm`` are loaded (lookups may then run beside jobs)."""
        return (robot, arm) in self._maps

    # ---- scenes ----
    def add_scene(
        self,
        data: bytes,
        fmt: str,
        bag: dict[str, Any] | None = None,
        transform: str | None = None,
        floor: float | None = None,
        fuse: float | None = None,
        obstacles: Sequence[str] | None = None,
    ) -> Scene:
        """A scene from an uploaded cloud or recording (worker thread): checked, saved, segmented.

        The cloud is read as the CLI's ``--cloud``/``--bag`` reads it
        (:func:`baseplace.jobs.inputs.world_cloud`): through ``transform``, else checked z up.

        Args:
            data: the uploaded file.
            fmt: its format (:data:`CLOUD_FORMATS`, :data:`BAG_FORMATS`).
            bag: for a recording, ``cloud_topics``, ``map_topic``, ``world_frame`` and ``clouds``
                as :func:`baseplace.io.bag.read_bag` takes them; its grid, if any, becomes the scene's.
            transform: a cloud file's ``--transform``: the sensor-frame up vector "ux uy uz", or
                ``T_world_sensor`` as 16 numbers row by row (what the CLI reads from a file).
            floor: ``--floor``: a floor plane at this height [m] under and around the cloud.
            fuse: ``--fuse --fuse-miss P``: fuse the clouds into an OctoMap by ray casting from each
                sensor origin, a ray passing a voxel with occupancy probability P (None: no fusion).
            obstacles: ``--obstacle`` boxes and cylinders [m, rad] that belong to the scene: every
                ``/place``, ``/explain`` and ``/candidates`` on it checks them, before its own.
        """
        from baseplace.files import write_bytes
        from baseplace.jobs.inputs import BagInput, CloudInput, occupancy_grid, world_cloud
        from baseplace.placement.scene_cache import SceneCache

        if fmt not in CLOUD_FORMATS + BAG_FORMATS:
            raise InputError(f"unknown format {fmt!r}; valid: {', '.join(CLOUD_FORMATS + BAG_FORMATS)}")
        if not data:
            raise InputError("the upload is empty: send the cloud or recording file as the request body")
        if transform is not None and fmt in BAG_FORMATS:
            raise InputError("transform is for a cloud file: a recording's clouds are posed by its /tf")
        if obstacles:
            from baseplace.world.obstacles import parse_obstacles

            parse_obstacles(obstacles, "obstacle")  # checked before the upload is read
        scene_id = uuid.uuid4().hex[:16]
        folder = self.folder / scene_id
        folder.mkdir(mode=0o700)
        grid = None
        fusion: dict[str, Any] = {} if fuse is None else {"fuse": True, "fuse_miss": fuse}
        try:
            upload = folder / f"upload.{fmt}"
            write_bytes(upload, data, "the upload")
            if fmt in BAG_FORMATS:
                b = bag or {}
                if not b.get("cloud_topics"):
                    raise InputError("with a recording, give the cloud topic: cloud_topic=/camera/points")
                source = CloudInput(bag=BagInput(str(upload), tuple(b["cloud_topics"]), b.get("map_topic"),
                                                 b.get("world_frame", "map"), b.get("clouds", "last")),
                                    **fusion)  # fmt: skip
                points = world_cloud(source).points
                if len(points) == 0:
                    raise InputError("the recording's cloud topics hold no points")
                grid = occupancy_grid(None, source.bag, source)
            else:
                transforms = [] if transform is None else [_transform_file(folder, transform)]
                points = world_cloud(
                    CloudInput([str(upload)], transforms, **fusion)
                ).points  # the CLI's checks
            if floor is not None:
                from baseplace.placement.pipeline import with_floor

                check_floor(points, floor)
                points = with_floor(points, floor)
            points = np.ascontiguousarray(points, dtype=np.float64)
            upload.unlink()
            _save_npy(folder / "cloud.npy", points)
            cache = SceneCache(points)
            cache.prepare()  # the cloud's bounds and near-point grid: no query builds them
            scene = Scene(
                scene_id, folder, cache, len(points), f"upload.{fmt}", obstacles=tuple(obstacles or ())
            )
            try:
                cache.terrain()  # the segmentation, once per scene
            except InputError as exc:
                if grid is None:
                    raise
                # the grid's free cells are the floor (place --occupancy needs no regions of the cloud)
                scene.segmentation_error = str(exc)
            if scene.segmentation_error is None:
                from baseplace.placement.pipeline import scene_environment

                for robot in list(self._robots.values()):  # the obstacle tree, before the first query
                    scene_environment(robot, cache)
            if grid is not None:
                _attach_grid_values(scene, grid)
        except BaseException:
            shutil.rmtree(folder, ignore_errors=True)
            raise
        with self._lock:
            self._scenes[scene_id] = scene
            while len(self._scenes) > self.settings.max_scenes:
                _, old = self._scenes.popitem(last=False)
                shutil.rmtree(old.folder, ignore_errors=True)
        return scene

    def scene(self, scene_id: str) -> Scene:
        """The scene of an id, most recently used now; 404 if unknown."""
        with self._lock:
            scene = self._scenes.get(scene_id)
            if scene is None:
                raise UnknownSceneError(
                    f"unknown scene id {scene_id!r}: upload the cloud with POST /scenes first "
                    f"({len(self._scenes)} scene(s) held)"
                )
            self._scenes.move_to_end(scene_id)
            return scene

    def drop_scene(self, scene_id: str) -> None:
        """Forget a scene and delete its files."""
        with self._lock:
            scene = self._scenes.pop(scene_id, None)
        if scene is None:
            raise UnknownSceneError(f"unknown scene id {scene_id!r}")
        shutil.rmtree(scene.folder, ignore_errors=True)

    def scene_ids(self) -> list[str]:
        """Ids of the scenes held, least recently used first."""
        with self._lock:
            return list(self._scenes)

    def close(self, wait_s: float | None = None) -> None:
        """Cancel every job, wait up to ``wait_s`` (default: the time limit) for them, delete the scenes' files.

        A job stops at its next deadline check; one that does not within ``wait_s`` is left to
        the process's exit (the worker threads are daemons of a process that is ending).
        """
        self.stop_jobs()
        pools = (self.lookups, self.commands, self.heavy, self.executor)
        for pool in pools:
            pool.shutdown(wait=False, cancel_futures=True)
        end = time.monotonic() + (self.settings.timeout_s if wait_s is None else wait_s)
        for pool in pools:
            for thread in pool.threads:
                thread.join(max(0.0, end - time.monotonic()))
        self._remove_folder()


MAX_FLOOR_POINTS = 4_000_000
"""Points of the floor one upload may add (``floor``): a 2 cm grid over the cloud's xy extent and
2 m around it; 4e6 points cover 40 x 40 m."""


def check_floor(points: np.ndarray, floor: float) -> None:
    """Refuse a floor under ``points`` (N, 3) [m] of more than :data:`MAX_FLOOR_POINTS` points, before it is made."""
    from baseplace.jobs.inputs import points_bounds

    lo, hi = points_bounds(points)
    margin, spacing = 2.0, 0.02  # with_floor's defaults
    size = hi[:2] - lo[:2] + 2 * margin
    n = float(np.prod(np.ceil(size / spacing)))
    if n > MAX_FLOOR_POINTS:
        raise InputError(
            f"a floor under the cloud ({size[0]:.0f} x {size[1]:.0f} m with 2 m around it, 2 cm apart) "
            f"is {n:.3g} points, over the limit of {MAX_FLOOR_POINTS:.0e} for one upload: a smaller cloud"
        )


def _transform_file(folder: Path, spec: str) -> str:
    """The file of a cloud's ``transform`` ("ux uy uz", or 16 numbers of ``T_world_sensor`` row by row).

    Written into the scene's folder and read back by the CLI's reader, so that the CLI's checks
    apply; a request never names a file of the server.
    """
    from baseplace.errors import brief
    from baseplace.files import write_bytes
    from baseplace.terrain.io import up_vector_transform

    try:
        numbers = [float(v) for v in spec.replace(",", " ").split()]
    except ValueError:
        numbers = []
    if len(numbers) not in (3, 16) or not np.isfinite(numbers).all():
        raise InputError(
            f"transform {brief(spec)}: give the sensor-frame up vector 'ux uy uz' or the 16 numbers of "
            "T_world_sensor row by row"
        )
    T = up_vector_transform(numbers) if len(numbers) == 3 else np.reshape(numbers, (4, 4))
    path = folder / "transform.txt"
    write_bytes(
        path, "\n".join(" ".join(repr(float(v)) for v in row) for row in T).encode() + b"\n", "transform"
    )
    return str(path)


def write_grid_files(scene: Scene, image: bytes, suffix: str, meta: dict[str, Any]) -> tuple[Path, Path]:
    """A map_server image and its YAML (``meta``: the YAML's fields) in the scene's folder; their paths.

    Under a new name: a new grid never breaks the one the scene has until it is read.
    """
    import uuid

    from baseplace.files import write_bytes

    if suffix not in ("pgm", "png"):
        raise InputError(f"unknown grid image format {suffix!r}; valid: pgm, png")
    if not image:
        raise InputError("the upload is empty: send the grid image as the request body")
    name = f"grid-{uuid.uuid4().hex[:8]}"
    image_path, yaml_path = scene.folder / f"{name}.{suffix}", scene.folder / f"{name}.yaml"
    write_bytes(image_path, image, "the grid image")
    origin = [float(meta["origin_x"]), float(meta["origin_y"]), float(meta["origin_yaw"])]
    doc = {"image": image_path.name, "resolution": float(meta["resolution"]), "origin": origin,
           "negate": int(bool(meta["negate"])), "occupied_thresh": float(meta["occupied_thresh"]),
           "free_thresh": float(meta["free_thresh"]), "mode": str(meta["mode"])}  # fmt: skip
    try:
        write_bytes(yaml_path, (json.dumps(doc) + "\n").encode(), "the grid's YAML")  # JSON is YAML
    except BaseException:
        image_path.unlink(missing_ok=True)
        raise
    return image_path, yaml_path


def attach_grid(scene: Scene, image_path: Path, yaml_path: Path) -> None:
    """Read the grid files back and make them the scene's grid (on failure they are deleted)."""
    from baseplace.world.occupancy import load_occupancy

    try:
        grid = load_occupancy(yaml_path)
    except BaseException:
        image_path.unlink(missing_ok=True)
        yaml_path.unlink(missing_ok=True)
        raise
    scene.grid_yaml, scene.grid = yaml_path, grid


def _attach_grid_values(scene: Scene, grid: Any) -> None:
    """Attach an :class:`~baseplace.world.occupancy.OccupancyGrid` (e.g. a recording's) as map_server files.

    Written in map_server's ``raw`` mode (a pixel is the cell value, 255 unknown), which reads
    back cell for cell.
    """
    import cv2

    values = np.asarray(grid.data)
    pixels = np.where((values >= 0) & (values <= 100), values, 255).astype(np.uint8)[::-1]
    ok, png = cv2.imencode(".png", pixels)
    if not ok:
        raise InputError("cannot encode the recording's occupancy grid")
    x, y, yaw = (float(v) for v in grid.origin)
    meta = {"resolution": grid.resolution, "origin_x": x, "origin_y": y, "origin_yaw": yaw, "negate": False,
            "occupied_thresh": 0.65, "free_thresh": 0.196, "mode": "raw"}  # fmt: skip
    attach_grid(scene, *write_grid_files(scene, png.tobytes(), "png", meta))


def _save_npy(path: Path, points: np.ndarray) -> None:
    """``points`` as an .npy file, written atomically."""
    from baseplace.files import atomic_write

    with atomic_write(path, "the scene's cloud") as tmp, open(tmp, "wb") as f:
        np.save(f, points, allow_pickle=False)
