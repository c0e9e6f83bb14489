"""Self-collision checks with coal through pinocchio's GeometryModel.

Pairs that can never collide meaningfully are disabled: the SRDF's ``disable_collisions`` where
the robot has one; otherwise, as MoveIt's setup assistant does, geometries rigidly attached to
the same joint, geometries on adjacent joints, and pairs already touching at the reference
configuration (parts that are in contact by design).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError, brief
from baseplace.robots.model import Arm, Robot, native_stderr_captured
from baseplace.robots.spec import RobotSpec


def allowed_mesh_dirs(spec: RobotSpec) -> list[Path]:
    """Where a robot's meshes may live (resolved folders).

    Its package folders, its URDF's folder, and the folders in ``$BASEPLACE_MESH_DIRS``
    (separated by ``os.pathsep``) the user allows in addition.
    """
    extra = [Path(d) for d in os.environ.get("BASEPLACE_MESH_DIRS", "").split(os.pathsep) if d]
    return [p.resolve() for p in (*spec.package_dirs, spec.urdf.parent, *extra)]


def check_mesh_paths(spec: RobotSpec) -> None:
    """Refuse a URDF whose mesh files lie outside :func:`allowed_mesh_dirs`.

    A robot file is data: it must not make baseplace open ``/etc/shadow`` or another user's
    files as meshes. ``package://pkg/x.stl`` is looked up under each package folder,
    ``file://`` and plain paths relative to the URDF's folder; symbolic links are followed.

    Raises:
        InputError: a mesh path escapes the allowed folders (one line, with the remedy).
    """
    allowed = allowed_mesh_dirs(spec)
    try:
        root = ElementTree.parse(spec.urdf).getroot()
    except (ElementTree.ParseError, OSError):
        return  # load_urdf reports it
    for mesh in root.iter("mesh"):
        uri = mesh.get("filename", "")
        if uri.startswith("package://"):
            rest = uri[len("package://") :]
            candidates = [(d / rest).resolve() for d in spec.package_dirs]
        else:
            rest = uri[len("file://") :] if uri.startswith("file://") else uri
            candidates = [(spec.urdf.parent / rest).resolve()]
        if not any(c.is_relative_to(d) for c in candidates for d in allowed):
            raise InputError(
                f"URDF {spec.urdf}: mesh {brief(uri, 80)} lies outside the robot's package folders; "
                "add its folder to package_dirs or to BASEPLACE_MESH_DIRS to allow it"
            )


def load_collision_model(robot: Robot) -> pin.GeometryModel:
    """The robot's collision geometry (mesh paths resolved when the robot was loaded)."""
    spec = robot.spec
    check_mesh_paths(spec)
    try:
        with native_stderr_captured():
            return pin.buildGeomFromUrdfString(robot.model, robot.urdf.xml, pin.COLLISION)
    except Exception as exc:
        lines = str(exc).strip().splitlines()
        raise InputError(
            f"cannot load collision meshes of {spec.urdf}: {lines[0] if lines else exc!r}"
        ) from None


MAX_SRDF_BYTES = 16 * 2**20
"""The largest SRDF read (a robot's SRDF, every pair of its links disabled, is well under 1 MB)."""


def _remove_srdf_pairs(model: pin.Model, geom: pin.GeometryModel, srdf: Path) -> None:
    """Disable the SRDF's ``disable_collisions`` pairs; a malformed, large or deep SRDF is a one-line error.

    Size and nesting are checked before pinocchio's reader, which recurses once per level (a
    700 kB SRDF nested 100,000 deep crashed the process).
    """
    from baseplace.guards import check_file_size
    from baseplace.robots.urdf import check_xml_depth

    check_file_size(srdf, "SRDF", MAX_SRDF_BYTES)
    try:
        root = ElementTree.parse(srdf).getroot()
    except (ElementTree.ParseError, OSError) as exc:
        raise InputError(f"cannot parse SRDF {srdf}: {' '.join(str(exc).split())[:200]}") from None
    check_xml_depth(root, f"SRDF {srdf}", 3)
    try:
        with native_stderr_captured():
            pin.removeCollisionPairs(model, geom, str(srdf))
    except Exception as exc:  # pinocchio raises RuntimeError/ValueError with multi-line text
        lines = str(exc).strip().splitlines()
        raise InputError(
            f"cannot read SRDF {srdf}: {lines[0][:200] if lines else type(exc).__name__}"
        ) from None


