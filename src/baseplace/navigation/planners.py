"""Base path planners over the obstacle space of seed 000 V.

* ``rrt``: OMPL's RRTConnect (the bidirectional RRT of seed 000 Fig. 4) in SE(2), with the
  navigation map as its state validity checker; motions are checked every quarter footprint
  radius, finer than the band of invalid states around any obstacle cell (a ledge line included).
* ``regions``: the hierarchical planner seed 000 names as the more principled approach. The
  region graph's traversable edges are portals between regions; the shortest region sequence by
  portal-to-portal distance is searched first (networkx), then a grid path (Dijkstra with
  geometric costs, scikit-image's MCP) is found inside those regions and the cells along their
  borders. If the footprint does not fit through a portal, the next region sequence is tried.

Both return the same :class:`Path`; neither ever crosses a non-traversable edge (it is an
obstacle in the map).
"""

from __future__ import annotations

import dataclasses
import gc
import itertools
import time

import networkx as nx
import numpy as np
from numpy.typing import NDArray
from scipy import ndimage

from baseplace.errors import NothingFoundError, unknown
from baseplace.geometry.poses import FloatArray, wrap_angle
from baseplace.navigation.navmap import NavigationMap
from baseplace.navigation.path import Path

PLANNERS = ("rrt", "regions")


def plan_path(
    navmap: NavigationMap,
    start: FloatArray,
    goal: FloatArray,
    planner: str = "rrt",
    time_limit: float = 2.0,
    seed: int = 0,
) -> Path:
    """A collision-free base path from ``start`` to ``goal`` (x, y, yaw).

    Raises:
        InputError: an unknown planner, or a start or goal outside the scan, off every surface
            or in collision.
        NothingFoundError: no path within the time limit (rrt) or none exists (regions).
    """
    if planner not in PLANNERS:
        raise unknown("planner", planner, PLANNERS)
    start, goal = np.array(start, dtype=float), np.array(goal, dtype=float)
    start[2], goal[2] = wrap_angle(start[2]), wrap_angle(goal[2])
    navmap.check_pose("start", start[:2])
    navmap.check_pose("goal", goal[:2])
    t0 = time.perf_counter()
    poses = _rrt(navmap, start, goal, time_limit, seed) if planner == "rrt" else _regions(navmap, start, goal)
    ms = (time.perf_counter() - t0) * 1e3
    if poses is None:
        raise NothingFoundError(f"no path from start to goal ({planner} planner, {ms:.0f} ms)")
    path = Path(poses, planner, ms, ())
    ids = navmap.seg.region_at(path.dense(navmap.seg.hmap.resolution / 2))
    passed = tuple(int(k) for k, _ in itertools.groupby(ids[ids >= 0]))
    return dataclasses.replace(path, regions=passed)


def _rrt(
    navmap: NavigationMap, start: FloatArray, goal: FloatArray, time_limit: float, seed: int
) -> FloatArray | None:
    from ompl import base as ob
    from ompl import geometric as og
    from ompl import util as ou

    ou.setLogLevel(ou.LOG_NONE)
    ou.RNG.setSeed(seed + 1)  # OMPL takes seeds > 0
    try:
        space = ob.SE2StateSpace()
        x0, y0, x1, y1 = navmap.bounds
        bounds = ob.RealVectorBounds(2)
        bounds.setLow(0, x0)
        bounds.setLow(1, y0)
        bounds.setHigh(0, x1)
        bounds.setHigh(1, y1)
        space.setBounds(bounds)
        setup = og.SimpleSetup(space)
        setup.setStateValidityChecker(lambda s: bool(navmap.free(np.array([s.getX(), s.getY()]))[0]))
        info = setup.getSpaceInformation()
        extent = space.getMaximumExtent()
        # Every obstacle cell is surrounded by a 2-radius band of invalid states, so checks a quarter
        # radius apart cannot step across one (a ledge line included).
        info.setStateValidityCheckingResolution(navmap.radius / 4 / extent)
        a, b = space.allocState(), space.allocState()
        for state, (x, y, yaw) in ((a, start), (b, goal)):
            state.setX(float(x))
            state.setY(float(y))
            state.setYaw(float(yaw))
            space.enforceBounds(state)  # OMPL's SO(2) holds [-pi, pi): a heading of pi becomes -pi
        setup.setStartAndGoalStates(a, b, 1e-6)
        setup.setPlanner(og.RRTConnect(info))
        solved = setup.solve(time_limit)
        if not solved or not setup.haveExactSolutionPath():
            return None
        setup.simplifySolution()
        path = setup.getSolutionPath()
        poses = np.array([[s.getX(), s.getY(), s.getYaw()] for s in path.getStates()])
        poses[:, 2] = wrap_angle(poses[:, 2])  # back to (-pi, pi], the range headings have here
        return poses
    finally:
        gc.collect()  # the validity callback forms a cycle with the setup; free it before exit


