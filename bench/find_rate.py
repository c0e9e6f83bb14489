"""Issue 25, second "Must show": how often ``place`` finds a placement that exists (false negatives), and
whether any placement it returns touches the true scene (false positives).

Protocol: docs/protocols/find_rate_v1.md (committed before any held-out run; the held-out split is
refused while it has uncommitted changes). Run for the figures after a change:

    python bench/find_rate.py --seeds held-out --out bench/results/find_rate_after.json

Per scene (one seed each; even seeds a side grasp, odd seeds a top-down grasp):

* The true scene: a table (a solid box on the floor), the grasped bottle (a cylinder) near one of
  its edges, 0-2 neighbour bottles 3-8 cm beside it, the floor. The cloud ``place`` sees samples
  the table's top and sides, the bottles and the floor, with 3 mm Gaussian noise per axis.
* The oracle, on the true shapes and nothing of the method (no cloud, no voxels, no reachability
  map): base poses on a grid around the grasp, coarse to fine (:data:`LEVELS`), each with IK from
  several random starts (``DampedLeastSquaresIK``, the project's solver, only proposing: pinocchio's
  FK must put the TCP on the target), and coal on the URDF's collision meshes, loaded here with
  ``pinocchio.buildGeomFromUrdf`` (as tests/test_grasped_object.py's ``_touching``), against the
  true table, neighbours and floor; only the hand's geometries may touch the grasped bottle. It
  stops at the first collision-free pose. It checks no motion: a placement exists when a
  collision-free configuration at the grasp exists.
* The method: ``place`` through the jobs layer the CLI uses (``baseplace.jobs.place.place_job``)
  with its defaults (``PlaceSettings()``, the default TIAGo map, ``--object auto``), the noisy
  cloud and the grasp point (``--grasp-point``). Found: >= 1 verified placement. Every returned
  placement is checked by the oracle's collision check at its own joints: a false positive touches
  the true scene (the hand on the grasped bottle excepted) or itself.

Keeps to one process and one thread (run as a script, ``NUMBA_NUM_THREADS=1`` is set before any import
of numba).
"""

from __future__ import annotations

import os

if __name__ == "__main__":  # one core: the machine is shared (not when a test imports this file:
    os.environ.setdefault("NUMBA_NUM_THREADS", "1")  # numba then refuses a second thread count)

import argparse
import hashlib
import json
import math
import sys
import time
from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import coal
import numpy as np
import pinocchio as pin

from baseplace.errors import InputError
from baseplace.geometry.poses import invert_transforms, pose_from_xyz_rpy
from baseplace.placement.robustness import wilson_interval
from baseplace.robots.collision import SelfCollision
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.robots.model import Robot
from baseplace_experiments.results import RunClock, SeedSplit, fixed_protocol, git_commit, write_results

PROTOCOL_FILE = "docs/protocols/find_rate_v1.md"
SEEDS = SeedSplit(dev=tuple(range(25000, 25010)), held_out=tuple(range(25100, 25160)))
"""One scene per seed; even seeds side grasps, odd seeds top-down grasps."""
NOISE = 0.003
"""Gaussian noise per axis of the cloud [m] (issue 25's robotics case)."""
LEVELS = ((0.10, 12), (0.05, 24))
"""The oracle's base-pose grids, tried in turn: (position spacing [m], headings per position)."""
IK_STARTS = 4
"""IK solves per oracle base pose; each starts from a uniform random configuration (shared by the
poses of one batch) and then tries :data:`IK_RESTARTS` random restarts of its own."""
IK_RESTARTS = 3
"""Random restarts within one IK solve."""
TOL_POSITION, TOL_ROTATION = 1e-3, 1e-2
"""Pinocchio FK must put the TCP within these of the target [m, rad]."""
CHUNK = 256
"""Base poses per IK batch."""
ON_FLOOR = 0.05
"""A returned base pose stands on the floor when its height is at most this [m] (else on the table top)."""
APPROACH_STEP = 0.0025
"""Protocol v2's oracle: the straight approach is walked back from the grasp in steps of this [m]."""
APPROACH_MAX = 0.30
"""Protocol v2's oracle: how far back [m] the hand may have to go before it touches nothing."""
APPROACH_JOINT_STEP = 0.2
"""Protocol v2's oracle: the largest joint change between two approach states [rad or m]."""
PROTOCOLS = {
    "v1": ("docs/protocols/find_rate_v1.md", SEEDS, False),
    "v2": ("docs/protocols/find_rate_v2.md",
           SeedSplit(dev=tuple(range(25000, 25060)), held_out=tuple(range(25200, 25300))), True),
    "v2-fresh": ("docs/protocols/find_rate_v2_fresh.md",
                 SeedSplit(dev=tuple(range(25000, 25060)), held_out=tuple(range(25300, 25400))), True),
    "v2-plane": ("docs/protocols/find_rate_v2_plane.md",
                 SeedSplit(dev=tuple(range(25000, 25060)), held_out=tuple(range(25400, 25500))), True),
    "v2-plane-4mm": ("docs/protocols/find_rate_v2_plane.md",
                     SeedSplit(dev=tuple(range(25000, 25060)), held_out=tuple(range(25500, 25600))), True),
}  # fmt: skip
"""Per protocol: its file, its seeds, and whether the oracle demands a straight approach (v2, and
v2-fresh and v2-plane: v2 on fresh held-out seeds, the library before and after a change)."""
NOISES = {"v2-plane-4mm": 0.004}
"""A protocol's noise per axis [m], where it is not :data:`NOISE`."""


