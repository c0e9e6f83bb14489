"""``baseplace serve``: the HTTP/JSON front end (FastAPI on uvicorn), a thin translation to the jobs.

Every job's answer is the jobs layer's ``baseplace.result/1`` report, the CLI's ``--json`` for the
same inputs. Errors carry ``"error": "<the CLI's one line>"``: 400 (bad input, the CLI's exit 2)
and, on a job's endpoint, 404 (unknown scene id) and 422 (a request that does not fit the
schema) answer the CLI's failure report of that kind (``exit_code`` 2); the HTTP-level refusals
of :mod:`baseplace.serve.guard` (400, 401, 403, 408, 413, 415, 503), a full queue (503), a
request over the time limit (504, its job stopped) and an internal failure (500, one generic
line) answer ``{"error": ...}``. A job that ran and found nothing answers 200 with its report
(``exit_code`` 3, ``error``) and ``"found": false``. No error line carries more than a short
escaped excerpt of what the client sent.
"""

from __future__ import annotations

import asyncio
import functools
import json
import time
from collections.abc import Callable
from typing import Annotated, Any, Literal

import numpy as np
from fastapi import FastAPI, Query, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from pydantic import BaseModel, ConfigDict, Field, StringConstraints, model_validator
from starlette.exceptions import HTTPException

from baseplace.errors import BaseplaceError
from baseplace.placement.deadline import Deadline, DeadlineExceeded, limited
from baseplace.robots.defaults import DEFAULT_ROBOT
from baseplace.serve import jobs
from baseplace.serve.guard import CLIENT, Guard, authorized
from baseplace.serve.state import ServeSettings, ServiceState, UnknownSceneError

STRATEGIES = Literal["MR", "TO", "MRTO", "orm", "grid", "random"]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", allow_inf_nan=False)  # NaN, Infinity, 1e999: 422


Pose = Annotated[str, StringConstraints(max_length=200)]
Obstacle = Annotated[str, StringConstraints(max_length=200, pattern=r"^\s*(?i:box|cylinder)\s")]
"""A box or cylinder obstacle: a mesh file would name a path on the server."""
"""A pose as text ("x y z roll pitch yaw", "x y yaw"): short, so that no answer echoes much."""

SEED = Field(0, ge=0, le=2**32 - 1, description="random seed")

MAX_PLACE_WORK = 20_000
"""targets x tries of one /place: what one request finishes within the default 30 s time limit."""

MAX_ROBUSTNESS_WORK = 16_384
"""targets x robustness samples x placements of one request (error draws checked by IK and collision)."""
MOTION_DRAW_COST = 100
"""A draw with ``robustness_motion`` counts as this many: a reaching-motion check costs about as much
as 100 IK + collision checks (0.2-1 s on the table grid)."""

MAX_SURFACE_CELLS = 4_000_000
"""Cells x orientations of one /surface-map (the polygon's bounding box at the resolution)."""


def _robustness_work(targets: int, samples: int, placements: int, motion: bool) -> None:
    work = targets * samples * placements * (MOTION_DRAW_COST if motion else 1)
    if work > MAX_ROBUSTNESS_WORK:
        weight = f" x {MOTION_DRAW_COST} (robustness_motion)" if motion else ""
        raise ValueError(
            f"targets x robustness_samples x placements{weight} = {work} is over the limit of "
            f"{MAX_ROBUSTNESS_WORK} for one request: fewer samples or placements"
        )


class RobustnessFields(_Model):
    """The CLI's reaching-motion and robustness options (``place``, ``candidates``)."""

    no_motion_check: bool = Field(False, description="skip the reaching-motion check")
    robustness_samples: int = Field(64, ge=0, le=1024, description="base-error draws per placement (0: none)")
    rank_by_robustness: bool = Field(False, description="most robust placements first")
    min_robustness: float = Field(0.0, ge=0.0, le=1.0, description="reject placements below this rate")
    robustness_motion: bool = Field(
        False, description="a draw counts only if the reaching motion from it exists too (slow)"
    )
    error_model: Literal["gaussian", "box"] = "gaussian"
    sigma_xy: float = Field(0.03, ge=0.0, le=10.0, description="base position error sigma [m]")
    sigma_yaw_deg: float = Field(2.0, ge=0.0, le=180.0, description="base heading error sigma [deg]")
    xy_tolerance: float = Field(0.25, gt=0.0, le=10.0, description="goal xy tolerance [m]")
    yaw_tolerance: float | None = Field(
        None,
        gt=0.0,
        le=360.0,
        description="goal yaw tolerance [rad, deg with degrees] (default 0.25 rad, Nav2's)",
    )