def _regions(
    navmap: NavigationMap, start: FloatArray, goal: FloatArray, max_sequences: int = 8
) -> FloatArray | None:
    from skimage.graph import MCP_Geometric

    seg = navmap.seg
    r_start, r_goal = (int(v) for v in seg.region_at(np.stack([start[:2], goal[:2]])))
    portals = nx.Graph()
    portals.add_nodes_from(navmap.graph.nodes)
    for a, b, data in navmap.graph.edges(data=True):
        if not data["traversable"]:
            continue
        mid = (np.asarray(data["p_s"]) + np.asarray(data["p_e"])) / 2
        if not portals.has_edge(a, b) or "mid" not in portals.edges[a, b]:
            portals.add_edge(a, b, mid=mid)
    if r_start == r_goal:
        sequences: list[list[int]] = [[r_start]]
    else:
        for a, b in portals.edges:  # weight: between the two regions' centroids through the portal
            ca, cb = (np.asarray(navmap.graph.nodes[k]["polygon"].centroid.coords[0]) for k in (a, b))
            m = portals.edges[a, b]["mid"]
            portals.edges[a, b]["weight"] = float(np.linalg.norm(ca - m) + np.linalg.norm(m - cb))
        try:
            sequences = list(
                itertools.islice(nx.shortest_simple_paths(portals, r_start, r_goal, "weight"), max_sequences)
            )
        except nx.NetworkXNoPath:
            return None
    free = navmap.clearance > navmap.radius
    res = seg.hmap.resolution
    (sr,), (sc,), _ = seg.hmap.cell_of(start[:2])
    (gr,), (gc_,), _ = seg.hmap.cell_of(goal[:2])
    for sequence in sequences:
        inside = np.isin(seg.labels, sequence)
        allowed = free & ndimage.binary_dilation(inside, iterations=2)  # the unlabelled seams between regions
        costs = np.where(allowed, 1.0, np.inf)
        mcp = MCP_Geometric(costs, fully_connected=True)
        cum, _ = mcp.find_costs([(sr, sc)], [(gr, gc_)])
        if not np.isfinite(cum[gr, gc_]):
            continue
        cells = np.array(mcp.traceback((gr, gc_)))
        xy = seg.hmap.origin + (cells[:, ::-1] + 0.5) * res
        xy[0], xy[-1] = start[:2], goal[:2]
        heading = np.arctan2(np.diff(xy[:, 1]), np.diff(xy[:, 0]))
        yaw = (
            np.r_[start[2], heading[:-1], goal[2]]
            if len(xy) > 2
            else np.array([start[2], goal[2]])[: len(xy)]
        )
        return _thin(np.c_[xy, yaw])
    return None


def _thin(poses: FloatArray) -> FloatArray:
    """Drop grid-path points that lie on a straight run, keeping the corners."""
    if len(poses) <= 2:
        return poses
    d = np.diff(poses[:, :2], axis=0)
    turn = np.any(np.abs(np.diff(d, axis=0)) > 1e-9, axis=1)
    keep: NDArray[np.bool_] = np.r_[True, turn, True]
    return poses[keep]
