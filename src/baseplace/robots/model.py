"""Robots loaded from URDF through pinocchio, and the kinematic chain of each arm.

A :class:`Robot` holds the full pinocchio model. An :class:`Arm` is the serial chain from the
base frame to one TCP frame: the joints named in the arm spec move, every other joint on the way
is frozen at its reference value and folded into a constant placement. The chain arrays feed the
compiled FK and IK kernels (``fk.py``, ``ik.py``); pinocchio itself stays the reference they are
tested against.
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
import tempfile
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError, unknown
from baseplace.geometry.poses import FloatArray
from baseplace.robots.spec import RobotSpec, load_spec
from baseplace.robots.urdf import check_urdf_file, check_urdf_tree, robot_urdf

REVOLUTE, PRISMATIC = 0, 1


@contextlib.contextmanager
def native_stderr_captured() -> Iterator[list[str]]:
    """Capture what C++ libraries (urdfdom's console_bridge, assimp) write to file descriptor 2.

    They print parse errors straight to the process's stderr; the CLI promises one line.
    """
    lines: list[str] = []
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as sink:
        os.dup2(sink.fileno(), 2)
        try:
            yield lines
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            sink.seek(0)
            lines.extend(sink.read().decode(errors="replace").splitlines())


def _urdfdom_reason(native: list[str]) -> str | None:
    """The explanation urdfdom printed, among its lines (console_bridge's "Error: ..." lines)."""
    for line in native:
        text = line.strip()
        if text.startswith("Error:"):
            return " ".join(text[len("Error:") :].split())
    return None


def load_urdf(path: Path, xml: str | None = None) -> pin.Model:
    """Parse a URDF (the file, or its text ``xml``) into a pinocchio model; failures are one line.

    Where urdfdom explains a failure (a joint whose parent link, such as a removed ``world``
    link, is not defined, say), its explanation is the message.
    """
    if not path.is_file():
        raise InputError(f"URDF {path} does not exist")
    if xml is None:
        check_urdf_file(path)
    try:
        root = ElementTree.fromstring(xml) if xml is not None else ElementTree.parse(path).getroot()
    except ElementTree.ParseError as exc:
        raise InputError(f"cannot parse URDF {path}: malformed XML ({exc})") from None
    check_urdf_tree(root, path)  # urdfdom and pinocchio recurse once per joint of a chain
    native: list[str] = []
    try:
        with native_stderr_captured() as native:
            return pin.buildModelFromXML(xml) if xml is not None else pin.buildModelFromUrdf(str(path))
    except Exception as exc:  # pinocchio raises ValueError/RuntimeError with multi-line text
        lines = str(exc).strip().splitlines()
        reason = _urdfdom_reason(native) or (lines[0] if lines else repr(exc))
        raise InputError(f"cannot parse URDF {path}: {reason}") from None


@dataclass(frozen=True)
class Arm:
    """The serial chain ``T_base_tcp(q) = prod_i (P_i M_i(q_i)) @ T_last_tcp``.

    Attributes:
        robot_name: the robot this arm belongs to.
        name: arm name in the robot spec.
        joint_names: the moving joints in chain order (base to TCP), n of them.
        base_frame: frame of the mobile base.
        tcp_frame: frame of the tool centre point.
        lower: (n,) lower joint limits [rad or m].
        upper: (n,) upper joint limits.
        continuous: (n,) True for unbounded revolute joints (angles wrap).
        placements: (n, 4, 4) placement of each joint relative to the previous moving joint
            (the first relative to the base frame), frozen joints folded in.
        axes: (n, 3) joint axis in the joint frame (unit).
        kinds: (n,) REVOLUTE (0) or PRISMATIC (1).
        T_last_tcp: (4, 4) TCP frame in the frame of the last moving joint.
        q_index: (n,) index of each joint in pinocchio's configuration vector.
        q_width: (n,) 1, or 2 for unbounded joints stored as (cos, sin).
        approach_axis: (3,) unit vector in the TCP frame pointing out of the hand (the spec's
            ``approach``, default x).
        stowed: (n,) the spec's stowed joint values (``ArmSpec.stowed``), or None (none given, or
            not one per joint).
    """

    robot_name: str
    name: str
    joint_names: tuple[str, ...]
    base_frame: str
    tcp_frame: str
    lower: FloatArray
    upper: FloatArray
    continuous: NDArray[np.bool_]
    placements: FloatArray
    axes: FloatArray
    kinds: NDArray[np.int64]
    T_last_tcp: FloatArray
    q_index: NDArray[np.int64]
    q_width: NDArray[np.int64]
    approach_axis: FloatArray = field(default_factory=lambda: np.array([1.0, 0.0, 0.0]))
    stowed: FloatArray | None = None

    @property
    def n_joints(self) -> int:
        """Number of moving joints."""
        return len(self.joint_names)

    def sample(self, rng: np.random.Generator, n: int) -> FloatArray:
        """``n`` configurations drawn uniformly within the joint limits, shape (n, n_joints)."""
        Q = rng.random((n, self.n_joints))
        Q *= self.upper - self.lower
        Q += self.lower
        return Q

    def within_limits(self, q: ArrayLike, tol: float = 1e-9) -> NDArray[np.bool_]:
        """True where every joint of (N, n) configurations lies within its limits."""
        q = np.asarray(q, dtype=float)
        return np.all((q >= self.lower - tol) & (q <= self.upper + tol), axis=-1)

    def to_pinocchio(self, q_arm: ArrayLike, q_full: ArrayLike) -> FloatArray:
        """Write arm joint values (n,) into a copy of a full pinocchio configuration."""
        q = np.array(q_full, dtype=float)
        for value, i, w in zip(np.asarray(q_arm, dtype=float), self.q_index, self.q_width, strict=True):
            if w == 2:
                q[i], q[i + 1] = math.cos(value), math.sin(value)
            else:
                q[i] = value
        return q

    def from_pinocchio(self, q_full: ArrayLike) -> FloatArray:
        """Read the arm joint values (n,) out of a full pinocchio configuration."""
        q = np.asarray(q_full, dtype=float)
        return np.array(
            [
                math.atan2(q[i + 1], q[i]) if w == 2 else q[i]
                for i, w in zip(self.q_index, self.q_width, strict=True)
            ]
        )


class Robot:
    """A mobile manipulator: its spec, its pinocchio model and its arms.

    Args:
        spec: a :class:`RobotSpec`, a built-in robot name, or a path to a robot file.
    """

    def __init__(self, spec: RobotSpec | str | Path) -> None:
        self.spec = spec if isinstance(spec, RobotSpec) else load_spec(spec)
        if not self.spec.urdf.is_file():
            raise InputError(f"URDF {self.spec.urdf} does not exist")
        self.urdf = robot_urdf(self.spec)
        self.model = load_urdf(self.spec.urdf, self.urdf.xml)
        if not self.model.existFrame(self.spec.base_frame):
            raise unknown("base frame", self.spec.base_frame, self.frame_names, f"robot {self.name!r}")
        for joint in [*self.spec.joint_limits, *self.spec.reference]:
            self._joint_id(joint)
        self._arms: dict[str, Arm] = {}
        self._tcp_grasp: dict[str, FloatArray] = {}

    @property
    def name(self) -> str:
        """The robot's name."""
        return self.spec.name

    @property
    def frame_names(self) -> list[str]:
        """Names of all frames of the URDF."""
        return [f.name for f in self.model.frames]

    @property
    def joint_names(self) -> list[str]:
        """Names of all joints with degrees of freedom (pinocchio's 'universe' excluded)."""
        return list(self.model.names)[1:]

    def _joint_id(self, name: str) -> int:
        j = self.model.getJointId(name)
        if j >= self.model.njoints:
            raise unknown("joint", name, self.joint_names, f"robot {self.name!r}")
        return int(j)

    @cached_property
    def q_reference(self) -> FloatArray:
        """Full pinocchio configuration: neutral, with the spec's reference values written in."""
        q = pin.neutral(self.model)
        for name, value in self.spec.reference.items():
            jm = self.model.joints[self._joint_id(name)]
            if jm.nq == 2:
                q[jm.idx_q : jm.idx_q + 2] = (math.cos(value), math.sin(value))
            else:
                q[jm.idx_q] = value
        return q

    def arm(self, name: str | None = None) -> Arm:
        """The :class:`Arm` called ``name`` (the spec's default arm if None)."""
        key = self.spec.default_arm if name is None else name
        if key not in self._arms:
            self._arms[key] = self._build_arm(key)
        return self._arms[key]

    def _build_arm(self, arm_name: str) -> Arm:
        spec = self.spec.arm(arm_name)
        model = self.model
        if not model.existFrame(spec.tcp_frame):
            raise unknown("TCP frame", spec.tcp_frame, self.frame_names, f"robot {self.name!r}")
        arm_ids = {self._joint_id(j) for j in spec.joints}
        data = model.createData()
        q_ref = self.q_reference
        pin.forwardKinematics(model, data, q_ref)
        pin.updateFramePlacements(model, data)
        pin.computeJointJacobians(model, data, q_ref)

        base = model.frames[model.getFrameId(self.spec.base_frame)]
        tcp = model.frames[model.getFrameId(spec.tcp_frame)]
        path = [int(j) for j in model.supports[tcp.parentJoint]][1:]  # root to leaf, no universe
        off_chain = arm_ids - set(path)
        if off_chain:
            names = sorted(model.names[j] for j in off_chain)
            on_chain = [model.names[j] for j in path]
            raise InputError(
                f"joint(s) {names} do not move TCP frame {spec.tcp_frame!r}; joints on its chain: {on_chain}"
            )
        if set(model.supports[base.parentJoint]) & arm_ids:
            raise InputError(f"base frame {self.spec.base_frame!r} must not move with the arm joints")

        T_acc = data.oMf[model.getFrameId(self.spec.base_frame)].inverse()
        placements, axes, kinds, lower, upper, continuous, q_index, q_width, names = ([] for _ in range(9))
        for j in path:
            if j not in arm_ids:
                T_acc = T_acc * data.liMi[j]
                continue
            jm = model.joints[j]
            if jm.nv != 1:
                raise InputError(
                    f"joint {model.names[j]!r} has {jm.nv} degrees of freedom; arm joints must be "
                    "revolute, continuous or prismatic"
                )
            S = pin.getJointJacobian(model, data, j, pin.LOCAL)[:, jm.idx_v]
            lin, ang = S[:3], S[3:]
            if np.linalg.norm(ang) > 1e-9 and np.linalg.norm(lin) < 1e-9:
                kinds.append(REVOLUTE)
                axes.append(ang / np.linalg.norm(ang))
            elif np.linalg.norm(ang) < 1e-9 and np.linalg.norm(lin) > 1e-9:
                kinds.append(PRISMATIC)
                axes.append(lin / np.linalg.norm(lin))
            else:
                raise InputError(f"joint {model.names[j]!r} is neither revolute nor prismatic")
            placements.append((T_acc * model.jointPlacements[j]).homogeneous)
            T_acc = pin.SE3.Identity()
            name = model.names[j]
            is_cont = jm.nq == 2
            lo, hi = (
                (-math.pi, math.pi)
                if is_cont
                else (model.lowerPositionLimit[jm.idx_q], model.upperPositionLimit[jm.idx_q])
            )
            lo, hi = self.spec.joint_limits.get(name, (lo, hi))
            if not (np.isfinite(lo) and np.isfinite(hi) and lo < hi):
                raise InputError(f"joint {name!r} needs finite limits lo < hi; set them in joint_limits")
            names.append(name)
            lower.append(lo)
            upper.append(hi)
            continuous.append(is_cont and name not in self.spec.joint_limits)
            q_index.append(jm.idx_q)
            q_width.append(jm.nq)
        return Arm(
            robot_name=self.name,
            name=arm_name,
            joint_names=tuple(names),
            base_frame=self.spec.base_frame,
            tcp_frame=spec.tcp_frame,
            lower=np.array(lower, dtype=float),
            upper=np.array(upper, dtype=float),
            continuous=np.array(continuous, dtype=bool),
            placements=np.ascontiguousarray(placements, dtype=float),
            axes=np.ascontiguousarray(axes, dtype=float),
            kinds=np.array(kinds, dtype=np.int64),
            T_last_tcp=(T_acc * tcp.placement).homogeneous,
            q_index=np.array(q_index, dtype=np.int64),
            q_width=np.array(q_width, dtype=np.int64),
            approach_axis=np.array(spec.approach_vector, dtype=float),
            stowed=None
            if spec.stowed is None or len(spec.stowed) != len(names)
            else np.array(spec.stowed, dtype=float),
        )

    def T_tcp_grasp(self, arm_name: str | None = None) -> FloatArray:
        """The grasp point's pose in the arm's TCP frame, (4, 4) [m]: fixed, read from the URDF.

        The grasp point is the spec's ``grasp_frame`` (between the fingertips); without one, the TCP.

        Raises:
            InputError: the grasp frame is not in the URDF, or moves relative to the TCP.
        """
        key = self.spec.default_arm if arm_name is None else arm_name
        if key not in self._tcp_grasp:  # read once per arm (read only)
            T = self._read_tcp_grasp(key)
            T.flags.writeable = False
            self._tcp_grasp[key] = T
        return self._tcp_grasp[key]

    def _read_tcp_grasp(self, arm_name: str) -> FloatArray:
        spec = self.spec.arm(arm_name)
        if spec.grasp_frame is None:
            return np.eye(4)
        model = self.model
        if not model.existFrame(spec.grasp_frame):
            raise unknown("grasp frame", spec.grasp_frame, self.frame_names, f"robot {self.name!r}")
        grasp = model.frames[model.getFrameId(spec.grasp_frame)]
        tcp = model.frames[model.getFrameId(spec.tcp_frame)]
        if grasp.parentJoint != tcp.parentJoint:  # a joint between them: no fixed offset
            raise InputError(f"robot {self.name!r}: grasp frame {spec.grasp_frame!r} must be fixed to "
                             f"the link of TCP frame {spec.tcp_frame!r}")  # fmt: skip
        return (tcp.placement.inverse() * grasp.placement).homogeneous

    def frame_pose(self, q_full: ArrayLike, frame: str, relative_to: str | None = None) -> FloatArray:
        """Pinocchio FK of one frame, (4, 4), in the robot root or in ``relative_to``."""
        data = self.model.createData()
        pin.framesForwardKinematics(self.model, data, np.asarray(q_full, dtype=float))
        T = data.oMf[self.model.getFrameId(frame)]
        if relative_to is not None:
            T = data.oMf[self.model.getFrameId(relative_to)].inverse() * T
        return T.homogeneous