DEGREES = Field(
    False,
    description="the angles of this request (pose headings, roll/pitch/yaw, an object box's yaw, "
    "yaw_tolerance) are in degrees; without it radians, and values beyond 2 pi are refused",
)


class PlaceRequest(RobustnessFields):
    """``baseplace place`` on an uploaded scene."""

    scene_id: str = Field(..., max_length=64, description="id from POST /scenes")
    targets: list[Pose] = Field([], max_length=16,
                                description='TCP targets "x y z roll pitch yaw" [m, rad]')  # fmt: skip
    grasp_points: list[Pose] = Field([], max_length=16,
                                     description='instead of targets: poses of the point between the fingertips '
                                                 '"x y z roll pitch yaw" [m, rad] (TIAGo: 0.151 m ahead of the TCP)')  # fmt: skip
    robot: str = Field(DEFAULT_ROBOT, max_length=64, description="built-in robot name")
    arm: str | None = Field(None, max_length=64, description="arm (default: the robot's default arm)")
    strategy: STRATEGIES = "MR"
    placements: int = Field(1, ge=1, le=20, description="M: placements to return")
    tries: int = Field(100, ge=1, le=2_000, description="N: candidates to check at most")
    seed: int = SEED
    object: str = Field("auto", max_length=200, description='"auto", "none", "box x y z sx sy sz [yaw]" ...')
    resolution: float | None = Field(None, ge=0.005, le=1.0, description="height-map cell [m]")
    clearance: float | None = Field(None, ge=0.0, le=0.1, allow_inf_nan=False,
                                    description="keep this far [m] from the scene near the grasped object "
                                                "(default: 3 sigma of the support plane's residuals)")  # fmt: skip
    stand_on: Literal["ground", "any"] = Field("ground", description="where the base may stand: the ground and "
                                               "what it can drive onto (ground), or every planar region (any)")  # fmt: skip
    start: Pose | None = Field(
        None, description='current base pose "x y yaw": also plan a path to each placement'
    )
    planner: Literal["rrt", "regions"] = Field("rrt", description="path planner with start (OMPL RRTConnect or "
                                               "the region graph; on a scene with a grid, the grid's)")  # fmt: skip
    use_grid: bool = Field(True, description="the scene's occupancy grid, if it has one (a recording's map topic "
                           "or POST /scenes/{id}/grid), as the CLI's --occupancy: its free cells are floor")  # fmt: skip
    degrees: bool = DEGREES
    obstacles: list[Obstacle] = Field(default_factory=list, max_length=16,
                                      description='collision objects beside the cloud, world frame: "box X Y Z SX SY '
                                                  'SZ [YAW]" or "cylinder X Y Z RADIUS HEIGHT" [m, rad]; no mesh files')  # fmt: skip

    @model_validator(mode="after")
    def _work(self) -> PlaceRequest:
        targets = len(self.targets) + len(self.grasp_points)
        if not targets:
            raise ValueError('give targets (TCP poses "x y z roll pitch yaw") or grasp_points (the point between '
                             "the fingertips), at least one")  # fmt: skip
        work = targets * self.tries
        if work > MAX_PLACE_WORK:
            raise ValueError(
                f"targets x tries = {work} is over the limit of {MAX_PLACE_WORK} for one request: fewer tries"
            )
        _robustness_work(targets, self.robustness_samples, self.placements, self.robustness_motion)
        return self

    @property
    def work(self) -> int:
        """What the request may cost at most: targets x (tries + placements x robustness samples).

        Candidates checked and error draws checked cost about the same (an IK and a collision
        check each, about 2 ms on one core), for every target.
        """
        targets = len(self.targets) + len(self.grasp_points)
        draws = self.robustness_samples * (MOTION_DRAW_COST if self.robustness_motion else 1)
        return targets * (self.tries + self.placements * draws)


class ExplainRequest(_Model):
    """``baseplace explain``: every check of ``place`` at one base pose for one target."""

    scene_id: str | None = Field(None, max_length=64,
                                 description="id from POST /scenes (none: IK and self-collision only)")  # fmt: skip
    base: Pose = Field(
        ..., description='base pose "x y yaw" [m, rad]; on a scene it stands on the region under (x, y)'
    )
    target: Pose | None = Field(None, description='TCP target "x y z roll pitch yaw" [m, rad]')
    grasp_point: Pose | None = Field(None, description="instead of target: the pose of the point between the "
                                     'fingertips "x y z roll pitch yaw" [m, rad]')  # fmt: skip
    robot: str = Field(DEFAULT_ROBOT, max_length=64, description="built-in robot name")
    arm: str | None = Field(None, max_length=64, description="arm (default: the robot's default arm)")
    object: str = Field("auto", max_length=200, description='"auto", "none", "box x y z sx sy sz [yaw]" ...')
    resolution: float | None = Field(None, ge=0.005, le=1.0, description="height-map cell [m]")
    clearance: float | None = Field(None, ge=0.0, le=0.1, allow_inf_nan=False,
                                    description="keep this far [m] from the scene near the grasped object, as place's")  # fmt: skip
    stand_on: Literal["ground", "any"] = Field("ground", description="where the base may stand, as place's")
    no_motion_check: bool = Field(False, description="skip the reaching-motion check, as place's")
    seed: int = SEED
    degrees: bool = DEGREES
    obstacles: list[Obstacle] = Field(default_factory=list, max_length=16,
                                      description="collision objects beside the cloud, as place's")  # fmt: skip


