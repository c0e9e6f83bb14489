"""A conservative sphere model of a robot's links for self-collision checks in the build kernel.

The exact check (``collision.py``: coal on the collision meshes) costs ~1 ms per configuration,
which makes a self-collision-aware map build 100x slower than one without. Here every collision
geometry is covered by a few spheres fitted to points on its surface (mesh vertices, edge
midpoints and area-weighted surface samples; box corners; cylinder rims), each grown by a
per-robot ``margin``, plus one bounding sphere per geometry for an early out. The compiled kernel
walks the arm's chain (the same ``placements``/``axes``/``kinds`` as ``fk.py``), moves the
spheres and tests only the pairs the exact model tests: the SRDF/adjacency-pruned pairs of
:class:`~baseplace.robots.collision.SelfCollision` whose relative pose changes with the arm.
Every other joint, the other arm of a dual-arm robot included, stays at the robot's reference
configuration. Sphere pairs that already overlap at the reference configuration (where the exact
model says the pair is free) are spurious contacts of the cover near shared joints and are left
out; the measured false-free rate against coal (``bench/bench_self_collision.py``,
``tests/test_spheres.py``) is what certifies the model.
"""

from __future__ import annotations

import math
from typing import Any

import numba as nb
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from baseplace.robots.collision import SelfCollision
from baseplace.robots.fk import NO_AXES, chain_frames
from baseplace.robots.model import Arm, Robot

MODEL_VERSION = "spheres-3"
"""Names the sphere model and kernel in a map's provenance (``MapInfo.self_collision_checker``)."""
DEFAULT_MARGIN = 0.005  # m, added to every sphere radius
_SURFACE_SAMPLES = 3000  # random surface points per mesh, on top of vertices and edge midpoints
_MAX_SPHERES = 8  # per geometry
_TARGET_RADIUS = 0.06  # m: parts are split until their sphere is this small
_REACH_SAMPLES = 1 << 17  # random configurations that find the sphere pairs that never meet
_REACH_MARGIN = 0.05  # m: a pair is kept if its spheres came this close in those samples
CALIBRATION_CHUNK = 1 << 14
_TABLE_MAX_JOINTS = 3  # cluster pairs whose relative pose depends on this many joints get a table
_TABLE_SLACK = 0.002  # m: a table's aim for how far a sphere moves inside one of its cells
_TABLE_MAX_CELLS = 1 << 21  # per table (256 KiB of bits)
_TABLE_MAX_DELTA = 0.004  # m: no table where the cell cap leaves more slack than this


def _surface_points(geometry: Any, rng: np.random.Generator) -> tuple[NDArray[np.float64], float]:
    """Points (P, 3) in the geometry frame and a radius every point is grown by."""
    kind = type(geometry).__name__
    if kind == "Sphere":
        return np.zeros((1, 3)), float(geometry.radius)
    if kind == "Box":
        h = np.asarray(geometry.halfSide, dtype=float)
        return np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h, 0.0
    if kind in ("Cylinder", "Capsule"):
        r, hl = float(geometry.radius), float(geometry.halfLength)
        if kind == "Capsule":
            return np.array(
                [[0.0, 0.0, -hl], [0.0, 0.0, hl]] + [[0, 0, z] for z in np.linspace(-hl, hl, 9)]
            ), r
        m = 32  # a 32-gon circumscribing the rim circle
        a = np.linspace(0.0, 2 * math.pi, m, endpoint=False)
        rr = r / math.cos(math.pi / m)
        zs = np.linspace(-hl, hl, 9)
        ring = np.stack([rr * np.cos(a), rr * np.sin(a)], axis=1)
        pts = [np.column_stack([ring, np.full(m, z)]) for z in zs]
        return np.concatenate(pts), 0.0
    if kind.startswith("BVHModel") or kind.startswith("Convex"):
        V: NDArray[np.float64] = np.asarray(geometry.vertices(), dtype=np.float64).reshape(-1, 3)
        n_tris = int(geometry.num_tris)
        tris = [geometry.tri_indices(i) for i in range(n_tris)]
        T = np.array([[t[0], t[1], t[2]] for t in tris], dtype=np.int64).reshape(-1, 3)
        if len(T) == 0:
            return V, 0.0
        A, B, C = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
        area = 0.5 * np.linalg.norm(np.cross(B - A, C - A), axis=1)
        p = area / area.sum() if area.sum() > 0 else None
        k = rng.choice(len(T), size=_SURFACE_SAMPLES, p=p)
        u, v = rng.random(_SURFACE_SAMPLES), rng.random(_SURFACE_SAMPLES)
        flip = u + v > 1
        u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
        S = A[k] + u[:, None] * (B[k] - A[k]) + v[:, None] * (C[k] - A[k])
        mids = np.concatenate([(A + B) / 2, (B + C) / 2, (C + A) / 2])
        return np.concatenate([V, mids, S]), 0.0
    raise ValueError(f"no sphere cover for collision geometry of type {kind}")


