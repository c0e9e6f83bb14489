"""Which grasps the true geometry allows at a clearance: the oracle of protocol v2 (issue 27).

Seed 000's ground truth (:class:`~baseplace_experiments.osrm_experiment.GroundTruth`) counts a grasp
when IK reaches it from a valid base pose and does not check the arm's collisions. A grasp counted
that way may be impossible for any robot that keeps a clearance: the arm would pass through the tray
rim, or the open hand lies 2 mm from a neighbour. :class:`AllowedGrasps` asks the stricter question
on the true shapes (coal on the tray, the objects, the planes and the floor; never the voxels or
points the method sees): is there a valid base pose and an IK solution from it whose whole robot,
base, arm and hand,

* keeps ``clearance`` from every true solid (coal's security margin: a distance below it is a
  contact), the grasped object included for every link outside the hand;
* has no self-collision;
* touches the grasped object only with the hand; the hand's rigid part (the geometries on the arm's
  last joint: tool link, wrist sensor, palm) no deeper than ``grasp_depth`` (checked against the
  object shrunk by ``grasp_depth`` on every face, with no margin). The fingers are not checked
  against the grasped object: the collision model has them open (the reference configuration), and
  open Hey5 fingers at v1's top-down grasps pass through the object (measured on a 6 cm bottle,
  grasp point 3 cm below its top: the middle finger 57 mm deep, the ring finger 20 mm); they close
  on it. :data:`ENVELOPES` are not parts of the hand;
* stands on its plane: the base's own links (those no arm joint moves) may touch the floor and the
  plane under the base, nothing else; the arm's links keep the clearance from those too.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence
from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from baseplace.errors import InputError
from baseplace.geometry.poses import FloatArray, invert_transforms, pose_from_xyz_rpy
from baseplace.robots.ik import DampedLeastSquaresIK
from baseplace.sim.scenes import Plane, Scene, SceneObject
from baseplace_experiments.table_grid import RobotShapes, TrueShape

CLEARANCE = 0.01
"""The clearance [m] of protocol v2, for the oracle and the method alike: the product's clearance
when no noise can be measured (``DEFAULT_CLEARANCE``, 3 sigma of 3 mm sensor noise rounded up)."""
GRASP_DEPTH = 0.005
"""How far [m] the hand may go into the grasped object (its surface compressed, a finger's pad)."""
ENVELOPES = ("hand_safety_box",)
"""Hand geometries that are envelopes, not parts (TIAGo's box around the open fingers): never checked
against the grasped object, which they always contain."""
SOLUTIONS = 3
"""IK solves per base pose (the first from mid-range, the others from one random start each, then
random restarts), each solution checked on the true shapes."""


def plane_solid(plane: Plane) -> TrueShape:
    """A support plane as a solid: its footprint prism from z = 0 up to its top (coal convex hull)."""
    corners = plane.polygon
    top = plane.z(corners)
    vertices = coal.StdVec_Vec3s()
    for (x, y), z in zip(corners, top, strict=True):
        vertices.append(np.array([x, y, 0.0]))
        vertices.append(np.array([x, y, max(float(z), 1e-4)]))
    return TrueShape(f"plane {plane.id}", coal.Convex.convexHull(vertices, False, ""), np.eye(4))


FLOOR = TrueShape("floor", coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.0), np.eye(4))
"""The floor: the half-space z <= 0."""


def object_solid(obj: SceneObject, name: str, shrink: float = 0.0) -> TrueShape:
    """A scene object as a coal shape, each face moved ``shrink`` [m] inwards."""
    w, d, h = (max(v - 2 * shrink, 1e-4) for v in obj.size)
    shape = coal.Cylinder(w / 2, h) if obj.shape == "cylinder" else coal.Box(w, d, h)
    return TrueShape(name, shape, pose_from_xyz_rpy([*obj.center, 0.0, 0.0, obj.yaw]))


