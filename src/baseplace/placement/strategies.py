"""Candidate generators: seed 000's TO, MR, MRTO (section III-B) and three baselines.

Every strategy yields :class:`~baseplace.placement.verify.Candidate` poses; none verifies them
(``verify.py`` does). The base's forward axis is x (ROS REP 103; seed 000's ARMAR-6 faces its y
axis): gamma_max bounds the angle between it and the direction to the targets' centroid, projected
on the support plane. Thresholds are relative to the largest OSRM value.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from baseplace.errors import unknown
from baseplace.geometry.poses import wrap_angle
from baseplace.geometry.surface_poses import plane_base_poses
from baseplace.placement.osrm import OSRM
from baseplace.placement.verify import Candidate
from baseplace.reachability.rmap import ReachabilityQuery, inverse_reachability

STRATEGIES = ("MR", "TO", "MRTO", "orm", "grid", "random")


class Strategy(Protocol):
    """Proposes base poses for the targets, best guesses first where it has a notion of best."""

    @property
    def name(self) -> str:
        """The strategy's name as the CLI spells it."""
        ...

    def candidates(
        self, osrm: OSRM, query: ReachabilityQuery, rng: np.random.Generator
    ) -> Iterator[Candidate]:
        """Candidate poses, until the strategy has nothing left to propose."""
        ...


def _box(osrm: OSRM) -> tuple[int, int, np.ndarray]:
    """The OSRM's values inside the bounding box of the cells within reach (the only ones not 0).

    Returns (first row, first column, (h, w, l) view); a 10 m scene's OSRM is mostly zeros, and
    scanning the box only keeps a query's cost independent of the scene's size.
    """
    rows, cols = np.nonzero(osrm.near)
    if len(rows) == 0:
        return 0, 0, osrm.values[:0, :0]
    r0, c0 = int(rows.min()), int(cols.min())
    return r0, c0, osrm.values[r0 : int(rows.max()) + 1, c0 : int(cols.max()) + 1]


def _deviation(osrm: OSRM, box: tuple[int, int, np.ndarray] | None = None) -> np.ndarray:
    """|gamma - gamma_to_target| for every OSRM entry: (H, W, l), or the box's (h, w, l) if given."""
    r0, c0, values = box if box is not None else (0, 0, osrm.values)
    rows, cols = np.nonzero(values.max(axis=2) > 0) if values.size else (np.zeros(0, int), np.zeros(0, int))
    dev = np.full(values.shape, np.inf)
    if len(rows):
        g_to = osrm.gamma_to_target(rows + r0, cols + c0)
        dev[rows, cols] = np.abs(wrap_angle(osrm.gammas[None, :] - g_to[:, None]))
    return dev


def _candidate(osrm: OSRM, row: int, col: int, gamma: float, value: float) -> Candidate:
    T = osrm.poses(np.array([row]), np.array([col]), np.array([gamma]))[0]
    return Candidate(T, int(osrm.seg.labels[row, col]), float(value))


@dataclass(frozen=True)
class MaximumReachability:
    """MR: a random OSRM entry whose reachability exceeds the threshold (within gamma_max)."""

    threshold: float = 0.2
    gamma_max: float = math.pi / 4
    name: str = "MR"

    def candidates(
        self, osrm: OSRM, query: ReachabilityQuery, rng: np.random.Generator
    ) -> Iterator[Candidate]:
        """Entries above the threshold in random order, each once."""
        box = _box(osrm)  # the same entries, in the same order, as over the whole OSRM
        r0, c0, v = box
        if v.size == 0:
            return
        top = float(v.max())
        ok = (v > self.threshold * top) & (_deviation(osrm, box) <= self.gamma_max) & (v > 0)
        rows, cols, ls = np.nonzero(ok)
        rows, cols = rows + r0, cols + c0
        for k in rng.permutation(len(rows)):
            yield _candidate(osrm, rows[k], cols[k], osrm.gammas[ls[k]], osrm.values[rows[k], cols[k], ls[k]])


@dataclass(frozen=True)
class ToObject:
    """TO: a random cell whose summed reachability exceeds the threshold, facing the targets."""

    threshold: float = 0.2
    gamma_max: float = math.pi / 4
    name: str = "TO"

    def _cells(self, osrm: OSRM) -> tuple[np.ndarray, np.ndarray]:
        summed = np.where(_deviation(osrm) <= self.gamma_max, osrm.values, 0).sum(axis=2)
        rows, cols = np.nonzero(
            summed > self.threshold * float(summed.max()) if summed.max() > 0 else summed > 0
        )
        return rows, cols

    def candidates(
        self, osrm: OSRM, query: ReachabilityQuery, rng: np.random.Generator
    ) -> Iterator[Candidate]:
        """Cells above the threshold in random order, each once, oriented to the targets."""
        rows, cols = self._cells(osrm)
        g_to = osrm.gamma_to_target(rows, cols) if len(rows) else np.zeros(0)
        l_count = len(osrm.gammas)
        for k in rng.permutation(len(rows)):
            b = round(g_to[k] / (2 * math.pi) * l_count) % l_count
            yield _candidate(osrm, rows[k], cols[k], g_to[k], osrm.values[rows[k], cols[k], b])