class CandidatesRequest(RobustnessFields):
    """``baseplace candidates`` on an uploaded scene with a grid (seed 004)."""

    scene_id: str = Field(..., max_length=64)
    object: str = Field(..., max_length=100, description='object position "x y z" [m]')
    robot_pose: str | None = Field(None, max_length=100, description='robot pose "x y yaw"')
    method: Literal["radial", "irm"] = "radial"
    robot: str = Field(DEFAULT_ROBOT, max_length=64)
    arm: str | None = Field(None, max_length=64)
    standoff: float | None = Field(None, ge=0.0, le=1.0)
    clearance: float | None = Field(None, ge=0.0, le=0.1, allow_inf_nan=False,
                                    description="as /place's: keep this far [m] from the scene near the object")  # fmt: skip
    seed: int = SEED
    object_shape: str = Field("auto", max_length=200)
    use_cloud: bool = Field(True, description="verify against the scene's cloud (else the grid alone)")
    degrees: bool = DEGREES

    @model_validator(mode="after")
    def _work(self) -> CandidatesRequest:
        _robustness_work(1, self.robustness_samples, 1, self.robustness_motion)
        return self


class PointRequest(RobustnessFields):
    """``baseplace point`` on one RGB-D frame sent in the body (base64); with ``scene_id``, its grid's candidates.

    The frame is ``rgb``, ``depth``, ``intrinsics`` and ``transform``, or a recording, ``bag``, with its
    three topics (the CLI's ``--bag``: the camera posed by the recording's tf).
    """

    rgb: str | None = Field(None, description="RGB image file (PNG or JPEG), base64")
    rgb_format: Literal["png", "jpg"] = "png"
    depth: str | None = Field(
        None, description="depth image file (16-bit PNG [mm] or float32 .npy [m]), base64"
    )
    depth_format: Literal["png", "npy"] = "png"
    intrinsics: str | None = Field(None, max_length=200, description='"fx fy cx cy" [px]')
    transform: str | None = Field(
        None, max_length=2000, description='T_world_camera: 16 numbers row by row, or "ux uy uz"'
    )
    bag: str | None = Field(None, description="instead of the four above: a ROS recording file, base64")
    bag_format: Literal["mcap", "bag"] = Field("mcap", description="rosbag2 .mcap file or ROS 1 .bag")
    rgb_topic: str | None = Field(None, max_length=200, description="recording: the colour sensor_msgs/Image")
    depth_topic: str | None = Field(None, max_length=200, description="recording: the aligned depth Image")
    camera_info_topic: str | None = Field(None, max_length=200, description="recording: the CameraInfo")
    world_frame: str = Field("map", max_length=200, description="recording: the frame tf poses the camera in")
    bag_frame: Literal["last", "first"] = Field("last", description="recording: which colour image")
    landmarks: list[list[float]] | None = Field(
        None,
        max_length=21,
        description="21 MediaPipe landmarks [x, y, z]; [] no hand; none: MediaPipe's hand model",
    )
    selection: Literal["finger3d", "first", "nearest"] = "finger3d"
    scene_id: str | None = Field(None, max_length=64, description="a scene with a grid: also the candidates")
    robot_pose: str | None = Field(None, max_length=100, description='robot pose "x y yaw"')
    robot: str = Field(DEFAULT_ROBOT, max_length=64)
    arm: str | None = Field(None, max_length=64)
    seed: int = SEED

    @model_validator(mode="after")
    def _one_frame(self) -> PointRequest:
        files = (self.rgb, self.depth, self.intrinsics, self.transform)
        if not ((self.bag is None and None not in files) or (self.bag is not None and files == (None,) * 4)):
            raise ValueError(
                "give rgb, depth, intrinsics and transform, or bag (a ROS recording) in place of all four"
            )
        if self.bag is not None:
            missing = [
                k for k in ("rgb_topic", "depth_topic", "camera_info_topic") if getattr(self, k) is None
            ]
            if missing:
                raise ValueError(f"with bag, give {', '.join(missing)}")
        return self


