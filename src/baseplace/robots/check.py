"""What a robot file describes, and where it looks wrong: the library side of ``baseplace robot check``.

:func:`check_robot` loads a robot (built-in or from a TOML/YAML file) and reports its arms, joints,
limits, TCP frames and approach axes, footprint and self-collision pairs, with warnings for the
mistakes that otherwise show up only as poor or empty results:

* a TCP approach axis that does not point out of the hand: the axis should point away from the
  wrist (the last moving joint of the arm) towards the TCP; an axis more than 45 degrees off that
  direction is flagged, with the axis that fits (a UR ``tool0`` or Panda's ``panda_hand_tcp``
  approaches along z, TIAGo's ``arm_tool_link`` along x);
* a link of an arm's chain or hand with visual geometry but no collision geometry (invisible to
  every collision check; the report lists all such links, of the base and head too);
* a footprint that does not contain the base's collision meshes, or a base frame above the floor
  (geometry of the base below z = 0);
* visual meshes that cannot be found, and a reference configuration outside the joint limits or
  in self-collision (naming the touching link pairs, with the SRDF lines that disable them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from xml.etree import ElementTree
from xml.sax.saxutils import quoteattr

import coal
import numpy as np
import pinocchio as pin
import shapely
import trimesh

from baseplace.geometry.poses import FloatArray
from baseplace.robots.collision import Contact, SelfCollision
from baseplace.robots.model import PRISMATIC, Robot
from baseplace.robots.spec import APPROACH_AXES, RobotSpec

APPROACH_TOLERANCE = math.radians(45)
"""Largest angle between a TCP's approach axis and the wrist -> TCP direction before a warning."""
WRIST_OFFSET_MIN = 0.02
"""Below this wrist -> TCP distance [m] the hand's collision geometry gives the direction instead."""
FOOTPRINT_TOLERANCE = 0.02
"""How far [m] the base's collision geometry may stick out of the footprint before a warning."""


@dataclass(frozen=True)
class CollisionMesh:
    """One collision geometry of the robot as a triangle mesh in the base frame.

    Attributes:
        name: pinocchio's geometry name (link name and index).
        link: the URDF link (frame) it belongs to.
        on_arm: True where an arm joint moves it (else it is part of the base).
        vertices: (V, 3) in the base frame [m].
        faces: (F, 3) vertex indices.
    """

    name: str
    link: str
    on_arm: bool
    vertices: FloatArray
    faces: np.ndarray


def _local_mesh(obj: pin.GeometryObject) -> trimesh.Trimesh | None:
    """The geometry of a pinocchio GeometryObject as a trimesh in its own frame (None: unsupported)."""
    geom = obj.geometry
    kind = geom.getNodeType()
    if kind == coal.NODE_TYPE.GEOM_BOX:
        return trimesh.creation.box(extents=2.0 * np.asarray(geom.halfSide))
    if kind == coal.NODE_TYPE.GEOM_CYLINDER:
        return trimesh.creation.cylinder(radius=geom.radius, height=2.0 * geom.halfLength, sections=32)
    if kind == coal.NODE_TYPE.GEOM_SPHERE:
        return trimesh.creation.icosphere(subdivisions=2, radius=geom.radius)
    if kind == coal.NODE_TYPE.GEOM_CAPSULE:
        return trimesh.creation.capsule(height=2.0 * geom.halfLength, radius=geom.radius)
    path = Path(obj.meshPath)
    if path.is_file():
        try:
            mesh = trimesh.load(path, force="mesh")
        except Exception:  # trimesh raises many types on odd files; the collision model loaded it
            return None
        if isinstance(mesh, trimesh.Trimesh) and len(mesh.faces):
            mesh.apply_scale(np.asarray(obj.meshScale, dtype=float))
            return mesh
    return None


def collision_meshes(robot: Robot, geom: pin.GeometryModel, q_full: Any | None = None) -> list[CollisionMesh]:
    """Every collision geometry as a mesh in the base frame at ``q_full`` (default: the reference)."""
    q = robot.q_reference if q_full is None else np.asarray(q_full, dtype=float)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    geom_data = pin.GeometryData(geom)
    pin.updateGeometryPlacements(robot.model, data, geom, geom_data, q)
    T_base_root = data.oMf[robot.model.getFrameId(robot.spec.base_frame)].inverse()
    arm_joints = {robot.model.getJointId(j) for name in robot.spec.arms for j in robot.arm(name).joint_names}
    out = []
    for i, obj in enumerate(geom.geometryObjects):
        mesh = _local_mesh(obj)
        if mesh is None:
            continue
        T = (T_base_root * geom_data.oMg[i]).homogeneous
        vertices = np.asarray(mesh.vertices) @ T[:3, :3].T + T[:3, 3]
        on_arm = bool(set(robot.model.supports[obj.parentJoint]) & arm_joints)
        link = robot.model.frames[obj.parentFrame].name
        out.append(CollisionMesh(obj.name, link, on_arm, vertices, np.asarray(mesh.faces)))
    return out