def fit_spheres(points: NDArray[np.float64], grow: float, margin: float) -> NDArray[np.float64]:
    """Spheres (k, 4) = (center xyz, radius) covering ``points`` each grown by ``grow``.

    The points are halved along their principal axis, recursively, until each part's sphere
    (about its bounding-box centre, through its farthest point) has a radius of at most
    ``_TARGET_RADIUS`` or ``_MAX_SPHERES`` spheres are reached.
    """
    parts = [points]
    done: list[NDArray[np.float64]] = []
    while parts and len(parts) + len(done) < _MAX_SPHERES:
        parts.sort(key=lambda P: -_sphere_of(P)[3])
        P = parts.pop(0)
        if _sphere_of(P)[3] <= _TARGET_RADIUS or len(P) < 2:
            done.append(P)
            continue
        X = P - P.mean(axis=0)
        _, _, Vt = np.linalg.svd(X[:: max(1, len(X) // 500)], full_matrices=False)
        s = X @ Vt[0]
        mid = (s.min() + s.max()) / 2
        lo, hi = P[s <= mid], P[s > mid]
        if len(lo) == 0 or len(hi) == 0:
            done.append(P)
            continue
        parts += [lo, hi]
    spheres = np.array([_sphere_of(P) for P in done + parts])
    spheres[:, 3] += grow + margin
    return spheres


def _sphere_of(P: NDArray[np.float64]) -> NDArray[np.float64]:
    c = (P.min(axis=0) + P.max(axis=0)) / 2
    return np.array([*c, float(np.linalg.norm(P - c, axis=1).max())])


class SphereModel:
    """The sphere cover of the geometries an arm moves and of those it can hit.

    Attributes:
        arm: the arm.
        margin: [m] added to every sphere radius.
        sphere_joint: (S,) arm joint index that moves each sphere, -1 for fixed in the base frame.
        sphere_center: (S, 3) center in that joint's frame (or the base frame) [m].
        sphere_radius: (S,) radius [m].
        geom_joint, geom_center, geom_radius: the same for one bounding sphere per geometry (G,).
        geom_pairs: (P, 2) geometry pairs checked (indices into the G geometries), the first
            geometry in the cluster with the larger bound, sorted by cluster pair then first geometry.
        sphere_pairs: (M, 2) sphere pairs checked, indices into the S spheres: the exact model's
            pairs less those that overlap where coal finds the robot free and those that never
            came within ``_REACH_MARGIN`` in ``_REACH_SAMPLES`` random configurations.
        cluster_center, cluster_radius: (n + 1, 3), (n + 1,) a bound of all spheres each arm
            joint moves (row 0: the fixed part), in that joint's frame.
        cluster_pairs: (K, 2) joint pairs (-1 the fixed part) with geometry pairs to check.
        cluster_pair_start: (K + 1,) where each cluster pair's first geometries start in
            ``first_geom``.
        first_geom, first_start: (F,), (F + 1,) each first geometry and where its pairs start in
            ``geom_pairs``.
        geom_first: (G + 1,) where each geometry's spheres start (they are contiguous).
        pair_u_start, ent_u, ent_v_start, ent_v: per geometry pair, the spheres u of its first
            geometry that are in a checked sphere pair, and for each its partners v.
        description: the model and its size, recorded in the maps it builds.
    """

    def __init__(
        self,
        robot: Robot,
        arm_name: str | None = None,
        margin: float = DEFAULT_MARGIN,
        calibration: int = 400,
        pair_tables: bool = True,
    ) -> None:
        self.robot = robot
        self.arm = arm = robot.arm(arm_name)
        self.margin = margin
        exact = SelfCollision(robot, num_threads=1)
        model, geom = exact.model, exact.geom
        q_ref = robot.q_reference
        data = model.createData()
        pin.forwardKinematics(model, data, q_ref)
        pin.updateFramePlacements(model, data)
        gdata = pin.GeometryData(geom)
        pin.updateGeometryPlacements(model, data, geom, gdata)
        base_inv = data.oMf[model.getFrameId(arm.base_frame)].inverse()
        arm_ids = [model.getJointId(j) for j in arm.joint_names]

        def group(joint: int) -> int:
            supports = set(model.supports[joint])
            return max((i for i, j in enumerate(arm_ids) if j in supports), default=-1)

        arm_geom = exact._arm_geometry_data(arm)
        pairs = [
            (int(p.first), int(p.second))
            for k, p in enumerate(geom.collisionPairs)
            if arm_geom.activeCollisionPairs[k]
        ]
        used = sorted({g for pair in pairs for g in pair})
        index = {g: i for i, g in enumerate(used)}
        rng = np.random.default_rng(0)
        s_joint: list[int] = []
        s_local: list[NDArray[np.float64]] = []
        s_rad: list[float] = []
        g_joint: list[int] = []
        g_local: list[NDArray[np.float64]] = []
        g_rad: list[float] = []
        g_spheres: list[range] = []
        for g in used:
            obj = geom.geometryObjects[g]
            pts, grow = _surface_points(obj.geometry, rng)
            pts = pts * np.asarray(obj.meshScale) if obj.meshScale is not None else pts
            sph = fit_spheres(pts, grow, margin)
            j = group(obj.parentJoint)
            frame = base_inv * data.oMi[arm_ids[j]] if j >= 0 else pin.SE3.Identity()
            T = frame.inverse() * base_inv * gdata.oMg[g]  # geometry in its moving frame
            centers = sph[:, :3] @ T.rotation.T + T.translation
            first = len(s_rad)
            for c, r in zip(centers, sph[:, 3], strict=True):
                s_joint.append(j)
                s_local.append(c)
                s_rad.append(r)
            g_spheres.append(range(first, len(s_rad)))
            # bounding sphere of the geometry's spheres
            bc = (centers.min(axis=0) + centers.max(axis=0)) / 2
            g_joint.append(j)
            g_local.append(bc)
            g_rad.append(float((np.linalg.norm(centers - bc, axis=1) + sph[:, 3]).max()))
        rad = np.array(s_rad)
        s_joint_a = np.array(s_joint, dtype=np.int64)
        s_local_a = np.array(s_local, dtype=float).reshape(-1, 3)
        candidates = np.array(
            [(i, j) for a, b in pairs for i in g_spheres[index[a]] for j in g_spheres[index[b]]],
            dtype=np.int64,
        ).reshape(-1, 2)
        # Sphere pairs that overlap where the exact model says the robot is free (at the reference
        # configuration and at calibration samples) are artefacts of the cover: hollow meshes
        # nested in each other, parts near a shared joint. They are left out.
        Qc = np.vstack(
            [arm.from_pinocchio(q_ref)[None], arm.sample(np.random.default_rng([19, 0]), calibration)]
        )
        free = ~exact.colliding_arm(arm, Qc)
        centers = np.empty((len(Qc), len(rad), 3))
        _sphere_centers(
            Qc[free], arm.placements, arm.axes, arm.kinds, s_joint_a, s_local_a, centers[: free.sum()]
        )
        spurious = np.zeros(len(candidates), dtype=bool)
        for C in centers[: free.sum()]:
            d = np.linalg.norm(C[candidates[:, 0]] - C[candidates[:, 1]], axis=1)
            spurious |= d < rad[candidates[:, 0]] + rad[candidates[:, 1]]
        # Sphere pairs that stay farther apart than ``_REACH_MARGIN`` over ``_REACH_SAMPLES``
        # random configurations cannot meet within the joint limits (up to that margin) and are
        # left out too: most pairs between the torso and the upper arm, the shoulder and the hand.
        near = candidates[~spurious]
        gap = np.full(len(near), np.inf)
        for k in range(_REACH_SAMPLES // CALIBRATION_CHUNK):
            Qr = arm.sample(np.random.default_rng([19, 1, k]), CALIBRATION_CHUNK)
            C = np.empty((len(Qr), len(rad), 3))
            _sphere_centers(Qr, arm.placements, arm.axes, arm.kinds, s_joint_a, s_local_a, C)
            _min_gap(C, near, rad, gap, nb.get_num_threads())
        ok = {(int(i), int(j)) for i, j in near[gap < _REACH_MARGIN]}
        geom_pairs: list[tuple[int, int]] = []
        kept_pairs: list[tuple[int, int]] = []
        for a, b in pairs:
            kept = [(i, j) for i in g_spheres[index[a]] for j in g_spheres[index[b]] if (i, j) in ok]
            if kept:
                geom_pairs.append((index[a], index[b]))
                kept_pairs.extend(kept)
        self.sphere_joint = np.array(s_joint, dtype=np.int64)
        self.sphere_center = np.array(s_local, dtype=float).reshape(-1, 3)
        self.sphere_radius = rad
        self.geom_joint = np.array(g_joint, dtype=np.int64)
        self.geom_center = np.array(g_local, dtype=float).reshape(-1, 3)
        self.geom_radius = np.array(g_rad, dtype=float)
        self.sphere_pairs = np.array(kept_pairs, dtype=np.int64).reshape(-1, 2)
        self.n_exact_pairs = len(pairs)
        self.geom_first = np.array([r.start for r in g_spheres] + [len(rad)], dtype=np.int64)
        self._group_pairs(np.array(geom_pairs, dtype=np.int64).reshape(-1, 2))
        self._build_tables(pair_tables)
        tables = (
            f", {len(self.table_joints)} joint-pair tables ({self.table_bits.nbytes // 1024} KiB)"
            if len(self.table_joints)
            else ", no joint-pair tables"
        )
        self.description = (
            f"{MODEL_VERSION}: {len(rad)} spheres (margin {margin} m), {len(self.sphere_pairs)} "
            f"sphere pairs in {len(self.geom_pairs)} geometry pairs{tables}"
        )

    def _group_pairs(self, gp: NDArray[np.int64]) -> None:
        """The bounding hierarchy over the geometry pairs: cluster pair, then geometry, then pair.

        A cluster is everything one arm joint moves (-1: the fixed part). Each geometry pair is
        oriented so that its first geometry is in the cluster with the larger bound (the fixed
        part before the hand): per configuration, one test of a first geometry against the other
        cluster's bound skips all of its pairs, so the 12 x 41 torso/hand geometry pairs of TIAGo
        cost a dozen tests while the hand is away from the torso.
        """
        rad, n = self.sphere_radius, self.arm.n_joints + 1
        self.cluster_center = np.zeros((n, 3))
        self.cluster_radius = np.zeros(n)
        for c in range(-1, self.arm.n_joints):
            sel = self.sphere_joint == c
            if sel.any():
                C, r = self.sphere_center[sel], rad[sel]
                bc = (C.min(axis=0) + C.max(axis=0)) / 2
                self.cluster_center[c + 1] = bc
                self.cluster_radius[c + 1] = float((np.linalg.norm(C - bc, axis=1) + r).max())
        ja, jb = self.geom_joint[gp[:, 0]] + 1, self.geom_joint[gp[:, 1]] + 1
        swap = (self.cluster_radius[jb] > self.cluster_radius[ja]) | (
            (self.cluster_radius[jb] == self.cluster_radius[ja]) & (jb < ja)
        )
        gp = np.where(swap[:, None], gp[:, ::-1], gp)
        ja, jb = np.where(swap, jb, ja), np.where(swap, ja, jb)
        order = np.lexsort((gp[:, 1], gp[:, 0], jb, ja))
        self.geom_pairs, ja, jb = gp[order], ja[order], jb[order]
        new_cluster = np.r_[True, (ja[1:] != ja[:-1]) | (jb[1:] != jb[:-1])] if len(gp) else np.zeros(0, bool)
        new_first = new_cluster | np.r_[True, self.geom_pairs[1:, 0] != self.geom_pairs[:-1, 0]][: len(gp)]
        first_at = np.flatnonzero(new_first)
        self.cluster_pairs = np.stack([ja[new_cluster] - 1, jb[new_cluster] - 1], axis=1).astype(np.int64)
        self.cluster_pair_start = np.r_[np.searchsorted(first_at, np.flatnonzero(new_cluster)), len(first_at)]
        self.cluster_pair_start = self.cluster_pair_start.astype(np.int64)
        self.first_geom = self.geom_pairs[first_at, 0].astype(np.int64)
        self.first_start = np.r_[first_at, len(gp)].astype(np.int64)
        allowed = np.zeros((len(rad), len(rad)), dtype=np.bool_)
        allowed[self.sphere_pairs[:, 0], self.sphere_pairs[:, 1]] = True
        allowed[self.sphere_pairs[:, 1], self.sphere_pairs[:, 0]] = True
        # per geometry pair, its spheres u (first geometry) that have a partner, each with its v
        pair_u_start, ent_u, ent_v_start, ent_v = [0], [], [0], []
        for a, b in self.geom_pairs:
            for u in range(self.geom_first[a], self.geom_first[a + 1]):
                vs = [v for v in range(self.geom_first[b], self.geom_first[b + 1]) if allowed[u, v]]
                if vs:
                    ent_u.append(u)
                    ent_v.extend(vs)
                    ent_v_start.append(len(ent_v))
            pair_u_start.append(len(ent_u))
        self.pair_u_start = np.array(pair_u_start, dtype=np.int64)
        self.ent_u = np.array(ent_u, dtype=np.int64)
        self.ent_v_start = np.array(ent_v_start, dtype=np.int64)
        self.ent_v = np.array(ent_v, dtype=np.int64)

    def _build_tables(self, enabled: bool) -> None:
        """Lookup tables for the cluster pairs whose relative pose depends on few joints.

        The spheres of cluster ``lo`` are rigid in joint ``lo``'s frame and those of ``hi > lo``
        in joint ``hi``'s, so their relative pose depends only on joints ``lo + 1 .. hi``. Where
        that is at most ``_TABLE_MAX_JOINTS`` joints, a bit table over those joints' limits
        (bins of half-width ``h_j``) records whether any sphere pair of the cluster pair may
        overlap in the cell: it is evaluated at the cell's centre with every radius sum grown by
        ``delta = sum_j h_j L_j``, where ``L_j`` bounds how far a sphere of cluster ``hi`` moves
        per unit of joint ``j`` (1 for a prismatic joint; for a revolute one its distance from
        the joint's axis: exact for joint ``hi``, through the joint origins for the others).
        A table is therefore conservative with respect to the spheres (it never calls a
        configuration free whose spheres overlap); it may call colliding a configuration whose
        spheres come within ``delta`` of each other. Bins are sized for ``delta`` <=
        ``_TABLE_SLACK``, fewer where a table would exceed ``_TABLE_MAX_CELLS`` cells; a table
        whose ``delta`` then exceeds ``_TABLE_MAX_DELTA`` is not made. Configurations outside a
        table's range (joint values beyond the limits) fall back to the bounding hierarchy.

        Attributes set: ``cluster_table`` (K,) table of each cluster pair or -1; per table,
        ``table_joints`` (T, 3) (-1: unused), ``table_lower`` (T, 3), ``table_scale`` (T, 3)
        bins per unit, ``table_bins`` (T, 3), ``table_start`` (T + 1,) bit offsets into
        ``table_bits`` (uint8), ``table_delta`` (T,) [m].
        """
        arm = self.arm
        K = len(self.cluster_pairs)
        self.cluster_table = np.full(K, -1, dtype=np.int64)
        joints: list[NDArray[np.int64]] = []
        bins: list[NDArray[np.int64]] = []
        lower: list[NDArray[np.float64]] = []
        scale: list[NDArray[np.float64]] = []
        start, delta = [0], []
        chunks: list[NDArray[np.uint8]] = []
        offsets = np.linalg.norm(arm.placements[:, :3, 3], axis=1)
        travel = np.where(arm.kinds == 1, np.maximum(np.abs(arm.lower), np.abs(arm.upper)), 0.0)
        for k in range(K if enabled else 0):
            lo, hi = int(self.cluster_pairs[k].min()), int(self.cluster_pairs[k].max())
            J = list(range(lo + 1, hi + 1))
            if not 1 <= len(J) <= _TABLE_MAX_JOINTS or np.any(arm.continuous[J]):
                continue
            U, V = self._cluster_sphere_pairs(k)
            down = np.unique(np.concatenate([U, V]))
            C = self.sphere_center[down[self.sphere_joint[down] == hi]]
            reach = float(np.linalg.norm(C, axis=1).max())
            ax = arm.axes[hi]
            L = [
                1.0
                if arm.kinds[j] == 1
                else float(np.linalg.norm(C - np.outer(C @ ax, ax), axis=1).max())
                if j == hi
                else reach + offsets[j + 1 : hi + 1].sum() + travel[j + 1 : hi + 1].sum()
                for j in J
            ]
            width = arm.upper[J] - arm.lower[J]
            wl = np.maximum(width * np.array(L), 1e-12)
            n = np.ceil(wl * len(J) / (2 * _TABLE_SLACK))
            if n.prod() > _TABLE_MAX_CELLS:  # equal shares of delta per joint at the cap
                n = np.ceil(wl * (_TABLE_MAX_CELLS / wl.prod()) ** (1 / len(J)) * 0.999)
            n = np.clip(n, 1, None).astype(np.int64)
            d = float((width / (2 * n) * np.array(L)).sum()) + 1e-9
            if d > _TABLE_MAX_DELTA:
                continue
            J3 = np.full(3, -1, dtype=np.int64)
            J3[: len(J)] = J
            n3 = np.ones(3, dtype=np.int64)
            n3[: len(J)] = n
            lo3, w3 = np.zeros(3), np.zeros(3)
            lo3[: len(J)], w3[: len(J)] = arm.lower[J], width / n
            bits = np.zeros((int(n3.prod()) + 7) // 8, dtype=np.uint8)
            thr2 = (self.sphere_radius[U] + self.sphere_radius[V] + d) ** 2
            _fill_table((arm.lower + arm.upper) / 2, J3, n3, lo3, w3, arm.placements, arm.axes,
                        arm.kinds, self.sphere_joint, self.sphere_center, U, V, thr2, bits)  # fmt: skip
            self.cluster_table[k] = len(joints)
            joints.append(J3)
            lower.append(lo3)
            scale.append(np.where(w3 > 0, 1 / np.where(w3 > 0, w3, 1), 0.0))
            bins.append(n3)
            chunks.append(bits)
            start.append(start[-1] + 8 * len(bits))
            delta.append(d)
        self.table_joints = np.array(joints, dtype=np.int64).reshape(-1, 3)
        self.table_lower = np.array(lower, dtype=float).reshape(-1, 3)
        self.table_scale = np.array(scale, dtype=float).reshape(-1, 3)
        self.table_bins = np.array(bins, dtype=np.int64).reshape(-1, 3)
        self.table_start = np.array(start, dtype=np.int64)
        self.table_bits = np.concatenate(chunks) if chunks else np.zeros(0, dtype=np.uint8)
        self.table_delta = np.array(delta, dtype=float)

    def _cluster_sphere_pairs(self, k: int) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        """The sphere pairs (u, v) the hierarchy checks under cluster pair ``k``."""
        U: list[int] = []
        V: list[int] = []
        for f in range(self.cluster_pair_start[k], self.cluster_pair_start[k + 1]):
            for p in range(self.first_start[f], self.first_start[f + 1]):
                for e in range(self.pair_u_start[p], self.pair_u_start[p + 1]):
                    vs = self.ent_v[self.ent_v_start[e] : self.ent_v_start[e + 1]]
                    U.extend([int(self.ent_u[e])] * len(vs))
                    V.extend(int(v) for v in vs)
        return np.array(U, dtype=np.int64), np.array(V, dtype=np.int64)

    def colliding_arm(self, arm: Arm, q_arm: ArrayLike) -> NDArray[np.bool_]:
        """Self-collision (N,) of (N, n) arm configurations by the sphere model.

        Other joints stay at their reference values; the same call as
        :meth:`SelfCollision.colliding_arm`.
        """
        if arm.name != self.arm.name:
            raise ValueError(f"sphere model is for arm {self.arm.name!r}, not {arm.name!r}")
        Q = np.ascontiguousarray(np.asarray(q_arm, dtype=float).reshape(-1, arm.n_joints))
        out = np.empty(len(Q), dtype=np.bool_)
        a = self.arm
        _colliding_batch(Q, a.placements, a.axes, a.kinds, self.sphere_joint, self.sphere_center,
                         self.sphere_radius, self.geom_joint, self.geom_center, self.geom_radius,
                         self.geom_pairs, self.cluster_center, self.cluster_radius,
                         self.cluster_pairs, self.cluster_pair_start, self.first_geom,
                         self.first_start, self.pair_u_start, self.ent_u, self.ent_v_start,
                         self.ent_v, self.cluster_table, self.table_joints, self.table_lower,
                         self.table_scale, self.table_bins, self.table_start, self.table_bits,
                         out)  # fmt: skip
        return out


@nb.njit(cache=True, inline="always")
def _joint_frames(q, placements, axes, kinds, F, R, t):
    """Frames F (n, 3, 4) of every arm joint in the base frame, after the joint's motion.

    The chain composition of ``fk.py``; R (3, 3) and t (3,) are scratch space.
    """
    chain_frames(q, placements, axes, kinds, _EYE4, R, t, NO_AXES, NO_AXES, False, F, True)


_EYE4 = np.eye(4)


@nb.njit(cache=True, inline="always")
def _place(joint, local, F, out):
    for k in range(joint.shape[0]):
        j = joint[k]
        if j < 0:
            out[k, 0], out[k, 1], out[k, 2] = local[k, 0], local[k, 1], local[k, 2]
        else:
            for a in range(3):
                out[k, a] = (
                    F[j, a, 0] * local[k, 0]
                    + F[j, a, 1] * local[k, 1]
                    + F[j, a, 2] * local[k, 2]
                    + F[j, a, 3]
                )


@nb.njit(cache=True, inline="always")
def _place_one(j, local, F, out):
    if j < 0:
        out[0], out[1], out[2] = local[0], local[1], local[2]
    else:
        for a in range(3):
            out[a] = F[j, a, 0] * local[0] + F[j, a, 1] * local[1] + F[j, a, 2] * local[2] + F[j, a, 3]


@nb.njit(cache=True, inline="always")
def _place_once(k, i, stamp, joint, local, F, out):
    """Place item k (a sphere or a geometry's bound) into ``out[k]`` for configuration i, unless it already is."""
    if stamp[k] != i:
        stamp[k] = i
        _place_one(joint[k], local[k], F, out[k])


@nb.njit(cache=True, inline="always")
def _overlap(A, a, ra, B, b, rb):
    """Whether the sphere (A[a], ra) overlaps the sphere (B[b], rb)."""
    dx, dy, dz = A[a, 0] - B[b, 0], A[a, 1] - B[b, 1], A[a, 2] - B[b, 2]
    r = ra + rb
    return dx * dx + dy * dy + dz * dz < r * r


@nb.njit(cache=True, parallel=True)
def _colliding_batch(Q, placements, axes, kinds, s_joint, s_local, s_rad, g_joint, g_local, g_rad,
                     geom_pairs, cl_local, cl_rad, cl_pairs, cl_start, first_geom, first_start,
                     pair_u_start, ent_u, ent_v_start, ent_v, cl_table, t_joints, t_lower, t_scale,
                     t_bins, t_start, t_bits, out):  # fmt: skip
    """Self-collision of each configuration by the sphere model, in blocks of 256 per thread.

    Per configuration, first the joint-pair tables (before any kinematics: a hit ends the
    configuration), then for the other cluster pairs (and tabled ones whose joints are out of
    the table's range) down the bounding hierarchy: cluster pair bounds; each first geometry
    against the other cluster's bound; geometry pair bounds; each sphere of the first geometry
    against the second geometry's bound; its sphere pairs. A sphere is placed when it is first
    needed; the first overlapping sphere pair ends the configuration.
    """
    n_block = 256
    n_blocks = (Q.shape[0] + n_block - 1) // n_block
    for blk in nb.prange(n_blocks):
        F = np.empty((Q.shape[1], 3, 4))
        gc = np.empty((g_joint.shape[0], 3))
        sc = np.empty((s_joint.shape[0], 3))
        placed = np.full(s_joint.shape[0], -1, dtype=np.int64)
        g_placed = np.full(g_joint.shape[0], -1, dtype=np.int64)
        cc = np.empty((cl_rad.shape[0], 3))
        R, t = np.empty((3, 3)), np.empty(3)
        in_table = np.zeros(t_joints.shape[0], dtype=np.bool_)
        for i in range(blk * n_block, min(Q.shape[0], (blk + 1) * n_block)):
            hit = False
            for tb in range(t_joints.shape[0]):
                idx = 0
                in_table[tb] = True
                for d in range(3):
                    j, n = t_joints[tb, d], t_bins[tb, d]
                    c = 0
                    if j >= 0:
                        x = (Q[i, j] - t_lower[tb, d]) * t_scale[tb, d]
                        if not 0.0 <= x <= n:
                            in_table[tb] = False
                            break
                        c = min(int(x), n - 1)
                    idx = idx * n + c
                if in_table[tb]:
                    idx += t_start[tb]
                    if (t_bits[idx >> 3] >> (idx & 7)) & 1:
                        hit = True
                        break
            if hit:
                out[i] = True
                continue
            _joint_frames(Q[i], placements, axes, kinds, F, R, t)
            for c in range(cl_rad.shape[0]):
                _place_one(c - 1, cl_local[c], F, cc[c])
            for k in range(cl_pairs.shape[0]):
                if cl_table[k] >= 0 and in_table[cl_table[k]]:
                    continue
                ca, cb = cl_pairs[k, 0] + 1, cl_pairs[k, 1] + 1
                if not _overlap(cc, ca, cl_rad[ca], cc, cb, cl_rad[cb]):
                    continue
                for f in range(cl_start[k], cl_start[k + 1]):
                    a = first_geom[f]
                    _place_once(a, i, g_placed, g_joint, g_local, F, gc)
                    if not _overlap(gc, a, g_rad[a], cc, cb, cl_rad[cb]):
                        continue
                    for p in range(first_start[f], first_start[f + 1]):
                        b = geom_pairs[p, 1]
                        _place_once(b, i, g_placed, g_joint, g_local, F, gc)
                        if not _overlap(gc, a, g_rad[a], gc, b, g_rad[b]):
                            continue
                        for e in range(pair_u_start[p], pair_u_start[p + 1]):
                            u = ent_u[e]
                            _place_once(u, i, placed, s_joint, s_local, F, sc)
                            if not _overlap(sc, u, s_rad[u], gc, b, g_rad[b]):
                                continue
                            for w in range(ent_v_start[e], ent_v_start[e + 1]):
                                v = ent_v[w]
                                _place_once(v, i, placed, s_joint, s_local, F, sc)
                                if _overlap(sc, u, s_rad[u], sc, v, s_rad[v]):
                                    hit = True
                                    break
                            if hit:
                                break
                        if hit:
                            break
                    if hit:
                        break
                if hit:
                    break
            out[i] = hit


@nb.njit(cache=True, parallel=True)
def _fill_table(q0, J, n, lo, w, placements, axes, kinds, s_joint, s_local, U, V, thr2, bits):
    """Set bit ``(a n1 + b) n2 + c`` of ``bits`` where a sphere pair (U, V) comes within ``thr2``.

    ``thr2`` holds squared distances. Cell (a, b, c) is evaluated at its centre: joint ``J[0]``
    at ``lo[0] + (a + 1/2) w[0]`` and likewise ``J[1]``, ``J[2]`` where they are >= 0 (``n`` is 1
    for an unused one); every other joint at ``q0`` (the pair's relative pose does not depend on
    them). Cells run in parallel into a boolean grid, packed into ``bits`` afterwards.
    """
    total = n[0] * n[1] * n[2]
    hits = np.zeros(total, dtype=np.bool_)
    for cell in nb.prange(total):
        q = q0.copy()
        c2 = cell % n[2]
        c1 = (cell // n[2]) % n[1]
        c0 = cell // (n[2] * n[1])
        q[J[0]] = lo[0] + (c0 + 0.5) * w[0]
        if J[1] >= 0:
            q[J[1]] = lo[1] + (c1 + 0.5) * w[1]
        if J[2] >= 0:
            q[J[2]] = lo[2] + (c2 + 0.5) * w[2]
        F = np.empty((q.shape[0], 3, 4))
        R, t = np.empty((3, 3)), np.empty(3)
        cu, cv = np.empty(3), np.empty(3)
        _joint_frames(q, placements, axes, kinds, F, R, t)
        for p in range(U.shape[0]):
            _place_one(s_joint[U[p]], s_local[U[p]], F, cu)
            _place_one(s_joint[V[p]], s_local[V[p]], F, cv)
            dx, dy, dz = cu[0] - cv[0], cu[1] - cv[1], cu[2] - cv[2]
            if dx * dx + dy * dy + dz * dz < thr2[p]:
                hits[cell] = True
                break
    for idx in range(total):
        if hits[idx]:
            bits[idx >> 3] |= np.uint8(1 << (idx & 7))


@nb.njit(cache=True, parallel=True)
def _sphere_centers(Q, placements, axes, kinds, s_joint, s_local, out):
    """Sphere centres (N, S, 3) in the base frame for (N, n) configurations."""
    for i in nb.prange(Q.shape[0]):
        F = np.empty((Q.shape[1], 3, 4))
        R, t = np.empty((3, 3)), np.empty(3)
        _joint_frames(Q[i], placements, axes, kinds, F, R, t)
        _place(s_joint, s_local, F, out[i])


@nb.njit(cache=True, parallel=True)
def _min_gap(C, pairs, rad, gap, n_threads):
    """Lower ``gap`` (P,) to the smallest surface distance of each sphere pair over centres C.

    Each of ``n_threads`` blocks of configurations keeps its own smallest squared centre
    distances, so that one configuration's centres stay in cache while all pairs are measured (a
    loop over pairs outside read C with a stride of a whole configuration, ~6 s per 16 k
    configurations); the result is the same whatever the order, the square root being monotone.
    """
    n, n_pairs = C.shape[0], pairs.shape[0]
    block = (n + n_threads - 1) // n_threads
    local = np.full((n_threads, n_pairs), np.inf)
    for t in nb.prange(n_threads):
        m = local[t]
        for i in range(t * block, min(n, (t + 1) * block)):
            Ci = C[i]
            for p in range(n_pairs):
                u, v = pairs[p, 0], pairs[p, 1]
                dx, dy, dz = Ci[u, 0] - Ci[v, 0], Ci[u, 1] - Ci[v, 1], Ci[u, 2] - Ci[v, 2]
                d2 = dx * dx + dy * dy + dz * dz
                if d2 < m[p]:
                    m[p] = d2
    for p in range(n_pairs):
        d2 = local[0, p]
        for t in range(1, n_threads):
            d2 = min(d2, local[t, p])
        d = math.sqrt(d2) - rad[pairs[p, 0]] - rad[pairs[p, 1]]
        if d < gap[p]:
            gap[p] = d