class ReachRequest(_Model):
    """``baseplace reach`` on the robot's default map: targets and bases paired row by row."""

    targets: list[Pose] = Field(..., min_length=1, max_length=10_000)
    bases: list[Pose] = Field(..., min_length=1, max_length=10_000, description='base poses "x y yaw"')
    robot: str = Field(DEFAULT_ROBOT, max_length=64)
    arm: str | None = Field(None, max_length=64)


class NavigateRequest(_Model):
    """``baseplace navigate`` across the scene's planar regions (seed 000 V)."""

    scene_id: str = Field(..., max_length=64)
    start: str = Field(..., max_length=100)
    goal: str = Field(..., max_length=100)
    robot: str = Field(DEFAULT_ROBOT, max_length=64)
    planner: Literal["rrt", "regions"] = "rrt"
    time_limit: float = Field(2.0, gt=0.0, le=20.0, description="planning time [s]")
    resolution: float | None = Field(None, ge=0.005, le=1.0)
    seed: int = SEED
    degrees: bool = DEGREES


class SurfaceMapRequest(_Model):
    """``baseplace surface-map``: where to stand to work on a whole surface (seed 002)."""

    polygon: str = Field(..., max_length=10_000, description='"x1,y1;x2,y2;..." [m]')
    height: float = Field(..., ge=-10.0, le=10.0, description="the surface's height [m]")
    robot: str = Field(DEFAULT_ROBOT, max_length=64)
    arms: str = Field("any", max_length=64)
    resolution: float = Field(0.05, ge=0.005, le=1.0)
    orientations: int = Field(16, ge=1, le=360)

    @model_validator(mode="after")
    def _cells(self) -> SurfaceMapRequest:
        try:  # the bounding box's cells; a polygon that does not parse is the job's to refuse
            xy = np.array([[float(v) for v in p.split(",")] for p in self.polygon.split(";") if p.strip()])
            extent = np.ptp(xy, axis=0) if xy.ndim == 2 and xy.shape[1] == 2 and len(xy) else None
        except ValueError:
            extent = None
        if extent is not None and np.isfinite(extent).all():
            cells = float(np.prod(np.floor(extent / self.resolution) + 1)) * self.orientations
            if cells > MAX_SURFACE_CELLS:
                raise ValueError(
                    f"the polygon's box at resolution {self.resolution:g} m x {self.orientations} orientations "
                    f"is {cells:.3g} cells, over the limit of {MAX_SURFACE_CELLS}: a coarser resolution"
                )
        return self


class SurfaceSamplesRequest(_Model):
    """``baseplace surface-sample`` from a surface map made by POST /surface-map."""

    surface_map_id: str = Field(..., max_length=64)
    n: int = Field(5, ge=1, le=1000)
    candidates: int = Field(40, ge=1, le=100_000)
    no_discount: bool = False
    seed: int = SEED
    scene_id: str | None = Field(
        None, max_length=64, description="a scene whose grid is the operational area"
    )


