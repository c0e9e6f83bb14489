"""Seed 002's "inspect every object on a table" task (section IV-B, Tables I and II) with a PDDL planner.

The robot starts away from a table it knows only as a surface map. It must drive to the table,
inspect the surface (which reveals the objects on it), and then pick up every object, hold it to
the camera and put it back. Two ways to give the planner robot poses are compared, as in seed 002:

* ``predefined``: a fixed set of 1-4 poses, "recorded manually" (here: facing the middle of each
  side of the table, long sides first, the footprint 5 cm from its edge);
* ``sampled``: poses from the grounding attachment
  (:func:`~baseplace.planning.attachments.grounding`), added *while planning*: whenever the planner
  proves the task unsolvable with the poses it has, the generator adds one more spread-out pose
  and the planner runs again, up to ``max_poses``.

The domain is written with unified-planning and solved by Fast Downward (``fast-downward-opt``,
minimizing action costs, a move costing its travel time). The attachments ground the geometric
predicates: ``can_see(p)`` is the condition attachment, R_S(p) > 0 (a surface-map lookup);
``can_reach(p, o)`` holds when the shared verification (IK for a top-down grasp with either arm,
the whole robot clear of the furniture) passes from pose p, after a reachability-map lookup has
ruled out the hopeless pairs. Execution is simulated: actions succeed, and their durations model
the seed's "total execution time".

Needs the optional ``planning`` extra: ``pip install baseplace[planning]``.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.geometry.poses import BasePose, FloatArray
from baseplace.placement.irm_candidates import grasp_poses
from baseplace.placement.surface_map import SurfaceMap
from baseplace.placement.surface_sampling import furniture_voxels
from baseplace.placement.verify import Candidate, Placement, Verifier
from baseplace.planning.attachments import grounding, reachability
from baseplace.reachability.rmap import ReachabilityMap
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace.terrain.polygons import footprint_outline
from baseplace.world.environment import Environment

MODES = ("predefined", "sampled")
INSPECT_TABLE = ("0,0;1.4,0;1.4,0.65;0,0.65", 0.74)
"""Seed 002's table: polygon [m] and height [m]."""
PAPER_TABLE1 = {  # seed 002 Table I: total execution time [min] on a PR2 per number of objects; None: unsolved
    "1 pose": [7.9, None, None, None], "2 poses": [8.6, 19.5, None, None],
    "3 poses": [10.7, 31.4, 43.0, None], "4 poses": [8.6, 16.9, 34.5, 87.9],
    "sampling": [15.3, 36.4, 37.0, 64.1],
}  # fmt: skip
PAPER_TABLE2 = {  # seed 002 Table II: averages over 7 runs inspecting 3 objects (T and t_p in minutes)
    "predefined": {"T_min": 38.0, "t_p_min": 7.0, "replans": 7.3, "moves": 3.9, "other_actions": 28.3},
    "sampled": {"T_min": 32.0, "t_p_min": 7.42, "replans": 9.3, "moves": 2.1, "other_actions": 28.6},
}


@dataclass(frozen=True)
class TaskSettings:
    """Durations, speeds and limits of the simulated inspect task.

    Attributes:
        speed: base speed [m/s] on a straight line between poses.
        turn_speed: base turning speed [rad/s].
        inspect_surface_s: looking at the table and recognizing the objects [s].
        pickup_s: grasping an object [s].
        inspect_object_s: holding an object to the camera [s].
        putdown_s: putting an object back [s].
        max_poses: poses the generator may add in one run (sampled mode).
        object_height: height of the objects [m]; the grasp point is 2 cm below their top.
        grasp_directions: top-down grasps per object (rotations about the vertical).
        edge_margin: objects stand at least this far inside the table's outline [m].
        object_spacing: objects stand at least this far apart [m].
        predefined_gap: the predefined poses stand with their footprint's front this far from the table [m].
    """

    speed: float = 0.3
    turn_speed: float = 0.5
    inspect_surface_s: float = 15.0
    pickup_s: float = 30.0
    inspect_object_s: float = 10.0
    putdown_s: float = 25.0
    max_poses: int = 12
    object_height: float = 0.10
    grasp_directions: int = 8
    edge_margin: float = 0.05
    object_spacing: float = 0.10
    predefined_gap: float = 0.05

    def travel_s(self, a: BasePose, b: BasePose) -> float:
        """Time [s] to drive from ``a`` to ``b``: the straight distance plus the heading change."""
        turn = abs(math.remainder(b.yaw - a.yaw, 2 * math.pi))
        return math.dist((a.x, a.y), (b.x, b.y)) / self.speed + turn / self.turn_speed