@dataclass
class RobotReport:
    """What ``robot check`` found: plain data, printed or written as JSON by the CLI."""

    name: str
    urdf: str
    base_frame: str
    mount: dict[str, Any] | None
    footprint: dict[str, Any]
    arms: dict[str, dict[str, Any]]
    collision: dict[str, Any]
    package_dirs: list[str]
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict[str, Any]:
        """The report as JSON-ready data."""
        return dict(self.__dict__)


def _best_axis(direction: FloatArray, R_dir_tcp: FloatArray) -> tuple[str, float]:
    """The TCP axis name closest to ``direction`` (given in the frame R_dir_tcp maps TCP axes into)."""
    scores = {name: float((R_dir_tcp @ np.asarray(v)) @ direction) for name, v in APPROACH_AXES.items()}
    best = max(scores, key=lambda k: scores[k])
    return best, scores[best]


def approach_warning(robot: Robot, arm_name: str, meshes: list[CollisionMesh]) -> str | None:
    """A warning where the arm's approach axis does not point out of the hand, else None.

    The hand's outward direction is wrist -> TCP: from the origin of the arm's last moving joint
    to the TCP. When the TCP sits on the wrist (closer than :data:`WRIST_OFFSET_MIN`), it is the
    direction from the TCP to the centre of the geometry the last joint carries (the hand, which
    lies ahead of the wrist).
    """
    arm = robot.arm(arm_name)
    spec = robot.spec.arm(arm_name)
    T = arm.T_last_tcp  # the TCP in the frame of the last moving joint, whatever the configuration
    direction, R = T[:3, 3].copy(), T[:3, :3]
    if np.linalg.norm(direction) < WRIST_OFFSET_MIN:
        data = robot.model.createData()
        pin.framesForwardKinematics(robot.model, data, robot.q_reference)
        T_base_tcp = (
            data.oMf[robot.model.getFrameId(robot.spec.base_frame)].inverse()
            * data.oMf[robot.model.getFrameId(arm.tcp_frame)]
        ).homogeneous
        last = robot.model.getJointId(arm.joint_names[-1])
        hand = [m.vertices for m in meshes if last in set(robot.model.supports[_parent_joint(robot, m.link)])]
        if not hand:
            return None
        direction = np.concatenate(hand).mean(axis=0) - T_base_tcp[:3, 3]  # the hand lies ahead of the wrist
        R = T_base_tcp[:3, :3]
        if np.linalg.norm(direction) < WRIST_OFFSET_MIN:
            return None
    direction /= np.linalg.norm(direction)
    cos = float((R @ arm.approach_axis) @ direction)
    if cos >= math.cos(APPROACH_TOLERANCE):
        return None
    best, best_cos = _best_axis(direction, R)
    angle = math.degrees(math.acos(max(-1.0, min(1.0, cos))))
    into = "points back into the hand" if cos < -0.5 else "does not point out of the hand"
    suggestion = (
        f'; the TCP axis pointing out of the hand is {best}: set approach = "{best}"'
        if best_cos > 0.7
        else ""
    )
    return (
        f"arm {arm_name!r}: TCP {spec.tcp_frame!r} approach axis {spec.approach} {into} "
        f"({angle:.0f} deg off the direction out of the hand, wrist -> TCP){suggestion}"
    )


def _parent_joint(robot: Robot, frame: str) -> int:
    return int(robot.model.frames[robot.model.getFrameId(frame)].parentJoint)


def _on_an_arm(robot: Robot, frame: str) -> bool:
    """True for a link of an arm's chain (base to TCP) or of its hand (after its last joint)."""
    joint = _parent_joint(robot, frame)
    for name in robot.spec.arms:
        arm = robot.arm(name)
        chain = set(robot.model.supports[_parent_joint(robot, arm.tcp_frame)])
        last = robot.model.getJointId(arm.joint_names[-1])
        if (joint in chain and joint != 0) or last in set(robot.model.supports[joint]):
            return True
    return False