def create_app(settings: ServeSettings | None = None, state: ServiceState | None = None) -> FastAPI:
    """The service's ASGI app (robots warmed in its startup when ``settings.warm_up``)."""
    settings = settings or ServeSettings()
    st = state or ServiceState(settings)

    async def lifespan(app: FastAPI) -> Any:
        if settings.warm_up:
            await asyncio.get_running_loop().run_in_executor(st.executor, functools.partial(warm_up, st))
        yield
        st.close(wait_s=min(5.0, settings.timeout_s))  # the jobs were cancelled: they end at their next check

    app = FastAPI(title="baseplace", version=_version(),
                  description="Where should a mobile manipulator stand? The CLI's jobs over HTTP/JSON; "
                              "the answers are the CLI's --json output.",
                  lifespan=lifespan)  # fmt: skip
    app.state.service = st

    async def run(
        fn: Callable[..., Any], *args: Any, lookup: bool = False, lane: Any = None, heavy: bool = False
    ) -> Any:
        """Run a job on its thread within the time limit, stopped when it is up.

        Placements and scenes on the worker, a placement of more work than ``heavy_work``
        (``heavy``) on the heavy thread, a read-only lookup on the lookup threads, candidates,
        navigation and surface maps on the command thread (``lane``: the job whose thread
        ``fn`` runs on, if not ``fn`` itself). A lane holds at most ``max_queue`` jobs, waiting
        or running (503 past it), a client (the peer's address) at most ``max_client_queue`` of
        them, one in the heavy lane (429 past it), and serves its clients in turn. The job runs
        under a deadline of the request's time limit, counted from now: it stops at its next
        check once the request is answered 504, and a job that waited out its time in the queue
        does not start.
        """
        job = fn if lane is None else lane
        name = "lookups" if lookup else "commands" if job in COMMAND_LANE else "heavy" if heavy else "jobs"
        pool = {"lookups": st.lookups, "commands": st.commands, "heavy": st.heavy, "jobs": st.executor}[name]
        if st.closing:
            raise _Busy("shutdown", settings)
        if st.queued[name] >= settings.max_queue:
            raise _Busy(name, settings)
        client = CLIENT.get()
        key = (name, client)
        share = 1 if name == "heavy" else min(settings.max_client_queue, settings.max_queue)
        if st.client_queued.get(key, 0) >= share:
            raise _OverShare(name, client, share)
        deadline = Deadline.after(settings.timeout_s)

        def limited_job() -> Any:
            with limited(deadline):
                return fn(*args)

        future = asyncio.wrap_future(pool.submit_for(client, limited_job))  # counted once queued
        st.queued[name] += 1
        st.client_queued[key] = st.client_queued.get(key, 0) + 1
        st.deadlines.add(deadline)

        def ended(f: asyncio.Future[Any]) -> None:
            st.queued[name] -= 1
            left = st.client_queued.pop(key) - 1
            if left:
                st.client_queued[key] = left
            st.deadlines.discard(deadline)
            if not f.cancelled():
                f.exception()  # retrieved: a job stopped after its 504 is no error to log

        future.add_done_callback(ended)
        try:
            return await asyncio.wait_for(asyncio.shield(future), settings.timeout_s)
        except (asyncio.TimeoutError, DeadlineExceeded):
            deadline.cancel()
            if st.closing:
                raise _Busy("shutdown", settings) from None
            raise _Timeout(settings.timeout_s) from None

    async def answer(
        fn: Callable[..., dict[str, Any]], *args: Any, lookup: bool = False, heavy: bool = False, **add: Any
    ) -> Response:
        """A job's report (with the fields ``add``) as the response, encoded on the job's thread.

        The report is plain JSON data already: FastAPI's encoder, which walks it again on the
        event loop, is skipped.
        """

        def encoded() -> bytes:
            return json.dumps({**fn(*args), **add}, allow_nan=False, separators=(",", ":")).encode()

        body = await run(encoded, lookup=lookup, lane=fn, heavy=heavy)
        return Response(body, media_type="application/json")

    @app.exception_handler(BaseplaceError)
    async def _baseplace_error(request: Request, exc: BaseplaceError) -> JSONResponse:
        message = _line(
            str(exc).replace(str(st.folder) + "/", "")
        )  # the scene's files, not the server's paths
        if isinstance(exc, jobs.JobFailed) and exc.exit_code == 3:
            return JSONResponse({**exc.report, "error": _line(exc.report.get("error")), "found": False},
                                status_code=200)  # fmt: skip
        if isinstance(exc, jobs.JobFailed):
            return JSONResponse({**exc.report, "error": _line(exc.report.get("error"))}, status_code=400)
        status = 404 if isinstance(exc, UnknownSceneError) else 400
        return JSONResponse(_error_body(request, message), status_code=status)

    @app.exception_handler(_Timeout)
    async def _timeout(request: Request, exc: _Timeout) -> JSONResponse:
        return JSONResponse({"error": str(exc)}, status_code=504)

    @app.exception_handler(_Busy)
    async def _busy(request: Request, exc: _Busy) -> JSONResponse:
        retry = str(max(1, round(settings.timeout_s)))
        return JSONResponse({"error": str(exc)}, status_code=503, headers={"Retry-After": retry})

    @app.exception_handler(_OverShare)
    async def _over_share(request: Request, exc: _OverShare) -> JSONResponse:
        retry = str(max(1, round(settings.timeout_s))) if exc.lane == "heavy" else "1"
        return JSONResponse({"error": str(exc)}, status_code=429, headers={"Retry-After": retry})

    @app.exception_handler(HTTPException)
    async def _http_error(request: Request, exc: HTTPException) -> JSONResponse:
        detail = exc.detail if isinstance(exc.detail, str) else "invalid request"
        if exc.status_code == 400:  # FastAPI's: the body did not parse (too deep, not UTF-8)
            detail = "the request body is not valid JSON (not UTF-8, or nested too deeply)"
        return JSONResponse(_error_body(request, _line(detail)), status_code=exc.status_code,
                            headers=getattr(exc, "headers", None))  # fmt: skip

    @app.exception_handler(Exception)
    async def _internal(request: Request, exc: Exception) -> JSONResponse:
        # no traceback and no exception text: they may name the server's paths or echo the input
        return JSONResponse(
            {"error": f"internal error ({type(exc).__name__}); the service goes on answering"},
            status_code=500,
        )

    @app.exception_handler(RequestValidationError)
    async def _invalid(request: Request, exc: RequestValidationError) -> JSONResponse:
        first = exc.errors()[0] if exc.errors() else {}
        if first.get("type") == "json_invalid":  # loc is (body, character offset)
            at = [p for p in first.get("loc", ()) if p != "body"]
            where = f" at character {at[0]}" if at else ""
            message = f"the request body is not valid JSON{where} ({first.get('msg', 'decode error')})"
        elif first.get("type") == "finite_number":
            where = ".".join(str(p) for p in first.get("loc", ()) if p != "body")
            message = f"{where}: NaN and infinite numbers are not accepted (a finite number)"
        else:
            where = ".".join(str(p) for p in first.get("loc", ()) if p != "body")
            message = (
                f"{where}: {first.get('msg', 'invalid request')}"
                if where
                else str(first.get("msg", "invalid"))
            )
        return JSONResponse(_error_body(request, _line(message.replace("\n", " "))), status_code=422)

    @app.get("/health", summary="liveness; with the token also scenes held, resident memory")
    async def health(request: Request) -> dict[str, Any]:
        headers = {k.lower(): v for k, v in request.scope["headers"]}
        if not authorized(headers, settings.token):
            return {"status": "ok"}
        return {"status": "ok", "version": _version(), "uptime_s": round(time.time() - st.started, 1),
                "scenes": len(st.scene_ids()), "requests": st.requests, "rss_mb": round(_rss_mb(), 1),
                "robots_warm": sorted(st._robots)}  # fmt: skip

    @app.post(
        "/scenes",
        summary="upload a cloud or a ROS recording (body: the file) once; later requests name its scene_id",
        openapi_extra=_UPLOAD,
    )
    async def upload_scene(
        request: Request,
        format: Literal["ply", "pcd", "npy", "xyz", "mcap", "bag"] = Query(
            ..., description="cloud file format, or a recording: rosbag2 .mcap file, ROS 1 .bag"
        ),
        cloud_topic: Annotated[
            list[Annotated[str, StringConstraints(max_length=200)]] | None,
            Query(description="recordings: PointCloud2 topic(s)", max_length=16),
        ] = None,
        map_topic: str | None = Query(
            None, max_length=200, description="recordings: an OccupancyGrid topic, the scene's grid"
        ),
        world_frame: str = Query("map", max_length=200, description="recordings: the frame of the scene"),
        bag_clouds: Literal["last", "first", "all"] = Query(
            "last", description="recordings: which cloud messages"
        ),
        transform: str | None = Query(
            None,
            max_length=1000,
            description="cloud files: the CLI's --transform, the sensor-frame up vector "
            '"ux uy uz" or T_world_sensor as 16 numbers row by row (none: the cloud must be z up, checked)',
        ),
        floor: float | None = Query(
            None,
            ge=-1e3,
            le=1e3,
            allow_inf_nan=False,
            description="the CLI's --floor: a floor plane at this height [m] under and 2 m around the cloud",
        ),
        fuse: bool = Query(
            False,
            description="the CLI's --fuse: the clouds fused into a 25 mm OctoMap by ray "
            "casting from each sensor origin (a recording's: bag_clouds=all for all its messages)",
        ),
        fuse_miss: float = Query(
            0.35,
            gt=0.0,
            lt=0.5,
            allow_inf_nan=False,
            description="the CLI's --fuse-miss: occupancy probability of a ray passing a voxel",
        ),
        obstacle: Annotated[
            list[Obstacle] | None,
            Query(
                description='the CLI\'s --obstacle, part of the scene: "box X Y Z SX SY SZ [YAW]" or "cylinder X Y '
                'Z RADIUS HEIGHT" [m, rad], world frame; checked by every /place, /explain and /candidates on '
                "it, before a request's own obstacles (box#k counts through both)",
                max_length=16,
            ),
        ] = None,
    ) -> dict[str, Any]:
        data = await request.body()
        bag = {
            "cloud_topics": cloud_topic or [],
            "map_topic": map_topic,
            "world_frame": world_frame,
            "clouds": bag_clouds,
        }
        scene = await run(
            st.add_scene, data, format, bag, transform, floor, fuse_miss if fuse else None, obstacle
        )
        out = {
            "scene_id": scene.id,
            "points": scene.points,
            "grid": scene.grid_yaml is not None,
            "obstacles": list(scene.obstacles),
        }
        if (
            scene.segmentation_error is not None
        ):  # a recording's grid, and a cloud of no region: place on the grid
            return {**out, "regions": 0, "segmentation_error": _line(scene.segmentation_error)}
        summary = await run(jobs.segment, scene, None)
        return {**out, "regions": len(summary["regions"]), "timings_ms": summary["timings_ms"]}

    @app.get("/scenes", summary="ids of the scenes held")
    async def list_scenes() -> dict[str, Any]:
        return {"scenes": st.scene_ids()}

    @app.delete("/scenes/{scene_id}", summary="forget a scene")
    async def delete_scene(scene_id: str) -> dict[str, Any]:
        st.drop_scene(scene_id)
        return {"deleted": scene_id}

    @app.post(
        "/scenes/{scene_id}/grid",
        summary="attach an occupancy grid (body: PGM/PNG; map_server YAML fields)",
        openapi_extra=_UPLOAD,
    )
    async def upload_grid(
        scene_id: str,
        request: Request,
        resolution: float = Query(..., gt=0.0, le=10.0, allow_inf_nan=False),
        format: Literal["pgm", "png"] = "pgm",
        origin_x: float = Query(0.0, ge=-1e6, le=1e6, allow_inf_nan=False),
        origin_y: float = Query(0.0, ge=-1e6, le=1e6, allow_inf_nan=False),
        origin_yaw: float = Query(0.0, ge=-10.0, le=10.0, allow_inf_nan=False),
        negate: bool = False,
        occupied_thresh: float = Query(0.65, ge=0.0, le=1.0, allow_inf_nan=False),
        free_thresh: float = Query(0.196, ge=0.0, le=1.0, allow_inf_nan=False),
        mode: Literal["trinary", "scale", "raw"] = "trinary",
    ) -> dict[str, Any]:
        scene = st.scene(scene_id)
        data = await request.body()
        meta = {"resolution": resolution, "origin_x": origin_x, "origin_y": origin_y, "origin_yaw": origin_yaw,
                "negate": negate, "occupied_thresh": occupied_thresh, "free_thresh": free_thresh, "mode": mode}  # fmt: skip
        return await run(jobs.add_grid, scene, data, format, meta)

    @app.get("/scenes/{scene_id}/segmentation", summary="baseplace segment --json of the scene (cached)")
    async def segmentation(
        scene_id: str, resolution: float | None = Query(None, ge=0.005, le=1.0, allow_inf_nan=False)
    ) -> Response:
        return await answer(jobs.segment, st.scene(scene_id), resolution)

    @app.post("/place", summary="baseplace place --json on an uploaded scene")
    async def place(req: PlaceRequest) -> Response:
        scene = st.scene(req.scene_id)
        if req.work > settings.heavy_work:  # its own thread and robots: cheap placements never wait behind it
            return await answer(jobs.place, st, scene, req.model_dump(), "heavy", heavy=True)
        return await answer(jobs.place, st, scene, req.model_dump())

    @app.post(
        "/explain", summary="baseplace explain --json: map value, IK, collisions, motion at one base pose"
    )
    async def explain(req: ExplainRequest) -> Response:
        scene = None if req.scene_id is None else st.scene(req.scene_id)
        return await answer(jobs.explain, st, scene, req.model_dump())

    @app.post("/reach", summary="baseplace reach --json on the robot's default map")
    async def reach(req: ReachRequest) -> Response:
        return await answer(jobs.reach, st, req.model_dump(), lookup=st.is_warm(req.robot, req.arm))

    @app.post("/candidates", summary="baseplace candidates --json on an uploaded scene with a grid")
    async def candidates(req: CandidatesRequest) -> Response:
        scene = st.scene(req.scene_id)
        return await answer(jobs.candidates, st, scene, req.model_dump())

    @app.post(
        "/point", summary="baseplace point --json: the object pointed at in an RGB-D frame, where to stand"
    )
    async def point(req: PointRequest) -> Response:
        scene = None if req.scene_id is None else st.scene(req.scene_id)
        return await answer(jobs.point, st, scene, req.model_dump())

    @app.post("/navigate", summary="baseplace navigate --json across the scene's planar regions")
    async def navigate(req: NavigateRequest) -> Response:
        scene = st.scene(req.scene_id)
        return await answer(jobs.navigate, st, scene, req.model_dump())

    @app.post("/surface-map", summary="baseplace surface-map --json; later samples name its surface_map_id")
    async def surface_map(req: SurfaceMapRequest) -> Response:
        import uuid

        sid = uuid.uuid4().hex[:16]
        path = st.folder / "surface" / f"{sid}.smap"
        path.parent.mkdir(mode=0o700, exist_ok=True)
        return await answer(jobs.surface_map, st, req.model_dump(), str(path), surface_map_id=sid)

    @app.post("/surface-samples", summary="baseplace surface-sample --json from a surface map")
    async def surface_samples(req: SurfaceSamplesRequest) -> Response:
        if not req.surface_map_id.isalnum():
            raise UnknownSceneError(f"unknown surface map id {req.surface_map_id!r}")
        path = st.folder / "surface" / f"{req.surface_map_id}.smap"
        if not path.is_file():
            raise UnknownSceneError(
                f"unknown surface map id {req.surface_map_id!r}: make one with POST /surface-map"
            )
        scene = None if req.scene_id is None else st.scene(req.scene_id)
        return await answer(jobs.surface_samples, st, req.model_dump(), str(path), scene)

    app.add_middleware(Guard, settings=settings, state=st)  # outermost: before any body is read
    return app