@dataclass(frozen=True)
class Solid:
    """A true shape: a coal primitive and its world pose (4, 4)."""

    name: str
    geometry: coal.CollisionGeometry
    T: np.ndarray

    def transform(self) -> coal.Transform3s:
        return coal.Transform3s(self.T[:3, :3], self.T[:3, 3])


def _at(x: float, y: float, z: float) -> np.ndarray:
    return pose_from_xyz_rpy([x, y, z, 0.0, 0.0, 0.0])


@dataclass
class Scene:
    """One generated scene: the true shapes, the noisy cloud and the grasp."""

    seed: int
    kind: str
    table: tuple[float, float, float]  # size x, size y, height [m]; centred at the origin
    bottle: tuple[float, float, float, float]  # x, y, radius, height [m]; standing on the table
    neighbours: list[tuple[float, float, float, float]]
    grasp: list[float]  # grasp point x y z roll pitch yaw [m, rad]
    cloud: np.ndarray

    def solids(self) -> tuple[list[Solid], Solid, Solid]:
        """(obstacles: table and neighbours, the grasped bottle, the floor)."""
        lx, ly, h = self.table
        out = [Solid("table", coal.Box(lx, ly, h), _at(0.0, 0.0, h / 2))]
        for k, (x, y, r, hb) in enumerate(self.neighbours):
            out.append(Solid(f"neighbour {k}", coal.Cylinder(r, hb), _at(x, y, h + hb / 2)))
        x, y, r, hb = self.bottle
        bottle = Solid("bottle", coal.Cylinder(r, hb), _at(x, y, h + hb / 2))
        floor = Solid("floor", coal.Box(20.0, 20.0, 2.0), _at(0.0, 0.0, -1.0))  # everything under z = 0
        return out, bottle, floor

    def record(self) -> dict[str, Any]:
        """The scene as stored in the results (the cloud by its hash)."""
        return {"seed": self.seed, "kind": self.kind, "table": [round(v, 4) for v in self.table],
                "bottle": [round(v, 4) for v in self.bottle],
                "neighbours": [[round(v, 4) for v in n] for n in self.neighbours],
                "grasp_point": [round(v, 5) for v in self.grasp], "cloud_points": len(self.cloud),
                "cloud_sha256": hashlib.sha256(self.cloud.tobytes()).hexdigest()[:16]}  # fmt: skip


def _grid(lo: float, hi: float, d: float) -> np.ndarray:
    return np.linspace(lo, hi, max(2, round((hi - lo) / d) + 1))


def _box_cloud(lx: float, ly: float, h: float) -> np.ndarray:
    """Table top (1 cm) and its four sides (2 cm), noise-free."""
    X, Y = np.meshgrid(_grid(-lx / 2, lx / 2, 0.01), _grid(-ly / 2, ly / 2, 0.01))
    parts = [np.c_[X.ravel(), Y.ravel(), np.full(X.size, h)]]
    zs = _grid(0.0, h, 0.02)
    for xs, ys in ((_grid(-lx / 2, lx / 2, 0.02), None), (None, _grid(-ly / 2, ly / 2, 0.02))):
        for side in (-1, 1):
            if xs is not None:
                A, Z = np.meshgrid(xs, zs)
                parts.append(np.c_[A.ravel(), np.full(A.size, side * ly / 2), Z.ravel()])
            else:
                assert ys is not None
                A, Z = np.meshgrid(ys, zs)
                parts.append(np.c_[np.full(A.size, side * lx / 2), A.ravel(), Z.ravel()])
    return np.concatenate(parts)


def _cylinder_cloud(x: float, y: float, r: float, z0: float, hb: float) -> np.ndarray:
    """Side and top of a standing cylinder, about 1 cm apart, noise-free."""
    angles = np.linspace(0, 2 * math.pi, max(12, math.ceil(2 * math.pi * r / 0.01)), endpoint=False)
    A, Z = np.meshgrid(angles, _grid(z0, z0 + hb, 0.01))
    side = np.c_[x + r * np.cos(A.ravel()), y + r * np.sin(A.ravel()), Z.ravel()]
    X, Y = np.meshgrid(_grid(-r, r, 0.01), _grid(-r, r, 0.01))
    inside = np.hypot(X, Y).ravel() <= r
    top = np.c_[x + X.ravel()[inside], y + Y.ravel()[inside], np.full(inside.sum(), z0 + hb)]
    return np.concatenate([side, top])