@dataclass
class RunResult:
    """One run of the task.

    Attributes:
        solved: every object was inspected.
        exec_s: modelled execution time [s] (moves and actions).
        plan_s: time spent in the planner [s] (all calls).
        grounding_s: time spent grounding ``can_see`` / ``can_reach`` and drawing poses [s].
        replans: planner calls after the first.
        moves: move actions executed.
        other_actions: non-move actions executed.
        poses: robot poses the planner had at the end (without the start).
        unreachable: objects no pose could reach.
        actions: the executed actions, as text.
    """

    solved: bool = False
    exec_s: float = 0.0
    plan_s: float = 0.0
    grounding_s: float = 0.0
    replans: int = 0
    moves: int = 0
    other_actions: int = 0
    poses: int = 0
    unreachable: int = 0
    actions: list[str] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return {k: (round(v, 3) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


def _require_planner() -> Any:
    try:
        import unified_planning.shortcuts as ups
    except ImportError as e:  # pragma: no cover - the dev extra installs it
        raise InputError(
            "the inspect task needs unified-planning and Fast Downward: pip install 'baseplace[planning]'"
        ) from e
    ups.get_environment().credits_stream = None
    return ups


def predefined_poses(robot: Robot, smap: SurfaceMap, gap: float = 0.05) -> list[BasePose]:
    """Facing the middle of each side of the surface polygon, the footprint's front ``gap`` [m] from it.

    Longest sides first. The front is the footprint's largest extent along the base x axis.
    """
    poly = np.asarray(smap.polygon, dtype=float)
    centre = poly.mean(axis=0)
    r = float(footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)[:, 0].max())
    poses: list[tuple[float, BasePose]] = []
    for a, b in zip(poly, np.roll(poly, -1, axis=0), strict=True):
        mid = 0.5 * (a + b)
        edge = b - a
        normal = np.array([edge[1], -edge[0]]) / np.linalg.norm(edge)
        if normal @ (mid - centre) < 0:
            normal = -normal
        p = mid + (r + gap) * normal
        poses.append(
            (
                float(np.linalg.norm(edge)),
                BasePose(float(p[0]), float(p[1]), math.atan2(-normal[1], -normal[0])),
            )
        )
    return [pose for _, pose in sorted(poses, key=lambda e: -e[0])]


def place_objects(smap: SurfaceMap, n: int, rng: np.random.Generator, settings: TaskSettings) -> FloatArray:
    """(n, 3) object centres on the surface, ``edge_margin`` inside it and ``object_spacing`` apart."""
    import shapely

    inner = shapely.Polygon(smap.polygon).buffer(-settings.edge_margin)
    x0, y0, x1, y1 = inner.bounds
    z = smap.height + 0.5 * settings.object_height
    out: list[FloatArray] = []
    for _ in range(10_000):
        if len(out) == n:
            break
        p = np.array([rng.uniform(x0, x1), rng.uniform(y0, y1), z])
        if inner.contains(shapely.Point(p[:2])) and all(
            math.dist(p[:2], q[:2]) >= settings.object_spacing for q in out
        ):
            out.append(p)
    if len(out) < n:
        raise InputError(f"cannot place {n} objects {settings.object_spacing} m apart on the surface")
    return np.array(out).reshape(-1, 3)


class ReachCheck:
    """``can_reach(pose, object)``: the shared verification of a top-down grasp with either arm.

    A reachability-map lookup first drops the grasps the map says no arm reaches from the pose;
    the rest go through :class:`~baseplace.placement.verify.Verifier` (IK, then the whole robot
    against the surface's furniture and itself).
    """

    def __init__(self, robot: Robot, rmaps: dict[str, ReachabilityMap], smap: SurfaceMap,
                 settings: TaskSettings) -> None:  # fmt: skip
        self.robot = robot
        self.rmaps = rmaps
        self.settings = settings
        env = Environment(robot, furniture_voxels(smap))
        outline = footprint_outline(robot.spec.footprint_radius, robot.spec.footprint_polygon)
        self.verifiers = {}
        for name in rmaps:
            arm = robot.arm(name)
            self.verifiers[name] = Verifier(arm, DampedLeastSquaresIK(arm, restarts=20), env, np.zeros((0, 4, 4)),
                                            {}, outline)  # fmt: skip

    def grasps(self, p_o: ArrayLike) -> FloatArray:
        """Top-down grasps of the object at ``p_o``, 2 cm below its top."""
        n = self.settings.grasp_directions
        return grasp_poses(p_o, n, top_down=True, top_offset=0.5 * self.settings.object_height - 0.02)[n:]

    def __call__(self, pose: BasePose, p_o: ArrayLike, rng: np.random.Generator) -> Placement | None:
        """A verified grasp of the object at ``p_o`` from ``pose`` by some arm (its joints), or None."""
        T = pose.matrix()
        G = self.grasps(p_o)
        for name, rmap in self.rmaps.items():
            values = np.array([rmap.inverse(g, T[None])[0] for g in G])
            verifier = self.verifiers[name]
            for k in np.argsort(-values, kind="stable"):
                if values[k] <= 0:
                    break
                verifier.targets = G[k][None]
                placement = verifier.check(Candidate(T, -1, float(values[k])), rng)
                if placement is not None:
                    return placement
        return None


def _problem(ups: Any, poses: dict[str, BasePose], at: str, can_see: set[str], objects: list[str],
             can_reach: set[tuple[str, str]], inspected_surface: bool, done: set[str],
             settings: TaskSettings) -> Any:  # fmt: skip
    """The PDDL problem of the current state (objects are known once the surface is inspected)."""
    Pose, Obj = ups.UserType("Pose"), ups.UserType("Obj")
    B, Int = ups.BoolType(), ups.IntType()
    robot_at = ups.Fluent("robot_at", B, p=Pose)
    see = ups.Fluent("can_see", B, p=Pose)
    reach = ups.Fluent("can_reach", B, p=Pose, o=Obj)
    surface_done = ups.Fluent("surface_inspected", B)
    on_table = ups.Fluent("on_table", B, o=Obj)
    holding = ups.Fluent("holding", B, o=Obj)
    hand_free = ups.Fluent("hand_free", B)
    inspected = ups.Fluent("inspected", B, o=Obj)
    travel = ups.Fluent("travel", Int, a=Pose, b=Pose)

    move = ups.InstantaneousAction("move", a=Pose, b=Pose)
    a, b = move.parameters
    move.add_precondition(robot_at(a))
    move.add_effect(robot_at(a), False)
    move.add_effect(robot_at(b), True)
    look = ups.InstantaneousAction("inspect_surface", p=Pose)
    look.add_precondition(robot_at(look.parameter("p")))
    look.add_precondition(see(look.parameter("p")))
    look.add_effect(surface_done, True)
    pick = ups.InstantaneousAction("pickup", o=Obj, p=Pose)
    o, p = pick.parameters
    for c in (robot_at(p), reach(p, o), on_table(o), hand_free, surface_done):
        pick.add_precondition(c)
    pick.add_effect(on_table(o), False)
    pick.add_effect(hand_free, False)
    pick.add_effect(holding(o), True)
    show = ups.InstantaneousAction("inspect_object", o=Obj)
    show.add_precondition(holding(show.parameter("o")))
    show.add_effect(inspected(show.parameter("o")), True)
    put = ups.InstantaneousAction("putdown", o=Obj, p=Pose)
    o2, p2 = put.parameters
    for c in (robot_at(p2), reach(p2, o2), holding(o2)):
        put.add_precondition(c)
    put.add_effect(holding(o2), False)
    put.add_effect(on_table(o2), True)
    put.add_effect(hand_free, True)

    prob = ups.Problem("inspect_objects")
    for f in (robot_at, see, reach, surface_done, on_table, holding, inspected):
        prob.add_fluent(f, default_initial_value=False)
    prob.add_fluent(hand_free, default_initial_value=True)
    prob.add_fluent(travel, default_initial_value=0)
    for act in (move, look, pick, show, put):
        prob.add_action(act)
    P = {name: ups.Object(name, Pose) for name in poses}
    objs = {name: ups.Object(name, Obj) for name in objects}
    prob.add_objects(list(P.values()) + list(objs.values()))
    prob.set_initial_value(robot_at(P[at]), True)
    prob.set_initial_value(surface_done, inspected_surface)
    for name in can_see:
        prob.set_initial_value(see(P[name]), True)
    for pn, on in can_reach:
        prob.set_initial_value(reach(P[pn], objs[on]), True)
    for name in objects:
        prob.set_initial_value(on_table(objs[name]), True)
        prob.set_initial_value(inspected(objs[name]), name in done)
    for na, pa in poses.items():
        for nb, pb in poses.items():
            if na != nb:
                prob.set_initial_value(travel(P[na], P[nb]), max(1, round(settings.travel_s(pa, pb))))
    costs = {
        move: travel(a, b),
        look: ups.Int(round(settings.inspect_surface_s)),
        pick: ups.Int(round(settings.pickup_s)),
        show: ups.Int(round(settings.inspect_object_s)),
        put: ups.Int(round(settings.putdown_s)),
    }
    prob.add_quality_metric(ups.MinimizeActionCosts(costs))
    prob.add_goal(surface_done)
    prob.add_goal(hand_free)
    for name in objects:
        prob.add_goal(inspected(objs[name]))
    return prob


def run_inspect_task(
    robot: Robot,
    rmaps: dict[str, ReachabilityMap],
    smap: SurfaceMap,
    objects: FloatArray,
    start: BasePose,
    mode: str,
    rng: np.random.Generator,
    settings: TaskSettings | None = None,
    n_predefined: int = 4,
) -> RunResult:
    """One run: plan, execute (simulated), replan when the objects appear or when no plan exists.

    Args:
        robot: the robot (seed 002: PR2).
        rmaps: reachability map per arm, for the ``can_reach`` pre-filter.
        smap: the table's surface map (condition and grounding attachments).
        objects: (n, 3) object centres on the table, unknown to the robot until it inspects it.
        start: the robot's start pose, away from the table.
        mode: "predefined" or "sampled".
        rng: randomness (pose sampling, IK).
        settings: durations and limits.
        n_predefined: how many of :func:`predefined_poses` the predefined mode gets.
    """
    if mode not in MODES:
        raise InputError(f"unknown pose mode {mode!r}; choose one of {', '.join(MODES)}")
    ups = _require_planner()
    from unified_planning.engines import PlanGenerationResultStatus as Status

    s = settings or TaskSettings()
    result = RunResult()
    reach = ReachCheck(robot, rmaps, smap, s)
    poses: dict[str, BasePose] = {"start": start}
    can_see: set[str] = set()
    can_reach: set[tuple[str, str]] = set()
    known: list[str] = []
    generator: Iterator[Any] | None = None

    def ground_reach(name: str, pose: BasePose) -> None:
        """``can_reach(name, o)`` for every known object o (the reach attachment)."""
        for k in known:
            if reach(pose, objects[int(k[1:])], rng) is not None:
                can_reach.add((name, k))

    def add_pose(pose: BasePose) -> None:
        t0 = time.perf_counter()
        name = f"p{len(poses)}"
        poses[name] = pose
        if reachability(smap, (pose.x, pose.y, pose.yaw)) > 0:
            can_see.add(name)
        ground_reach(name, pose)
        result.grounding_s += time.perf_counter() - t0

    if mode == "predefined":
        for pose in predefined_poses(robot, smap, s.predefined_gap)[:n_predefined]:
            add_pose(pose)
    else:
        generator = grounding(smap, rng, robot=robot)
    at, surface_done, done = "start", False, set[str]()
    calls = 0
    while True:
        problem = _problem(ups, poses, at, can_see, known, can_reach, surface_done, done, s)
        t0 = time.perf_counter()
        with ups.OneshotPlanner(name="fast-downward-opt", problem_kind=problem.kind) as planner:
            answer = planner.solve(problem)
        result.plan_s += time.perf_counter() - t0
        calls += 1
        if answer.status not in (Status.SOLVED_SATISFICING, Status.SOLVED_OPTIMALLY):
            if generator is None or len(poses) - 1 >= s.max_poses:
                break  # unsolved: no pose set can be extended
            t0 = time.perf_counter()
            sampled = next(generator)
            result.grounding_s += time.perf_counter() - t0
            add_pose(sampled.pose)
            continue
        replan = False
        for step in answer.plan.actions:
            name = step.action.name
            args = [str(x) for x in step.actual_parameters]
            result.actions.append(f"{name}({', '.join(args)})")
            if name == "move":
                result.exec_s += s.travel_s(poses[args[0]], poses[args[1]])
                result.moves += 1
                at = args[1]
                continue
            result.other_actions += 1
            result.exec_s += {"inspect_surface": s.inspect_surface_s, "pickup": s.pickup_s,
                              "inspect_object": s.inspect_object_s, "putdown": s.putdown_s}[name]  # fmt: skip
            if name == "inspect_object":
                done.add(args[0])
            if name == "inspect_surface" and not surface_done:
                surface_done = True  # the objects appear: ground can_reach for them, replan
                t0 = time.perf_counter()
                known = [f"o{i}" for i in range(len(objects))]
                for pn, pose in poses.items():
                    if pn != "start":
                        ground_reach(pn, pose)
                result.grounding_s += time.perf_counter() - t0
                replan = bool(known)
                break
        if not replan:
            result.solved = surface_done and len(done) == len(objects)
            break
    result.replans = calls - 1
    result.poses = len(poses) - 1
    reached = {k for _, k in can_reach}
    result.unreachable = (
        sum(f"o{i}" not in reached for i in range(len(objects))) if surface_done else len(objects)
    )
    return result


def run_inspect_experiment(
    robot: Robot,
    rmaps: dict[str, ReachabilityMap],
    smap: SurfaceMap,
    counts: tuple[int, ...] = (1, 2, 3, 4),
    runs: int = 7,
    seed: int = 0,
    settings: TaskSettings | None = None,
    start: BasePose | None = None,
    progress: Callable[[int], None] | None = None,
) -> dict[str, Any]:
    """Seed 002 Tables I and II: 1-4 predefined poses and sampled poses on the same layouts.

    For each object count, ``runs`` random layouts; each layout is solved with the first 1, 2, 3
    and 4 predefined poses and with sampled poses.

    Args:
        robot: the robot.
        rmaps: reachability map per arm.
        smap: the table's surface map.
        counts: object counts (seed 002: 1-4).
        runs: random layouts per count.
        seed: random seed.
        settings: durations and limits.
        start: the robot's start pose (default: 1.5 m out from the table's lower-left corner in x and y).
        progress: called with 1 after each run.

    Returns:
        A JSON-ready dict: every run, per (count, configuration) the number unsolved and the means
        over the solved runs, and the settings.
    """
    s = settings or TaskSettings()
    if runs < 1 or not counts or min(counts) < 1:
        raise InputError(f"need runs >= 1 and object counts >= 1, got runs={runs}, counts={counts}")
    if start is None:  # 2 m out from the table's first corner, facing it
        corner = np.asarray(smap.polygon, dtype=float).min(axis=0)
        start = BasePose(float(corner[0]) - 1.5, float(corner[1]) - 1.5, math.pi / 4)
    configs = [("predefined", k) for k in range(1, len(smap.polygon) + 1)] + [("sampled", 0)]
    rows = []
    for n in counts:
        for r in range(runs):
            layout = place_objects(smap, n, np.random.default_rng([seed, n, r]), s)
            for mode, k in configs:
                res = run_inspect_task(robot, rmaps, smap, layout, start, mode,
                                       np.random.default_rng([seed, n, r, 1]), s, k)  # fmt: skip
                rows.append({"objects": n, "run": r, "mode": mode, "predefined": k,
                             "layout": np.round(layout, 4).tolist(), **res.to_json()})  # fmt: skip
                if progress is not None:
                    progress(1)
    summary = []
    for n in counts:
        for mode, k in configs:
            rs = [
                row for row in rows if row["objects"] == n and row["mode"] == mode and row["predefined"] == k
            ]
            ok = [row for row in rs if row["solved"]]

            def mean(key: str, sel: list[dict[str, Any]]) -> float | None:
                return round(float(np.mean([row[key] for row in sel])), 2) if sel else None

            summary.append({"objects": n, "config": f"{k} pose{'s' * (k > 1)}" if mode == "predefined" else "sampling",
                            "runs": len(rs), "unsolved": len(rs) - len(ok),
                            "exec_min": None if not ok else round(float(np.mean([row["exec_s"] for row in ok])) / 60, 2),
                            "plan_s": mean("plan_s", rs), "grounding_s": mean("grounding_s", rs),
                            "replans": mean("replans", ok), "moves": mean("moves", ok),
                            "other_actions": mean("other_actions", ok), "poses": mean("poses", rs)})  # fmt: skip
    return {
        "robot": robot.name,
        "arms": list(rmaps),
        "surface": {"polygon": np.asarray(smap.polygon).tolist(), "height": smap.height},
        "start": [start.x, start.y, start.yaw],
        "summary": summary,
        "paper": {"table1": PAPER_TABLE1, "table2": PAPER_TABLE2},
        "runs": rows,
        "settings": dict(s.__dict__),
        "seed": seed,
    }