COMMAND_LANE = (jobs.candidates, jobs.navigate, jobs.surface_map, jobs.surface_samples, jobs.point)
"""Jobs run on the command thread, on robots of their own, beside the placements."""

KINDS = {"/place": "place", "/candidates": "candidates", "/navigate": "navigate", "/reach": "reach",
         "/explain": "explain", "/surface-map": "surface_map", "/surface-samples": "surface_samples",
         "/point": "point"}  # fmt: skip
"""A job's endpoint -> the kind of its report."""


def _error_body(request: Request, message: str) -> dict[str, Any]:
    """The CLI's failure report of the endpoint's kind (exit 2), or ``{"error": ...}`` off the jobs."""
    path = request.url.path
    kind = KINDS.get(path) or ("segment" if path.endswith("/segmentation") else
                               "occupancy" if path.endswith("/grid") else None)  # fmt: skip
    if kind is None:
        return {"error": message}
    return jobs.failure_report(kind, message, 2)


class _Timeout(Exception):
    def __init__(self, limit: float) -> None:
        super().__init__(
            f"the request took longer than {limit:g} s (serve --timeout); its job was stopped, the scene's "
            "caches stay warm"
        )


class _Busy(Exception):
    def __init__(self, lane: str, settings: ServeSettings) -> None:
        super().__init__(
            "the service is shutting down"
            if lane == "shutdown"
            else f"the service has {settings.max_queue} {lane} waiting or running already "
            "(serve --max-queue); try again shortly"
        )