def _adjacent(parents: list[int], a: pin.GeometryObject, b: pin.GeometryObject) -> bool:
    """True where one geometry's joint is the other's parent joint (MoveIt's "Adjacent" links)."""
    return bool(parents[a.parentJoint] == b.parentJoint or parents[b.parentJoint] == a.parentJoint)


@dataclass(frozen=True)
class Contact:
    """Two collision geometries of one robot that touch.

    Attributes:
        geometry1, geometry2: pinocchio's geometry names (link name and index).
        link1, link2: the URDF links they belong to (the names an SRDF's ``disable_collisions`` uses).
        adjacent: True where one link's joint is the other's parent joint (fixed joints merged), the
            pairs MoveIt's setup assistant disables as "Adjacent".
        depth: the penetration depth [m] coal reports for its deepest contact (for two meshes, that
            of the intersecting triangles); None where coal gives no contact point.
    """

    geometry1: str
    geometry2: str
    link1: str
    link2: str
    adjacent: bool
    depth: float | None


class SelfCollision:
    """Self-collision checker for one robot.

    Args:
        robot: the robot.
        num_threads: threads for batched checks (default: all cores).
    """

    def __init__(self, robot: Robot, num_threads: int | None = None) -> None:
        self.robot = robot
        self.model = robot.model
        self.geom = load_collision_model(robot)
        self.geom.addAllCollisionPairs()
        if robot.spec.srdf is not None:
            _remove_srdf_pairs(self.model, self.geom, robot.spec.srdf)
            # an SRDF knows nothing of a mount's base body: rigidly joined geometry never moves apart
            objects = self.geom.geometryObjects
            for pair in [p for p in self.geom.collisionPairs
                         if objects[p.first].parentJoint == objects[p.second].parentJoint]:  # fmt: skip
                self.geom.removeCollisionPair(pin.CollisionPair(pair.first, pair.second))
        else:
            self._disable_structural_pairs()
        self.num_threads = num_threads or os.cpu_count() or 1
        self.data = self.model.createData()
        self.geom_data = pin.GeometryData(self.geom)
        self._arm_data: dict[str, pin.GeometryData] = {}

    def _disable_structural_pairs(self) -> None:
        parents = self.model.parents
        objects = self.geom.geometryObjects
        keep = []
        for pair in self.geom.collisionPairs:
            ja, jb = objects[pair.first].parentJoint, objects[pair.second].parentJoint
            if ja == jb or parents[ja] == jb or parents[jb] == ja:
                continue
            keep.append((pair.first, pair.second))  # copies: the vector is cleared below
        self.geom.removeAllCollisionPairs()
        for first, second in keep:
            self.geom.addCollisionPair(pin.CollisionPair(first, second))
        data, geom_data = self.model.createData(), pin.GeometryData(self.geom)
        pin.computeCollisions(self.model, data, self.geom, geom_data, self.robot.q_reference, False)
        touching = [
            pin.CollisionPair(pair.first, pair.second)
            for pair, res in zip(self.geom.collisionPairs, geom_data.collisionResults, strict=True)
            if res.isCollision()
        ]
        for pair in touching:
            self.geom.removeCollisionPair(pair)

    @property
    def n_pairs(self) -> int:
        """Number of active collision pairs."""
        return len(self.geom.collisionPairs)

    def colliding(self, q_full: ArrayLike) -> bool:
        """True if the robot at the full pinocchio configuration collides with itself."""
        q = np.asarray(q_full, dtype=float)
        return bool(pin.computeCollisions(self.model, self.data, self.geom, self.geom_data, q, True))

    def colliding_pairs(self, q_full: ArrayLike, arm: Arm | None = None) -> list[tuple[str, str]]:
        """The (link, link) pairs that touch at the full pinocchio configuration.

        With ``arm``, only the pairs that arm moves relative to each other (as :meth:`colliding_arm`).
        """
        q = np.asarray(q_full, dtype=float)
        geom_data = self._arm_geometry_data(arm) if arm is not None else self.geom_data
        pin.computeCollisions(self.model, self.data, self.geom, geom_data, q, False)
        return [
            self.pair_links(k)
            for k, res in enumerate(geom_data.collisionResults)
            if geom_data.activeCollisionPairs[k] and res.isCollision()
        ]

    def pair_links(self, pair: int) -> tuple[str, str]:
        """The names of the two links (frames) whose geometries collision pair ``pair`` (index) joins."""
        p, objects, frames = self.geom.collisionPairs[pair], self.geom.geometryObjects, self.model.frames
        return str(frames[objects[p.first].parentFrame].name), str(frames[objects[p.second].parentFrame].name)

    def contacts(self, q_full: ArrayLike) -> list[Contact]:
        """Every active pair that touches at the full pinocchio configuration, with its depth.

        Slower than :meth:`colliding` (coal computes contact points): meant for reports.
        """
        q = np.asarray(q_full, dtype=float)
        geom_data = pin.GeometryData(self.geom)
        for request in geom_data.collisionRequests:
            request.enable_contact = True
        pin.computeCollisions(self.model, self.data, self.geom, geom_data, q, False)
        objects, frames, parents = self.geom.geometryObjects, self.model.frames, self.model.parents
        out = []
        for pair, res in zip(self.geom.collisionPairs, geom_data.collisionResults, strict=True):
            if not res.isCollision():
                continue
            a, b = objects[pair.first], objects[pair.second]
            depths = [abs(float(c.penetration_depth)) for c in res.getContacts()]
            out.append(Contact(
                geometry1=str(a.name), geometry2=str(b.name),
                link1=str(frames[a.parentFrame].name), link2=str(frames[b.parentFrame].name),
                adjacent=_adjacent(parents, a, b),
                depth=max(depths) if depths else None,
            ))  # fmt: skip
        return out

    def active_link_pairs(self) -> list[tuple[str, str, bool]]:
        """The (link, link, adjacent) pairs with at least one active geometry pair, in pair order."""
        objects, frames, parents = self.geom.geometryObjects, self.model.frames, self.model.parents
        seen: dict[tuple[str, str], bool] = {}
        for pair in self.geom.collisionPairs:
            a, b = objects[pair.first], objects[pair.second]
            key = (str(frames[a.parentFrame].name), str(frames[b.parentFrame].name))
            seen[key] = _adjacent(parents, a, b)
        return [(a, b, adjacent) for (a, b), adjacent in seen.items()]

    def _arm_geometry_data(self, arm: Arm) -> pin.GeometryData:
        """GeometryData with only the pairs whose relative pose changes when ``arm`` moves.

        Geometries are grouped by the last arm joint that moves them; two geometries in one group
        keep their relative pose for every arm configuration, so checking them is wasted work.
        """
        if arm.name not in self._arm_data:
            arm_ids = [self.model.getJointId(j) for j in arm.joint_names]
            group_of_joint = {}
            for joint in range(self.model.njoints):
                supports = set(self.model.supports[joint])
                group_of_joint[joint] = max((i for i, j in enumerate(arm_ids) if j in supports), default=-1)
            group = [group_of_joint[g.parentJoint] for g in self.geom.geometryObjects]
            geom_data = pin.GeometryData(self.geom)
            for k, pair in enumerate(self.geom.collisionPairs):
                if group[pair.first] == group[pair.second]:
                    geom_data.deactivateCollisionPair(k)
            self._arm_data[arm.name] = geom_data
        return self._arm_data[arm.name]

    def colliding_arm(self, arm: Arm, q_arm: ArrayLike) -> NDArray[np.bool_]:
        """Self-collision of (N, n) arm configurations, other joints at their reference values."""
        Q = np.asarray(q_arm, dtype=float).reshape(-1, arm.n_joints)
        q_ref = self.robot.q_reference
        geom_data = self._arm_geometry_data(arm)
        return np.array(
            [
                pin.computeCollisions(
                    self.model, self.data, self.geom, geom_data, arm.to_pinocchio(q, q_ref), True
                )
                for q in Q
            ],
            dtype=bool,
        )