def _links_without_collision(urdf_xml: str) -> list[str]:
    root = ElementTree.fromstring(urdf_xml)
    return [
        link.get("name", "")
        for link in root.findall("link")
        if link.find("visual") is not None and link.find("collision") is None
    ]


def _footprint_overhang(spec: RobotSpec, points: FloatArray) -> tuple[float, int]:
    """Largest distance [m] of (N, 2) points outside the footprint, and the index of that point."""
    if spec.footprint_radius is not None:
        d = np.hypot(points[:, 0], points[:, 1]) - spec.footprint_radius
    else:
        assert spec.footprint_polygon is not None
        poly = shapely.Polygon(spec.footprint_polygon)
        pts = shapely.points(points)
        d = np.where(shapely.contains(poly, pts), 0.0, shapely.distance(poly, pts))
    i = int(np.argmax(d))
    return float(d[i]), i


def disable_collisions_lines(contacts: list[Contact], active: list[tuple[str, str, bool]]) -> list[str]:
    """SRDF lines, ready to paste, that disable the link pairs of ``contacts`` (empty: none touch).

    The pairs touching at the reference configuration come first ("Adjacent" where their links are
    joined by one joint, else "Default", MoveIt's reason for pairs in collision at the default
    pose), then the other ``active`` (link, link, adjacent) pairs of adjacent links, which MoveIt's
    setup assistant disables too.
    """
    if not contacts:
        return []
    touching = [(c.link1, c.link2, "Adjacent" if c.adjacent else "Default") for c in contacts]
    lines, done = [], set()
    for a, b, reason in touching + [(a, b, "Adjacent") for a, b, adjacent in active if adjacent]:
        if frozenset((a, b)) not in done:
            done.add(frozenset((a, b)))
            lines.append(
                f"<disable_collisions link1={quoteattr(a)} link2={quoteattr(b)} reason={quoteattr(reason)}/>"
            )
    return lines


def self_collision_warning(contacts: list[Contact], base_body: str | None = None) -> str:
    """The warning naming each link pair that touches at the reference configuration, and the fix.

    ``base_body``: the link a mount generates (the base's collision body), whose height is a fix too.
    Only a robot with an SRDF gets here: without one, pairs touching at the reference are pruned.
    """
    deepest: dict[tuple[str, str], float | None] = {}
    for c in contacts:
        key = (c.link1, c.link2)
        deepest[key] = c.depth if deepest.get(key) is None else max(c.depth or 0.0, deepest[key] or 0.0)
    named = ", ".join(
        f"{a} - {b}" + ("" if d is None else f" ({d * 1e3:.2f} mm deep)") for (a, b), d in deepest.items()
    )
    touches_base = base_body is not None and any(base_body in (c.link1, c.link2) for c in contacts)
    return (
        f"the reference configuration is in self-collision: {named}; disable these pairs in the robot's "
        "SRDF (the <disable_collisions> lines below, collision.srdf_fix in --json) or set another "
        "reference configuration under [reference]" + ("; or lower mount.base_height" if touches_base else "")
    )