@dataclass(frozen=True)
class MinReachabilityToObject(ToObject):
    """MRTO: a TO cell; turn away from the targets step by step until the value exceeds the threshold."""

    mr_threshold: float = 0.2
    name: str = "MRTO"

    def candidates(
        self, osrm: OSRM, query: ReachabilityQuery, rng: np.random.Generator
    ) -> Iterator[Candidate]:
        """Per TO cell, the orientation nearest the targets whose OSRM value is high enough."""
        rows, cols = self._cells(osrm)
        g_to = osrm.gamma_to_target(rows, cols) if len(rows) else np.zeros(0)
        l_count = len(osrm.gammas)
        step = 2 * math.pi / l_count
        thr = self.mr_threshold * float(osrm.values.max())
        for k in rng.permutation(len(rows)):
            base = round(g_to[k] / step) % l_count
            for i in range(int(self.gamma_max / step) + 1):
                for sign in (1, -1) if i else (1,):
                    b = (base + sign * i) % l_count
                    value = osrm.values[rows[k], cols[k], b]
                    if value > thr:
                        yield _candidate(osrm, rows[k], cols[k], osrm.gammas[b], value)
                        break
                else:
                    continue
                break


@dataclass(frozen=True)
class FlatORM:
    """Baseline: the ORM of seed 000's reference [1]: the IRM intersected with the floor plane z = 0.

    It ignores the planar regions: every cell within reach is a candidate standing on z = 0, sampled
    like TO (a random cell above the threshold, facing the targets).
    """

    threshold: float = 0.2
    n_orientations: int = 36
    name: str = "orm"

    def candidates(
        self, osrm: OSRM, query: ReachabilityQuery, rng: np.random.Generator
    ) -> Iterator[Candidate]:
        """Floor cells in random order, facing the targets."""
        X, Y = osrm.seg.hmap.cell_centres()
        goal = osrm.targets[:, :3, 3].mean(axis=0)
        near = np.ones(X.shape, dtype=bool)
        for T in osrm.targets:
            near &= np.hypot(X - T[0, 3], Y - T[1, 3]) <= osrm.reach
        rows, cols = np.nonzero(near)
        gam = np.arctan2(goal[1] - Y[rows, cols], goal[0] - X[rows, cols])
        poses = plane_base_poses(X[rows, cols], Y[rows, cols], gam, [0, 0, 1], 0.0)
        values = inverse_reachability(query, osrm.targets, poses)
        keep = values > self.threshold * float(values.max()) if values.max() > 0 else values > 0
        idx = np.flatnonzero(keep)
        for k in rng.permutation(idx):
            yield Candidate(poses[k], -1, float(values[k]))


@dataclass(frozen=True)
class GridSearch:
    """Baseline: every region cell within reach x every orientation, in grid order, no map values."""

    name: str = "grid"

    def candidates(
        self, osrm: OSRM, query: ReachabilityQuery, rng: np.random.Generator
    ) -> Iterator[Candidate]:
        """Cells row by row, orientations in order."""
        near = osrm.near
        for row, col in zip(*np.nonzero(near), strict=True):
            for gamma in osrm.gammas:
                yield _candidate(osrm, row, col, gamma, 0.0)


@dataclass(frozen=True)
class RandomPlacement:
    """Baseline: a uniformly random region cell within reach and a random orientation."""

    name: str = "random"

    def candidates(
        self, osrm: OSRM, query: ReachabilityQuery, rng: np.random.Generator
    ) -> Iterator[Candidate]:
        """Random draws with replacement (never exhausts)."""
        rows, cols = np.nonzero(osrm.near)
        if len(rows) == 0:
            return
        while True:
            k = int(rng.integers(len(rows)))
            yield _candidate(osrm, rows[k], cols[k], float(rng.uniform(0, 2 * math.pi)), 0.0)


def make_strategy(name: str, gamma_max: float = math.pi / 4) -> Strategy:
    """The strategy called ``name`` (one of :data:`STRATEGIES`)."""
    if name == "MR":
        return MaximumReachability(gamma_max=gamma_max)
    if name == "TO":
        return ToObject(gamma_max=gamma_max)
    if name == "MRTO":
        return MinReachabilityToObject(gamma_max=gamma_max)
    if name == "orm":
        return FlatORM()
    if name == "grid":
        return GridSearch()
    if name == "random":
        return RandomPlacement()
    raise unknown("strategy", name, STRATEGIES)