def make_scene(seed: int, noise: float = NOISE) -> Scene:
    """The scene of ``seed`` (docs/protocols/find_rate_v1.md, "Scenes"); ``noise`` [m] per axis (dev runs only: ``--noise``)."""
    rng = np.random.default_rng([25, seed])
    kind = "side" if seed % 2 == 0 else "top-down"
    lx, ly, h = rng.uniform(0.8, 1.6), rng.uniform(0.6, 1.0), rng.uniform(0.70, 0.80)
    r, hb = rng.uniform(0.03, 0.045), rng.uniform(0.18, 0.28)
    edge = int(rng.integers(4))  # +x, +y, -x, -y: the edge the bottle stands near
    normal = np.array([(1, 0), (0, 1), (-1, 0), (0, -1)][edge], dtype=float)
    half = np.array([lx / 2, ly / 2])
    along = np.array([-normal[1], normal[0]])
    inset = rng.uniform(0.08, 0.25)
    span = float(abs(along @ half)) - 0.15
    centre = normal * (abs(normal @ half) - inset) + along * rng.uniform(-span, span)
    neighbours: list[tuple[float, float, float, float]] = []
    placed = [(float(centre[0]), float(centre[1]), r)]
    want = int(rng.integers(3))
    for _ in range(200):
        if len(neighbours) == want:
            break
        rn, hn = rng.uniform(0.03, 0.045), rng.uniform(0.10, 0.30)
        gap, angle = rng.uniform(0.03, 0.08), rng.uniform(0, 2 * math.pi)
        p = centre + (r + gap + rn) * np.array([math.cos(angle), math.sin(angle)])
        if np.any(np.abs(p) > half - rn - 0.01):
            continue  # off the table top
        if any(math.hypot(p[0] - x, p[1] - y) < rn + ro + 0.03 for x, y, ro in placed):
            continue  # closer than 3 cm to another bottle
        neighbours.append((float(p[0]), float(p[1]), rn, hn))
        placed.append((float(p[0]), float(p[1]), rn))
    if kind == "side":  # the hand comes from outside the table, within 60 deg of the edge's normal
        yaw = math.atan2(-normal[1], -normal[0]) + rng.uniform(-math.pi / 3, math.pi / 3)
        z = rng.uniform(h + 0.05, h + hb - 0.03)
        grasp = [float(centre[0]), float(centre[1]), z, 0.0, 0.0, yaw]
    else:  # from above, 2 cm under the bottle's top, any roll about the vertical
        grasp = [
            float(centre[0]),
            float(centre[1]),
            h + hb - 0.02,
            0.0,
            math.pi / 2,
            rng.uniform(-math.pi, math.pi),
        ]
    extent = max(lx, ly) / 2 + 2.0
    FX, FY = np.meshgrid(_grid(-extent, extent, 0.02), _grid(-extent, extent, 0.02))
    floor = np.c_[FX.ravel(), FY.ravel(), np.zeros(FX.size)]
    floor = floor[np.any(np.abs(floor[:, :2]) > half, axis=1)]  # not under the table
    clean = [floor, _box_cloud(lx, ly, h), _cylinder_cloud(*centre, r, h, hb)]
    clean += [_cylinder_cloud(x, y, rn, h, hn) for x, y, rn, hn in neighbours]
    points = np.concatenate(clean)
    cloud = points + rng.normal(0.0, noise, points.shape)
    return Scene(
        seed, kind, (lx, ly, h), (float(centre[0]), float(centre[1]), r, hb), neighbours, grasp, cloud
    )