def check_robot(robot: Robot) -> RobotReport:
    """Describe ``robot`` and warn where its robot file looks wrong (see the module docstring)."""
    spec = robot.spec
    selfcol = SelfCollision(robot)
    geom = selfcol.geom
    meshes = collision_meshes(robot, geom)
    warnings: list[str] = []

    arms: dict[str, dict[str, Any]] = {}
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, robot.q_reference)
    T_root_base = data.oMf[robot.model.getFrameId(spec.base_frame)]
    for name in spec.arms:
        arm, arm_spec = robot.arm(name), spec.arm(name)
        T_base_tcp = (T_root_base.inverse() * data.oMf[robot.model.getFrameId(arm.tcp_frame)]).homogeneous
        arms[name] = {
            "tcp_frame": arm.tcp_frame,
            "approach": arm_spec.approach,
            "approach_in_base_at_reference": np.round(T_base_tcp[:3, :3] @ arm.approach_axis, 4).tolist(),
            "tcp_at_reference": np.round(T_base_tcp[:3, 3], 4).tolist(),
            "joints": [
                {
                    "name": j,
                    "type": "prismatic" if k == PRISMATIC else ("continuous" if c else "revolute"),
                    "lower": round(float(lo), 5),
                    "upper": round(float(hi), 5),
                }
                for j, k, c, lo, hi in zip(
                    arm.joint_names, arm.kinds, arm.continuous, arm.lower, arm.upper, strict=True
                )
            ],
        }
        warning = approach_warning(robot, name, meshes)
        if warning is not None:
            warnings.append(warning)

    bare = _links_without_collision(robot.urdf.xml)
    bare_on_arm = [link for link in bare if robot.model.existFrame(link) and _on_an_arm(robot, link)]
    if bare_on_arm:
        warnings.append(
            "arm or hand link(s) with visual but no collision geometry, invisible to collision checks: "
            + ", ".join(bare_on_arm)
        )
    # a mount's generated base body is the footprint itself (a polygon's bounding box): not a finding
    generated = spec.base_frame if spec.mount is not None else None
    base = [m for m in meshes if not m.on_arm and m.link != generated]
    footprint: dict[str, Any] = (
        {"radius": spec.footprint_radius}
        if spec.footprint_radius is not None
        else {"polygon": [list(p) for p in spec.footprint_polygon or ()]}
    )
    if base:
        points = np.concatenate([m.vertices for m in base])
        owner = [m.link for m in base for _ in range(len(m.vertices))]
        overhang, i = _footprint_overhang(spec, points[:, :2])
        footprint["base_mesh_overhang"] = round(overhang, 4)
        footprint["base_mesh_radius"] = round(float(np.hypot(points[:, 0], points[:, 1]).max()), 4)
        if overhang > FOOTPRINT_TOLERANCE:
            warnings.append(
                f"the footprint is smaller than the base's collision meshes: link {owner[i]!r} reaches "
                f"{overhang:.3f} m beyond it (at x={points[i, 0]:.3f}, y={points[i, 1]:.3f} in {spec.base_frame})"
            )
        lowest = float(points[:, 2].min())
        if lowest < -FOOTPRINT_TOLERANCE:
            warnings.append(
                f"the base's collision geometry reaches {-lowest:.3f} m below {spec.base_frame!r}: the base "
                "frame should lie on the floor"
            )
    if not [m for m in meshes if not m.on_arm]:
        warnings.append(
            "the base has no collision geometry: nothing keeps it off obstacles (set mount.base_height)"
        )
    if robot.urdf.missing_visual:
        warnings.append(
            f"visual mesh(es) not found (the viewer will skip them): {', '.join(robot.urdf.missing_visual[:5])}"
        )
    for name in spec.arms:
        arm = robot.arm(name)
        q_ref = arm.from_pinocchio(robot.q_reference)
        outside = [
            f"{j} = {v:.3g} not in [{lo:.3g}, {hi:.3g}]"
            for j, v, lo, hi in zip(arm.joint_names, q_ref, arm.lower, arm.upper, strict=True)
            if not lo - 1e-9 <= v <= hi + 1e-9
        ]
        if outside:
            warnings.append(
                f"arm {name!r}: the reference configuration (the pose the robot stands in, e.g. for "
                f"surface-sample's collision checks) is outside the joint limits: {'; '.join(outside)}; "
                "set these joints under [reference]"
            )
    contacts = selfcol.contacts(robot.q_reference)
    srdf_fix = disable_collisions_lines(contacts, selfcol.active_link_pairs())
    if contacts:
        warnings.append(self_collision_warning(contacts, generated))

    objects = geom.geometryObjects
    pairs = [[objects[p.first].name, objects[p.second].name] for p in geom.collisionPairs]
    return RobotReport(
        name=spec.name,
        urdf=str(spec.urdf),
        base_frame=spec.base_frame,
        mount=None
        if spec.mount is None
        else {
            "xyz": list(spec.mount.xyz),
            "rpy": list(spec.mount.rpy),
            "base_height": spec.mount.body_top,
        },
        footprint=footprint,
        arms=arms,
        collision={
            "geometries": int(geom.ngeoms),
            "links_without_collision": bare,
            "meshes_rendered": len(meshes),
            "pairs": len(pairs),
            "srdf": None if spec.srdf is None else str(spec.srdf),
            "pair_names": pairs,
            "colliding_at_reference": [
                {
                    "link1": c.link1,
                    "link2": c.link2,
                    "geometry1": c.geometry1,
                    "geometry2": c.geometry2,
                    "adjacent": c.adjacent,
                    "depth_m": None if c.depth is None else round(c.depth, 6),
                }
                for c in contacts
            ],
            "srdf_fix": srdf_fix,
        },
        package_dirs=[str(d) for d in robot.urdf.package_dirs],
        warnings=warnings,
    )