def tray_solids(scene: Scene) -> list[TrueShape]:
    """The tray's pedestal with its bottom, and its four walls (as the scene's cloud samples them)."""
    box = scene.box
    if box is None:
        return []
    L, W, h = box.size
    e, t = box.elevation, box.wall
    c, s = math.cos(box.yaw), math.sin(box.yaw)

    def part(name: str, size: tuple[float, float, float], x: float, y: float, z: float) -> TrueShape:
        xy = (box.center[0] + c * x - s * y, box.center[1] + s * x + c * y)
        return TrueShape(name, coal.Box(*size), pose_from_xyz_rpy([*xy, z, 0.0, 0.0, box.yaw]))

    return [
        part("tray pedestal", (L, W, e + t), 0, 0, (e + t) / 2),
        part("tray wall +x", (t, W, h), L / 2 - t / 2, 0, e + h / 2),
        part("tray wall -x", (t, W, h), -L / 2 + t / 2, 0, e + h / 2),
        part("tray wall +y", (L, t, h), 0, W / 2 - t / 2, e + h / 2),
        part("tray wall -y", (L, t, h), 0, -W / 2 + t / 2, e + h / 2),
    ]


@dataclass(frozen=True)
class Contact:
    """What a robot configuration touches on the true scene: ``link - shape``."""

    link: str
    shape: str

    def __str__(self) -> str:
        return f"{self.link} - {self.shape}"


def scene_solids(
    scene: Scene, grasped_index: int, under: int, grasp_depth: float = GRASP_DEPTH
) -> tuple[list[TrueShape], list[TrueShape], TrueShape, TrueShape]:
    """The true scene as :meth:`AllowedGrasps.touching` takes it, for a base standing on plane ``under``.

    Returns:
        obstacles (the tray, the other objects, the planes but ``under``), supports (the floor and
        plane ``under``), the grasped object, and the grasped object shrunk by ``grasp_depth``.
    """
    planes = {p.id: plane_solid(p) for p in scene.planes[1:]}
    obstacles = tray_solids(scene)
    obstacles += [object_solid(o, f"object {i}") for i, o in enumerate(scene.objects) if i != grasped_index]
    obstacles += [solid for pid, solid in planes.items() if pid != under]
    supports = [FLOOR] + ([planes[under]] if under in planes else [])
    obj = scene.objects[grasped_index]
    inner = object_solid(obj, "grasped object (beyond the grasp depth)", grasp_depth)
    return obstacles, supports, object_solid(obj, "grasped object"), inner