class Oracle:
    """Collision checks on the true shapes with the URDF's own collision meshes, and the pose search.

    The hand: every geometry that the arm's last joint moves (wrist, palm, fingers); only it may
    touch the grasped bottle. The floor: checked against the geometries that the arm's first
    revolute joint moves (the base and torso stand on it). Self-collision: the project's
    :class:`~baseplace.robots.collision.SelfCollision` (the URDF's pairs less the SRDF's allowed ones).
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.arm = robot.arm()
        model = robot.model
        self.model = model
        self.data = model.createData()
        self.geom = pin.buildGeomFromUrdf(model, str(robot.spec.urdf), pin.COLLISION,
                                          package_dirs=[str(p) for p in robot.spec.package_dirs])  # fmt: skip
        self.gdata = pin.GeometryData(self.geom)
        self.self_collision = SelfCollision(robot, num_threads=1)
        names = self.arm.joint_names
        last = model.getJointId(names[-1])
        first_revolute = next(
            model.getJointId(n)
            for n in names
            if model.joints[model.getJointId(n)].shortname().startswith("JointModelR")
        )
        objs = self.geom.geometryObjects
        self.hand = {k for k, g in enumerate(objs) if last in set(model.supports[g.parentJoint])}
        self.above_floor = {
            k for k, g in enumerate(objs) if first_revolute in set(model.supports[g.parentJoint])
        }
        self.hand_links = sorted({model.frames[objs[k].parentFrame].name for k in self.hand})
        ref = model.createData()
        pin.framesForwardKinematics(model, ref, robot.q_reference)
        self.T_root_base = ref.oMf[model.getFrameId(robot.spec.base_frame)].homogeneous
        self.T_tcp_grasp = robot.T_tcp_grasp(None)
        self.ik = DampedLeastSquaresIK(self.arm, restarts=IK_RESTARTS)
        self._base = model.getFrameId(self.arm.base_frame)
        self._tcp = model.getFrameId(self.arm.tcp_frame)
        # the largest horizontal distance base -> TCP over 20000 random configurations, + 5 cm
        rng = np.random.default_rng(0)
        reach = 0.0
        for q in rng.uniform(self.arm.lower, self.arm.upper, (20000, self.arm.n_joints)):
            pin.framesForwardKinematics(model, self.data, self.arm.to_pinocchio(q, robot.q_reference))
            p = (self.data.oMf[self._base].inverse() * self.data.oMf[self._tcp]).translation
            reach = max(reach, math.hypot(p[0], p[1]))
        self.reach = reach + 0.05

    def reaches(self, q: np.ndarray, T_base_tcp: np.ndarray) -> bool:
        """Pinocchio FK puts the TCP at ``q`` (n,) on ``T_base_tcp`` (4, 4), within the tolerances."""
        pin.framesForwardKinematics(self.model, self.data, self.arm.to_pinocchio(q, self.robot.q_reference))
        T = (self.data.oMf[self._base].inverse() * self.data.oMf[self._tcp]).homogeneous
        c = (np.trace(T[:3, :3].T @ T_base_tcp[:3, :3]) - 1.0) / 2.0
        return bool(np.linalg.norm(T[:3, 3] - T_base_tcp[:3, 3]) <= TOL_POSITION
                    and math.acos(min(1.0, max(-1.0, c))) <= TOL_ROTATION)  # fmt: skip

    def contacts(self, q_arm: np.ndarray, T_world_base: np.ndarray, scene: Scene, first: bool = True,
                 skip_hand: bool = False) -> list[str]:  # fmt: skip
        """What the robot at arm joints (n,) and base pose (4, 4) touches: "self", "LINK - SHAPE".

        The hand may touch the grasped bottle (listed as "LINK - bottle (hand)", never a contact
        that counts). With ``first`` it stops at the first counting contact; with ``skip_hand`` the
        hand's geometries are not checked (the search checks them once, at the grasp).
        """
        out = []
        if not bool(self.arm.within_limits(q_arm)):
            out.append("joint limits")
            if first:
                return out
        if self.self_collision.colliding_arm(self.arm, q_arm)[0]:
            out.append("self")
            if first:
                return out
        q = self.arm.to_pinocchio(q_arm, self.robot.q_reference)
        pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata, q)
        T_world_root = np.asarray(T_world_base, dtype=float) @ invert_transforms(self.T_root_base)
        geoms = range(len(self.geom.geometryObjects))
        if skip_hand:  # already checked at the grasp (:meth:`hand_contacts`)
            geoms = [k for k in geoms if k not in self.hand]
        return out + self._touching(list(geoms), T_world_root, scene, first)

    def hand_contacts(self, T_world_tcp: np.ndarray, scene: Scene) -> list[str]:
        """What the hand's geometries touch with the TCP at ``T_world_tcp`` (4, 4), whatever the base pose."""
        return self._touching(sorted(self.hand), self.hand_placed(T_world_tcp), scene, first=False)

    def hand_placed(self, T_world_tcp: np.ndarray) -> np.ndarray:
        """The root's world pose (4, 4) that puts the TCP on ``T_world_tcp`` (4, 4), with the geometries
        placed (``self.gdata``) for a mid-range arm: the hand's are right whatever the arm, the rest not."""
        q = self.arm.to_pinocchio(0.5 * (self.arm.lower + self.arm.upper), self.robot.q_reference)
        pin.framesForwardKinematics(self.model, self.data, q)
        pin.updateGeometryPlacements(self.model, self.data, self.geom, self.gdata, q)
        T_root_tcp = self.data.oMf[self._tcp].homogeneous
        return np.asarray(T_world_tcp, dtype=float) @ invert_transforms(T_root_tcp)

    def _touching(self, geoms: list[int], T_world_root: np.ndarray, scene: Scene, first: bool) -> list[str]:
        """Contacts of the posed geometries ``geoms`` (placements in ``self.gdata``) with the true shapes."""
        obstacles, bottle, floor = scene.solids()
        request = coal.CollisionRequest()
        out = []
        for k in geoms:
            g = self.geom.geometryObjects[k]
            T = T_world_root @ self.gdata.oMg[k].homogeneous
            Tg = coal.Transform3s(T[:3, :3], T[:3, 3])
            shapes = [*obstacles, bottle] + ([floor] if k in self.above_floor else [])
            for s in shapes:
                if coal.collide(g.geometry, Tg, s.geometry, s.transform(), request, coal.CollisionResult()):
                    link = self.model.frames[g.parentFrame].name
                    if s is bottle and k in self.hand:
                        out.append(f"{link} - bottle (hand)")
                        continue
                    out.append(f"{link} - {s.name}")
                    if first:
                        return out
        return out

    def approach(
        self, q_grasp: np.ndarray, T_base: np.ndarray, T_tcp: np.ndarray, scene: Scene
    ) -> dict[str, Any]:
        """Whether the hand can come straight in to the grasp: protocol v2's approach check.

        Walks the TCP back from the grasp (joints ``q_grasp`` (n,), TCP at ``T_tcp`` (4, 4) in the
        world, base at ``T_base`` (4, 4)) along the arm's approach axis, :data:`APPROACH_STEP` at a
        time, each state's IK seeded with the last state (and 4 small perturbations of it); pinocchio
        FK must put the TCP on the line, no joint may change by more than :data:`APPROACH_JOINT_STEP`
        between two states, and every state must touch nothing but the grasped bottle with the
        hand (:meth:`contacts`). The approach exists once a state touches nothing at all (the
        hand clear of the bottle) within :data:`APPROACH_MAX`. Returns ``ok``, the distance [m],
        and the reason of a failure (``ik``, ``jump`` or the first contact that counts).
        """
        T_base_inv = invert_transforms(T_base)
        jitter = np.random.default_rng(0).normal(0.0, 0.05, size=(4, self.arm.n_joints))
        q = np.asarray(q_grasp, dtype=float)
        for k, T in self._back_along_approach(T_tcp):
            T_base_tcp = T_base_inv @ T
            seeds = np.clip(np.vstack([q, q + jitter]), self.arm.lower, self.arm.upper)
            q_next = self.ik.solve_from(T_base_tcp, seeds)
            distance = round(k * APPROACH_STEP, 4)
            if q_next is None or not self.reaches(q_next, T_base_tcp):
                return {"ok": False, "distance": distance, "why": "ik"}
            if float(np.max(np.abs(q_next - q))) > APPROACH_JOINT_STEP:
                return {"ok": False, "distance": distance, "why": "jump"}
            q = q_next
            touched = self.contacts(q, T_base, scene, first=False)
            hit = self.counting(touched)
            if hit:
                return {"ok": False, "distance": distance, "why": hit[0]}
            if not touched:
                return {"ok": True, "distance": distance, "why": None}
        return {"ok": False, "distance": APPROACH_MAX, "why": "hand not clear"}

    def hand_clear_pose(self, T_tcp: np.ndarray, scene: Scene) -> np.ndarray | None:
        """The TCP pose (4, 4) back along the approach from ``T_tcp`` (4, 4) where the hand alone first
        touches nothing (steps of :data:`APPROACH_STEP`), or None within :data:`APPROACH_MAX`."""
        for _, T in self._back_along_approach(T_tcp):
            if not self.hand_contacts(T, scene):
                return T
        return None

    def _back_along_approach(self, T_tcp: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
        """(k, TCP pose (4, 4)) k :data:`APPROACH_STEP` back from ``T_tcp`` along the approach axis, up to
        :data:`APPROACH_MAX`: the one line :meth:`approach` walks and :meth:`hand_clear_pose` scans."""
        direction = T_tcp[:3, :3] @ self.arm.approach_axis
        for k in range(1, math.ceil(APPROACH_MAX / APPROACH_STEP - 1e-9) + 1):
            T = T_tcp.copy()
            T[:3, 3] -= k * APPROACH_STEP * direction
            yield k, T

    def _reachable(self, T_base_tcp: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(N,) whether the (N, 4, 4) TCP poses have an IK solution (:data:`IK_STARTS` solves, FK-checked)."""
        ok = np.zeros(len(T_base_tcp), dtype=bool)
        for _ in range(IK_STARTS):
            q, solved = self.ik.solve_batch(
                T_base_tcp, rng, q_seed=rng.uniform(self.arm.lower, self.arm.upper)
            )
            for n in np.flatnonzero(solved & ~ok):
                ok[n] = self.reaches(q[n], T_base_tcp[n])
        return ok

    @staticmethod
    def counting(contacts: list[str]) -> list[str]:
        """The contacts that make a configuration collide (all but the hand on the grasped bottle)."""
        return [c for c in contacts if not c.endswith("(hand)")]

    def search(self, scene: Scene, rng: np.random.Generator, approach: bool = False) -> dict[str, Any]:
        """The first collision-free base pose of :data:`LEVELS`, or none; with what was tried.

        With ``approach`` (protocol v2) a pose counts only when :meth:`approach` finds the straight
        approach to its grasp configuration; the search goes on through every collision-free
        configuration until one has it. The first collision-free configuration, with or without
        an approach, is kept as the v1 verdict (``grasp_only``). The hand alone clears the bottle
        at a distance back that holds for every base pose (it is rigid on the TCP); a pose whose
        TCP has no IK solution there (:data:`IK_STARTS` random starts, drawn from a generator
        of their own) cannot have the approach, and is not walked.
        """
        T_grasp = pose_from_xyz_rpy(scene.grasp)
        T_tcp = T_grasp @ np.linalg.inv(self.T_tcp_grasp)
        gx, gy = T_grasp[0, 3], T_grasp[1, 3]
        lx, ly, _ = scene.table
        clear = self.robot.spec.footprint_bounding_radius
        t0 = time.perf_counter()
        tried, solved, blocked = 0, 0, Counter[str]()
        # the hand is rigid on the TCP (fingers at their reference values): at the grasp it lies where
        # it lies from every base pose, so one check decides whether any placement can exist
        hand = self.counting(self.hand_contacts(T_tcp, scene))
        grasp_only: dict[str, Any] | None = None
        walks: Counter[str] = Counter()
        if hand:
            none = {"found": False, "level": None, "poses_tried": 0, "ik_solutions": 0,
                    "blocked_by": {}, "hand_at_grasp": hand, "seconds": round(time.perf_counter() - t0, 2)}  # fmt: skip
            return {**none, "grasp_only": dict(none), "approaches_failed": {}} if approach else none
        T_far = far_rng = None
        if approach:  # the necessary condition's IK draws from a generator of its own (v1's draws unchanged)
            far_rng = np.random.default_rng(rng.bit_generator.seed_seq.spawn(1)[0])  # type: ignore[attr-defined]
            T_far = self.hand_clear_pose(T_tcp, scene)
        for level, (d, n_yaw) in enumerate(LEVELS):
            k = math.ceil(self.reach / d)
            g = np.arange(-k, k + 1) * d
            X, Y = np.meshgrid(gx + g, gy + g)
            xy = np.c_[X.ravel(), Y.ravel()]
            dist = np.hypot(xy[:, 0] - gx, xy[:, 1] - gy)
            # outside the table's footprint grown by the base's bounding radius
            dx, dy = np.maximum(np.abs(xy[:, 0]) - lx / 2, 0), np.maximum(np.abs(xy[:, 1]) - ly / 2, 0)
            keep = (dist <= self.reach) & (np.hypot(dx, dy) > clear)
            xy, dist = xy[keep], dist[keep]
            xy = xy[np.argsort(np.abs(dist - 0.6), kind="stable")]  # arm's length first
            yaws = np.arange(n_yaw) * (2 * math.pi / n_yaw)
            poses = np.array([(x, y, math.atan2(gy - y, gx - x) + a) for x, y in xy for a in yaws])
            for lo in range(0, len(poses), CHUNK):
                chunk = poses[lo : lo + CHUNK]
                c, s = np.cos(chunk[:, 2]), np.sin(chunk[:, 2])
                T_base = np.zeros((len(chunk), 4, 4))
                T_base[:, 0, 0], T_base[:, 0, 1], T_base[:, 1, 0], T_base[:, 1, 1] = c, -s, s, c
                T_base[:, 2, 2] = T_base[:, 3, 3] = 1.0
                T_base[:, 0, 3], T_base[:, 1, 3] = chunk[:, 0], chunk[:, 1]
                T_base_tcp = invert_transforms(T_base) @ T_tcp
                tried += len(chunk)
                far_ok: np.ndarray | None = None
                for _ in range(IK_STARTS):  # each solve: a random first start, then its random restarts
                    q_seed = rng.uniform(self.arm.lower, self.arm.upper)
                    q, ok = self.ik.solve_batch(T_base_tcp, rng, q_seed=q_seed)
                    for n in np.flatnonzero(ok):
                        if not self.reaches(q[n], T_base_tcp[n]):
                            continue
                        solved += 1
                        hit = self.counting(self.contacts(q[n], T_base[n], scene, skip_hand=True))
                        if hit:
                            blocked[hit[0].split(" - ")[-1]] += 1
                            continue
                        verdict = {"found": True, "level": level, "base": [round(float(v), 4) for v in chunk[n]],
                                   "joints": np.round(q[n], 6).tolist(), "poses_tried": tried,
                                   "ik_solutions": solved, "blocked_by": dict(blocked),
                                   "seconds": round(time.perf_counter() - t0, 2)}  # fmt: skip
                        if not approach:
                            return verdict
                        grasp_only = grasp_only or verdict
                        if T_far is None:
                            walks["hand not clear"] += 1
                            continue
                        if far_ok is None:
                            assert far_rng is not None
                            far_ok = self._reachable(invert_transforms(T_base) @ T_far, far_rng)
                        if not far_ok[n]:
                            walks["no ik where the hand clears"] += 1
                            continue
                        walk = self.approach(q[n], T_base[n], T_tcp, scene)
                        if not walk["ok"]:
                            walks[walk["why"]] += 1
                            continue
                        verdict["seconds"] = round(time.perf_counter() - t0, 2)
                        return {**verdict, "approach_m": walk["distance"], "grasp_only": grasp_only,
                                "approaches_failed": dict(walks)}  # fmt: skip
        none = {"found": False, "level": None, "poses_tried": tried, "ik_solutions": solved,
                "blocked_by": dict(blocked), "seconds": round(time.perf_counter() - t0, 2)}  # fmt: skip
        if not approach:
            return none
        return {**none, "grasp_only": grasp_only or dict(none), "approaches_failed": dict(walks)}


def unrounded(q: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> tuple[np.ndarray, bool]:
    """Joints (n,) of a result row, which rounds them to 1e-6 rad: one at its limit may come back
    just past it. Those within 1e-6 of the limits are put back on them; returns (q, whether any was)."""
    inside = np.clip(q, lower, upper)
    rounded = bool(np.any(inside != q) and np.all(np.abs(inside - q) <= 1e-6))
    return (inside, True) if rounded else (q, False)


def run_place(scene: Scene, oracle: Oracle) -> dict[str, Any]:
    """``place`` with its defaults on the noisy cloud; every returned placement checked on the true scene."""
    from baseplace.jobs.inputs import CloudInput
    from baseplace.jobs.place import PlaceJob, place_job
    from baseplace.jobs.report import NoResultError

    job = PlaceJob(targets=[], grasp_points=[scene.grasp], cloud=CloudInput(points=scene.cloud),
                   object="auto", segmentation_cache=False)  # fmt: skip
    t0 = time.perf_counter()
    try:
        report = place_job(job)
    except NoResultError as e:
        r = e.report
        return {"found": False, "seconds": round(time.perf_counter() - t0, 2), "refusal": str(e),
                "failures": dict(r.failures), "contacts": r.collisions[:5], "tries": r.tries,
                "object": r.object.get("found")}  # fmt: skip
    except InputError as e:
        return {"found": False, "seconds": round(time.perf_counter() - t0, 2), "refusal": f"input: {e}",
                "failures": {}, "contacts": [], "tries": 0, "object": None}  # fmt: skip
    seconds = time.perf_counter() - t0
    rows = []
    for row in report.placements:
        T = np.asarray(row["base_pose"], dtype=float)
        q = np.array([row["joints"][0][n] for n in oracle.arm.joint_names])
        q, rounded = unrounded(q, oracle.arm.lower, oracle.arm.upper)
        touched = oracle.contacts(q, T, scene, first=False)
        rows.append({"base": [row["x"], row["y"], row["yaw"]], "base_z": row["z"], "joints": q.round(6).tolist(),
                     "touches": oracle.counting(touched),
                     "hand_on_bottle": any(c.endswith("(hand)") for c in touched),
                     "joints_clipped_from_rounding": rounded})  # fmt: skip
    return {"found": bool(rows), "seconds": round(seconds, 2), "placements": rows, "failures": dict(report.failures),
            "tries": report.tries, "object": report.object.get("found")}  # fmt: skip


def refusal_reason(method: dict[str, Any]) -> str:
    """One key per refusal: the most frequent contact (link and what), else the failure counts."""
    if method["found"]:
        return "found"
    if method["refusal"].startswith("input:"):
        return method["refusal"]
    if method["contacts"]:
        c = method["contacts"][0]
        return f"{c['link']} touched {c['touched']}"
    return "failures " + ", ".join(f"{k}={v}" for k, v in sorted(method["failures"].items()))


def scenes_by_seed(paths: list[str]) -> dict[int, dict[str, Any]]:
    """Each scene's row of these results files by its seed (a later file's row replaces an earlier one's)."""
    out: dict[int, dict[str, Any]] = {}
    for path in paths:
        for r in json.loads(Path(path).read_text())["scenes"]:
            out[r["scene"]["seed"]] = r
    return out


def summarise(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Find rate (Wilson 95 %) over scenes the oracle solves, per kind and overall; FP; refusal reasons."""
    out: dict[str, Any] = {}
    for kind in ("all", "side", "top-down"):
        sel = [r for r in rows if kind == "all" or r["scene"]["kind"] == kind]
        solvable = [r for r in sel if r["oracle"]["found"]]
        found = sum(r["method"]["found"] for r in solvable)
        placements = [p for r in sel for p in r["method"].get("placements", [])]
        fp = [p for p in placements if p["touches"]]
        on_table = [p for p in placements if p["base_z"] > ON_FLOOR]
        floor = sum(any(p["base_z"] <= ON_FLOOR for p in r["method"].get("placements", [])) for r in solvable)
        low, high = wilson_interval(found, len(solvable)) if solvable else (math.nan, math.nan)
        out[kind] = {"scenes": len(sel), "oracle_none": len(sel) - len(solvable), "solvable": len(solvable),
                     "found": found, "find_rate": found / len(solvable) if solvable else math.nan,
                     "ci95": [round(low, 4), round(high, 4)],
                     "found_where_oracle_none": sum(r["method"]["found"] for r in sel if not r["oracle"]["found"]),
                     "found_on_floor": floor, "find_rate_on_floor": floor / len(solvable) if solvable else math.nan,
                     "placements": len(placements), "false_positives": len(fp),
                     "placements_on_table_top": len(on_table),
                     "false_positives_on_the_floor": sum(1 for p in fp if p["base_z"] <= ON_FLOOR),
                     "false_positive_contacts": [p["touches"] for p in fp],
                     "refusals": dict(Counter(refusal_reason(r["method"]) for r in solvable
                                              if not r["method"]["found"]).most_common()),
                     "place_seconds_median": float(np.median([r["method"]["seconds"] for r in sel])) if sel else math.nan,
                     "place_seconds_mean": float(np.mean([r["method"]["seconds"] for r in sel])) if sel else math.nan,
                     "oracle_seconds_median": float(np.median([r["oracle"]["seconds"] for r in sel])) if sel else math.nan}  # fmt: skip
    return out


def library_commit(where: Path | None = None) -> dict[str, Any]:
    """The commit of the ``baseplace`` package that runs (it may be another checkout than this script's), or of the package at ``where``."""
    import subprocess

    import baseplace

    where = Path(baseplace.__file__).resolve().parent if where is None else where.resolve()
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=where, capture_output=True, text=True,
                              check=True, timeout=10).stdout.strip()  # fmt: skip
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", "."], cwd=where.parent,
                               capture_output=True, text=True, check=True, timeout=10).stdout.strip()  # fmt: skip
    except (OSError, subprocess.SubprocessError):
        return {"commit": None, "dirty": None}
    return {"commit": head, "dirty": bool(dirty)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--protocol", choices=tuple(PROTOCOLS), default="v1",
                        help="v1: the oracle checks the grasp configuration; v2: and the straight approach; "
                             "v2-fresh, v2-plane, v2-plane-4mm (4 mm noise): v2 on fresh held-out seeds")  # fmt: skip
    parser.add_argument("--seeds", choices=("dev", "held-out"), required=True)
    parser.add_argument("--scenes", type=int, default=None, help="only the first N scenes of the split")
    parser.add_argument("--seed", type=int, default=None, help="only this seed of the split")
    parser.add_argument("--out", required=True, help="results JSON")
    parser.add_argument("--noise", type=float, default=None, metavar="METRES",
                        help="dev split only: the cloud's noise per axis instead of the protocol's")  # fmt: skip
    parser.add_argument("--oracle-from", default=None,
                        help="reuse the oracle's verdicts of an earlier results file of the same scenes")  # fmt: skip
    args = parser.parse_args(argv)
    noise = NOISES.get(args.protocol, NOISE) if args.noise is None else args.noise
    if args.noise is not None:
        if args.seeds != "dev":
            parser.error("--noise is for the dev split only: a held-out run keeps its protocol's noise")
        if not (math.isfinite(args.noise) and 0.0 < args.noise <= 0.05):
            parser.error(f"--noise must be a noise level in metres in (0, 0.05], got {args.noise}")
    clock = RunClock()
    harness = git_commit(
        Path(__file__).resolve().parent
    )  # this script's checkout; the library may be another
    protocol_file, split, with_approach = PROTOCOLS[args.protocol]
    protocol = fixed_protocol(protocol_file, args.seeds, Path(__file__).resolve().parent)
    seeds = split.seeds(args.seeds)[: args.scenes]
    if args.seed is not None:
        if args.seed not in seeds:
            raise InputError(
                f"--seed {args.seed} is not a seed of the {args.seeds} split: {seeds[0]}-{seeds[-1]}"
            )
        seeds = (args.seed,)
    earlier = scenes_by_seed([args.oracle_from] if args.oracle_from else [])
    robot = Robot("tiago")
    oracle = Oracle(robot)
    rows = []
    for seed in seeds:
        scene = make_scene(seed, noise)
        record = scene.record()
        if seed in earlier:
            if earlier[seed]["scene"] != record:
                raise InputError(f"--oracle-from: scene {seed} differs from this run's; run the oracle again")
            verdict = earlier[seed]["oracle"]
        else:
            verdict = oracle.search(scene, np.random.default_rng([25, seed, 1]), approach=with_approach)
        method = run_place(scene, oracle)
        rows.append({"scene": record, "oracle": verdict, "method": method})
        print(seed, scene.kind, "oracle", verdict["found"], verdict["seconds"], "place", method["found"],
              method["seconds"], refusal_reason(method), [p["touches"] for p in method.get("placements", [])],
              flush=True)  # fmt: skip
    result = {
        "benchmark": "find_rate",
        "protocol": {"file": protocol_file, "noise": noise, "levels": LEVELS, "ik_starts": IK_STARTS,
                     "ik_restarts": IK_RESTARTS, "oracle_reach_m": round(oracle.reach, 4),
                     "hand_links": oracle.hand_links, "settings": "place defaults, --object auto, default map"},
        "library": library_commit(),
        "harness": harness,
        "oracle_from": Path(args.oracle_from).name if args.oracle_from else None,
        "summary": summarise(rows),
        "scenes": rows,
    }  # fmt: skip
    if with_approach:  # the same scenes and runs of place, against the v1 oracle (the grasp only)
        result["protocol"]["approach"] = {"step_m": APPROACH_STEP, "max_m": APPROACH_MAX,
                                          "joint_step": APPROACH_JOINT_STEP}  # fmt: skip
        result["summary_grasp_only_oracle"] = summarise(
            [{**r, "oracle": r["oracle"]["grasp_only"]} for r in rows]
        )
    whole = write_results(args.out, result, clock, seeds=split, split=args.seeds, used_seeds=list(seeds),
                          protocol_file=protocol)  # fmt: skip
    print(json.dumps(whole["summary"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