class _OverShare(Exception):
    def __init__(self, lane: str, client: str, share: int) -> None:
        self.lane = lane
        super().__init__(
            f"this client ({client}) has a heavy placement (work over serve --heavy-work) waiting or running "
            "already: one at a time per client; send the next when it is answered"
            if lane == "heavy"
            else f"this client ({client}) has {share} {lane} waiting or running already "
            "(serve --max-client-queue); send the next when one is answered"
        )


_UPLOAD: dict[str, Any] = {
    "requestBody": {
        "required": True,
        "content": {"application/octet-stream": {"schema": {"type": "string", "format": "binary"}}},
    }
}
"""The file body of an upload endpoint, in the OpenAPI document."""


def _line(message: Any, limit: int = 400) -> str:
    """An error line of at most ``limit`` characters: a long one (an echoed input) keeps its ends."""
    text = str(message)
    if len(text) <= limit:
        return text
    half = limit // 2
    return f"{text[:half]} ... ({len(text) - 2 * half} characters cut) ... {text[-half:]}"


def warm_up(state: ServiceState) -> None:
    """Make the first request as fast as the next: robots, maps, kernels and a first placement.

    The placement is the place job's, as a request runs it: a first request imports nothing more.
    """
    from baseplace.jobs.inputs import CloudInput
    from baseplace.jobs.place import PlaceJob, place_job
    from baseplace.placement.pipeline import PlaceSettings
    from baseplace.placement.scene_cache import SceneCache

    floor = np.mgrid[-2.0:2.0:0.02, -2.0:2.0:0.02].reshape(2, -1).T
    points = np.c_[floor, np.zeros(len(floor))]
    cache = SceneCache(points)
    for name in state.settings.robots:
        state.robot(name, lane="heavy")  # built here, used by the heavy thread alone from now on
        robot = state.robot(name)
        job = PlaceJob(["0.6 0 0.8 0 1.5708 0"], robot, cloud=CloudInput(points=points),
                       map=state.reach_map(robot, None), settings=PlaceSettings(tries=5), cache=cache)  # fmt: skip
        try:
            place_job(job)
        except BaseplaceError:
            pass  # the kernels are loaded all the same


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("baseplace")
    except PackageNotFoundError:
        return "unknown"


def _rss_mb() -> float:
    """Resident memory of this process [MiB] (Linux /proc; 0 elsewhere)."""
    try:
        with open("/proc/self/statm") as f:
            pages = int(f.read().split()[1])
    except (OSError, ValueError, IndexError):
        return 0.0
    import os

    return pages * os.sysconf("SC_PAGE_SIZE") / 2**20