class AllowedGrasps:
    """The oracle (module docstring): a grasp is allowed if some valid base pose has a clear IK solution.

    Args:
        shapes: the robot's own geometry model (pinocchio + coal, built once per robot).
        clearance: [m] kept from every true solid.
        grasp_depth: [m] the hand may go into the grasped object.
        solutions: IK solutions tried per base pose.
        restarts: IK restarts per solution.
    """

    def __init__(self, shapes: RobotShapes, clearance: float = CLEARANCE, grasp_depth: float = GRASP_DEPTH,
                 solutions: int = SOLUTIONS, restarts: int = 4) -> None:  # fmt: skip
        for name, value in (("clearance", clearance), ("grasp_depth", grasp_depth)):
            if not (math.isfinite(value) and value >= 0):
                raise InputError(f"{name} must be a finite distance >= 0 [m], got {value}")
        if solutions < 1:
            raise InputError(f"solutions must be >= 1, got {solutions}")
        self.shapes = shapes
        self.clearance = clearance
        self.grasp_depth = grasp_depth
        self.solutions = solutions
        self.ik = DampedLeastSquaresIK(shapes.arm, restarts=restarts)
        model = shapes.model
        arm_joints = {model.getJointId(n) for n in shapes.arm.joint_names}
        self.base_links = {k for k, obj in enumerate(shapes.geom.geometryObjects)
                           if not arm_joints & set(model.supports[obj.parentJoint])}  # fmt: skip
        last = model.getJointId(shapes.arm.joint_names[-1])
        self.rigid_hand = {k for k in shapes.hand if shapes.geom.geometryObjects[k].parentJoint == last
                           and not shapes.geom.geometryObjects[k].name.startswith(ENVELOPES)}  # fmt: skip
        ref = model.createData()
        pin.framesForwardKinematics(model, ref, shapes.robot.q_reference)
        self._margin = coal.CollisionRequest()
        self._margin.security_margin = clearance
        self._touch = coal.CollisionRequest()
        # the rigid hand's geometries with their poses (4, 4) in the TCP frame (they move with it)
        T_ref_tcp = ref.oMf[model.getFrameId(shapes.arm.tcp_frame)].inverse()
        gdata = pin.GeometryData(shapes.geom)
        pin.updateGeometryPlacements(model, ref, shapes.geom, gdata, shapes.robot.q_reference)
        self.rigid_parts = [(shapes.geom.geometryObjects[k].geometry, (T_ref_tcp * gdata.oMg[k]).homogeneous)
                            for k in sorted(self.rigid_hand)]  # fmt: skip

    def with_clearance(self, clearance: float) -> AllowedGrasps:
        """This oracle keeping ``clearance`` [m] instead (the same robot model, IK and grasp depth)."""
        if not (math.isfinite(clearance) and clearance >= 0):
            raise InputError(f"clearance must be a finite distance >= 0 [m], got {clearance}")
        other = copy.copy(self)
        other.clearance = clearance
        other._margin = coal.CollisionRequest()
        other._margin.security_margin = clearance
        return other

    def touching(self, q_arm: ArrayLike, T_world_base: ArrayLike, obstacles: Sequence[TrueShape],
                 supports: Sequence[TrueShape], grasped: TrueShape, grasped_inner: TrueShape) -> Contact | None:  # fmt: skip
        """The first contact of the robot at arm joints (n,) and base pose (4, 4), None when clear.

        ``obstacles`` keep the clearance from every link; ``supports`` (the floor, the plane under the
        base) from every link but the base's; ``grasped`` from every link but the hand's, and the
        hand's rigid part must not meet ``grasped_inner`` (the object shrunk by the grasp depth).
        """
        s = self.shapes
        q = s.arm.to_pinocchio(np.asarray(q_arm, dtype=float), s.robot.q_reference)
        if s.self_collision.colliding_arm(s.arm, np.asarray(q_arm, dtype=float))[0]:
            return Contact("self", "self")
        pin.updateGeometryPlacements(s.model, s.data, s.geom, s.geom_data, q)
        T_world_root = np.asarray(T_world_base, dtype=float) @ s.T_base_root
        for k, obj in enumerate(s.geom.geometryObjects):
            T = T_world_root @ s.geom_data.oMg[k].homogeneous
            T_geom = coal.Transform3s(T[:3, :3], T[:3, 3])
            checks = [(shape, self._margin) for shape in obstacles]
            if k not in self.base_links:
                checks += [(shape, self._margin) for shape in supports]
            if k not in s.hand:
                checks.append((grasped, self._margin))
            elif k in self.rigid_hand:
                checks.append((grasped_inner, self._touch))
            for shape, request in checks:
                if coal.collide(obj.geometry, T_geom, shape.geometry, shape.transform(), request,
                                coal.CollisionResult()):  # fmt: skip
                    return Contact(obj.name, shape.name)
        return None

    def allowed(self, scene: Scene, grasp: FloatArray, grasped_index: int, T_world_base: FloatArray,
                plane_ids: ArrayLike, rng: np.random.Generator) -> bool:  # fmt: skip
        """True if the robot at one of the base poses (P, 4, 4) grasps ``grasp`` (4, 4) clear of the true scene.

        Args:
            scene: the true scene.
            grasp: world TCP pose of the grasp.
            grasped_index: index of the grasped object in ``scene.objects``.
            T_world_base: candidate base poses, tried in order (the ground truth's grid).
            plane_ids: (P,) the plane each pose stands on (its support with the floor).
            rng: random generator for the IK starts.
        """
        ids = np.asarray(plane_ids, dtype=int)
        by_plane = {
            int(pid): scene_solids(scene, grasped_index, int(pid), self.grasp_depth) for pid in np.unique(ids)
        }
        arm = self.shapes.arm
        for lo in range(0, len(T_world_base), 48):
            chunk = T_world_base[lo : lo + 48]
            T_base_tcp = invert_transforms(chunk) @ grasp
            for r in range(self.solutions):  # the first from mid-range, the others from random starts
                q_seed = None if r == 0 else rng.uniform(arm.lower, arm.upper)
                q, ok = self.ik.solve_batch(T_base_tcp, rng, q_seed)
                for j in np.flatnonzero(ok):
                    n = lo + int(j)
                    if self.touching(q[j], T_world_base[n], *by_plane[int(ids[n])]) is None:
                        return True
        return False


APPROACH_LIMIT = 0.15
"""How far [m] planner v2 moves a draw back along its approach axis at most (then it is turned down)."""
APPROACH_TOLERANCE = 0.0005
"""The bisection's resolution [m] on the standoff: the rigid hand ends within it of the object's surface."""


class ContactApproach:
    """Grasp planner v2's approach: a draw moved back along its approach axis until the palm meets the object.

    A top-down draw of v1's planner puts its grasp point 1-3 cm below the object's top; TIAGo's TCP
    sits about at the palm's face, so the rigid hand (the oracle's: tool link, wrist sensor, palm)
    is buried in the object. Planner v2 moves each draw back along its approach (x) axis by the
    smallest standoff in [0, ``limit``] at which the rigid hand does not meet the grasped object's
    true shape (coal, no margin; bisection to ``tolerance``): the hand approaches until its palm
    touches the object, a contact grasp whose depth (0) leaves the oracle's grasp depth for IK error.
    A draw the rigid hand already clears keeps standoff 0; one still in the object ``limit`` back is
    turned down. Only the true shapes are used, never the method's cloud or voxels.

    Args:
        oracle: gives the rigid hand (:attr:`AllowedGrasps.rigid_parts`).
        scene: the true scene; the grasped object is ``scene.objects[i]`` of each call.
        limit: [m] the largest standoff.
        tolerance: [m] the bisection's resolution.
    """

    def __init__(self, oracle: AllowedGrasps, scene: Scene, limit: float = APPROACH_LIMIT,
                 tolerance: float = APPROACH_TOLERANCE) -> None:  # fmt: skip
        if not (0 < tolerance < limit):
            raise InputError(f"need 0 < tolerance < limit, got {tolerance}, {limit}")
        self.parts = oracle.rigid_parts
        self.solids = [object_solid(o, f"object {i}") for i, o in enumerate(scene.objects)]
        self.limit = limit
        self.tolerance = tolerance
        self.calls = 0
        """coal collision calls made so far (for the protocol's cost)."""

    def meets(self, T_world_tcp: FloatArray, i: int) -> bool:
        """True if the rigid hand at ``T_world_tcp`` (4, 4) meets object ``i``'s true shape (no margin)."""
        solid = self.solids[i]
        for geometry, T_tcp_geom in self.parts:
            T = T_world_tcp @ T_tcp_geom
            self.calls += 1
            if coal.collide(geometry, coal.Transform3s(T[:3, :3], T[:3, 3]), solid.geometry, solid.transform(),
                            coal.CollisionRequest(), coal.CollisionResult()):  # fmt: skip
                return True
        return False

    def __call__(self, T_world_tcp: FloatArray, i: int) -> tuple[FloatArray, float] | None:
        """The draw (4, 4) on object ``i`` moved back to contact, and its standoff [m]; None: turned down."""

        def back(d: float) -> FloatArray:
            T = np.array(T_world_tcp, dtype=float)
            T[:3, 3] -= d * T[:3, 0]
            return T

        if not self.meets(back(0.0), i):
            return back(0.0), 0.0
        if self.meets(back(self.limit), i):
            return None
        lo, hi = 0.0, self.limit  # meets at lo, clear at hi
        while hi - lo > self.tolerance:
            mid = (lo + hi) / 2
            lo, hi = (mid, hi) if self.meets(back(mid), i) else (lo, mid)
        return back(hi), hi


__all__ = [
    "APPROACH_LIMIT",
    "APPROACH_TOLERANCE",
    "CLEARANCE",
    "ENVELOPES",
    "FLOOR",
    "GRASP_DEPTH",
    "SOLUTIONS",
    "AllowedGrasps",
    "Contact",
    "ContactApproach",
    "object_solid",
    "plane_solid",
    "scene_solids",
    "tray_solids",
]  # fmt: skip
