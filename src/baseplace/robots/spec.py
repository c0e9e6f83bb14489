"""Robot specifications: which URDF, which base frame, which arms, which footprint.

Built-in specs use the URDFs and meshes of the ``example-robot-data`` wheel. Custom robots come
from a small TOML or YAML file::

    name = "my_arm"
    urdf = "my_arm.urdf"              # relative to this file
    srdf = "my_arm.srdf"              # optional: disabled self-collision pairs
    package_dirs = ["."]              # optional: where package:// mesh paths resolve (else found)
    base_frame = "base_link"
    footprint = { radius = 0.3 }      # or { polygon = [[x, y], ...] } in the base frame [m]
    [mount]                           # optional: the URDF is an arm alone, standing on a mobile base
    xyz = [0.1, 0.0, 0.4]             # pose of the URDF's root link in base_frame [m]
    rpy = [0.0, 0.0, 0.0]             # [rad]
    base_height = 0.4                 # optional: top of the base's collision body [m] (default xyz z)
    [arms.arm]
    joints = ["joint1", "joint2"]     # the joints sampled for reachability
    tcp_frame = "tool0"
    approach = "z"                    # optional: the TCP axis pointing out of the hand (default "x")
    grasp_frame = "grasp_link"        # optional: the frame between the fingertips (default: the TCP)
    [joint_limits]                    # optional overrides [rad or m]
    joint1 = [-1.5, 1.5]
    [reference]                       # optional values of joints not in an arm (default 0)
    head_joint = 0.2
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import math
import os
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

from baseplace.errors import InputError, brief, unknown
from baseplace.guards import check_name, read_document

MAX_ROBOT_FILE_BYTES = 1 << 20
"""The largest robot file (TOML or YAML) read [bytes]; one with two arms and joint limits is about 2 kB."""


APPROACH_AXES = {"x": (1.0, 0.0, 0.0), "y": (0.0, 1.0, 0.0), "z": (0.0, 0.0, 1.0),
                 "-x": (-1.0, 0.0, 0.0), "-y": (0.0, -1.0, 0.0), "-z": (0.0, 0.0, -1.0)}  # fmt: skip
"""TCP approach axes a robot file may name: the TCP frame's axis pointing out of the hand."""


@dataclass(frozen=True)
class ArmSpec:
    """One arm: the joints sampled for its reachability and its tool centre point frame.

    Attributes:
        joints: joint names; any order, they are sorted along the kinematic chain.
        tcp_frame: name of the TCP frame in the URDF.
        approach: the TCP frame's axis that points out of the hand, towards what it grasps: one
            of :data:`APPROACH_AXES`. "x" for TIAGo's ``arm_tool_link`` and PR2's
            ``*_gripper_tool_frame``; "z" for ROS-Industrial ``tool0`` frames and Panda's
            ``panda_hand_tcp``. Surface maps and the side/top grasps read it.
        grasp_frame: the URDF frame at the grasp point, between the fingertips, fixed to the TCP's
            link (``--grasp-point`` targets it); None: the TCP is the grasp point (PR2's
            ``*_gripper_tool_frame``). TIAGo's is ``hand_grasping_frame``, 0.151 m ahead of
            ``arm_tool_link``.
        stowed: the arm's stowed ("home", "tucked") joint values in the order of ``joints``
            [rad, m], where the reaching motion starts; None: the robot's reference values.
    """

    joints: tuple[str, ...]
    tcp_frame: str
    approach: str = "x"
    grasp_frame: str | None = None
    stowed: tuple[float, ...] | None = None

    def __post_init__(self) -> None:
        if self.approach not in APPROACH_AXES:
            raise unknown("TCP approach axis", self.approach, APPROACH_AXES, f"TCP {self.tcp_frame!r}")

    @property
    def approach_vector(self) -> tuple[float, float, float]:
        """The approach axis as a unit vector in the TCP frame."""
        return APPROACH_AXES[self.approach]


@dataclass(frozen=True)
class Mount:
    """Where an arm's URDF stands on the mobile base: no wrapper URDF needed.

    The URDF's root link is attached to a new ``base_frame`` link at ``T_base_root``; the base
    gets a collision body, the footprint (a cylinder, or the polygon's bounding box) from
    :data:`BASE_CLEARANCE` above the floor up to ``base_height``.

    Attributes:
        xyz: position of the URDF's root link in the base frame [m].
        rpy: its orientation as ROS roll, pitch, yaw [rad].
        base_height: top of the base's collision body above the floor [m]; None: the mount's z.
            0 gives the base no collision body.
    """

    xyz: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rpy: tuple[float, float, float] = (0.0, 0.0, 0.0)
    base_height: float | None = None

    def __post_init__(self) -> None:
        values = (*self.xyz, *self.rpy, 0.0 if self.base_height is None else self.base_height)
        if len(self.xyz) != 3 or len(self.rpy) != 3 or not all(math.isfinite(v) for v in values):
            raise InputError(
                "mount needs xyz = [x, y, z] [m] and rpy = [roll, pitch, yaw] [rad], finite numbers"
            )
        if max(abs(v) for v in self.xyz) > 5.0 or not (0.0 <= self.body_top <= 5.0):
            raise InputError(
                "mount xyz and base_height must lie within 5 m of the base frame, base_height >= 0"
            )

    @property
    def body_top(self) -> float:
        """Top of the base's collision body [m]."""
        return self.xyz[2] if self.base_height is None else self.base_height


BASE_CLEARANCE = 0.05
"""Height [m] of a mounted base's collision body above the floor: its wheels' clearance (floor
voxels within 0.1 m of the plane are support, never obstacles)."""


@dataclass(frozen=True)
class RobotSpec:
    """Everything baseplace needs to know about a mobile manipulator beyond its URDF.

    Attributes:
        name: short identifier used in map files and the CLI.
        urdf: path of the URDF file.
        base_frame: frame of the mobile base; placements are poses of this frame.
        arms: arm name -> :class:`ArmSpec`.
        default_arm: the arm used when none is named.
        footprint_radius: base footprint as a circle [m], or None if a polygon is given.
        footprint_polygon: base footprint as a polygon ((x, y), ...) in the base frame [m].
        srdf: optional SRDF with disabled self-collision pairs.
        package_dirs: directories searched first where ``package://`` mesh URIs resolve; more are
            found automatically (:func:`baseplace.robots.urdf.package_search_dirs`).
        joint_limits: joint name -> (lower, upper) overriding the URDF [rad or m].
        reference: joint name -> value for joints outside the arm (default 0).
        mount: where an arm-only URDF stands on the mobile base ``base_frame``, or None when the
            URDF is the whole robot.
    """

    name: str
    urdf: Path
    base_frame: str
    arms: dict[str, ArmSpec]
    default_arm: str
    footprint_radius: float | None = None
    footprint_polygon: tuple[tuple[float, float], ...] | None = None
    srdf: Path | None = None
    package_dirs: tuple[Path, ...] = ()
    joint_limits: dict[str, tuple[float, float]] = field(default_factory=dict)
    reference: dict[str, float] = field(default_factory=dict)
    mount: Mount | None = None

    def __post_init__(self) -> None:
        check_name(self.name, "robot name")  # names reach map files and cache keys: words only
        for arm_name in self.arms:
            check_name(arm_name, "arm name", f"robot {self.name!r}")
        if not self.arms:
            raise InputError(f"robot {self.name!r} defines no arm")
        if self.default_arm not in self.arms:
            raise unknown("default arm", self.default_arm, self.arms)
        if (self.footprint_radius is None) == (self.footprint_polygon is None):
            raise InputError(f"robot {self.name!r}: give exactly one of footprint radius or polygon")
        if self.footprint_radius is not None and not (0 < self.footprint_radius < 5):
            raise InputError(f"robot {self.name!r}: footprint radius must be in (0, 5) m")
        if self.footprint_polygon is not None and len(self.footprint_polygon) < 3:
            raise InputError(f"robot {self.name!r}: footprint polygon needs at least 3 vertices")
        for joint, (lo, hi) in self.joint_limits.items():
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise InputError(f"robot {self.name!r}: joint limits of {joint!r} must be lo < hi")

    def arm(self, name: str | None = None) -> ArmSpec:
        """The arm called ``name`` (the default arm if None)."""
        key = self.default_arm if name is None else name
        if key not in self.arms:
            raise unknown("arm", key, self.arms, f"robot {self.name!r}")
        return self.arms[key]

    @property
    def urdf_sha256(self) -> str:
        """SHA-256 of the URDF file (and the mount), recorded in maps to catch a changed robot."""
        if self.mount is None:
            return _sha256(self.urdf)
        return hashlib.sha256(f"{_sha256(self.urdf)} mount {self.mount}".encode()).hexdigest()

    @property
    def footprint_bounding_radius(self) -> float:
        """Radius [m] of the smallest origin-centred circle containing the footprint."""
        if self.footprint_radius is not None:
            return self.footprint_radius
        assert self.footprint_polygon is not None
        return max(math.hypot(x, y) for x, y in self.footprint_polygon)


@cache
def _sha256(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def example_robot_data_dir() -> Path:
    """The ``share`` directory of the example-robot-data wheel (its package root for meshes)."""
    try:
        dist = importlib.metadata.distribution("example-robot-data")
    except importlib.metadata.PackageNotFoundError:  # pragma: no cover
        raise InputError("the example-robot-data package is not installed") from None
    share = Path(str(dist.locate_file("cmeel.prefix/share")))
    if not (share / "example-robot-data" / "robots").is_dir():  # pragma: no cover
        raise InputError(f"example-robot-data has no robots directory under {share}")
    return share


def ros_package_roots() -> tuple[Path, ...]:
    """Folders holding ROS packages, in order.

    ``ROS_PACKAGE_PATH``, then the ``share`` folders of ``AMENT_PREFIX_PATH``, then
    example-robot-data's share folder.
    """
    roots = [Path(e) for e in os.environ.get("ROS_PACKAGE_PATH", "").split(os.pathsep) if e]
    roots += [Path(e) / "share" for e in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep) if e]
    try:
        roots.append(example_robot_data_dir())
    except InputError:  # pragma: no cover - a dependency of baseplace
        pass
    return tuple(roots)


def _erd(relative: str) -> Path:
    return example_robot_data_dir() / "example-robot-data" / "robots" / relative


_TIAGO_ARM = tuple(f"arm_{i}_joint" for i in range(1, 8))
_PR2_ARM = (
    "shoulder_pan_joint",
    "shoulder_lift_joint",
    "upper_arm_roll_joint",
    "elbow_flex_joint",
    "forearm_roll_joint",
    "wrist_flex_joint",
    "wrist_roll_joint",
)
# PAL's PMB2 base is a disc of 0.54 m diameter; the PR2 base is a 0.668 m square.
_PR2_HALF = 0.334


def _builtin_specs() -> dict[str, RobotSpec]:
    share = (example_robot_data_dir(),)
    return {
        "tiago": RobotSpec(
            name="tiago",
            urdf=_erd("tiago_description/robots/tiago.urdf"),
            base_frame="base_footprint",
            arms={
                "arm": ArmSpec(
                    ("torso_lift_joint", *_TIAGO_ARM),
                    "arm_tool_link",
                    grasp_frame="hand_grasping_frame",
                    stowed=(0.15, 0.20, -1.34, -0.20, 1.94, -1.57, 1.37, 0.0),  # PAL's home motion
                )
            },
            default_arm="arm",
            footprint_radius=0.275,
            package_dirs=share,
        ),
        "pr2": RobotSpec(
            name="pr2",
            urdf=_erd("pr2_description/urdf/pr2.urdf"),
            srdf=_erd("pr2_description/srdf/pr2.srdf"),
            base_frame="base_footprint",
            arms={
                # stowed: pr2_tuck_arms' values
                "left": ArmSpec(
                    ("torso_lift_joint", *(f"l_{j}" for j in _PR2_ARM)),
                    "l_gripper_tool_frame",
                    stowed=(0.0, 0.06024, 1.248526, 1.78907, -1.683386, -1.7343417, -0.0962141, -0.0864053),
                ),
                "right": ArmSpec(
                    ("torso_lift_joint", *(f"r_{j}" for j in _PR2_ARM)),
                    "r_gripper_tool_frame",
                    stowed=(0.0, -0.023593, 1.10728, -1.5566882, -2.124408, -1.4175, -1.8417, 0.21436),
                ),
            },
            default_arm="right",
            footprint_polygon=(
                (_PR2_HALF, _PR2_HALF),
                (-_PR2_HALF, _PR2_HALF),
                (-_PR2_HALF, -_PR2_HALF),
                (_PR2_HALF, -_PR2_HALF),
            ),
            package_dirs=share,
        ),
        "tiago_dual": RobotSpec(
            name="tiago_dual",
            urdf=_erd("tiago_description/robots/tiago_dual.urdf"),
            base_frame="base_footprint",
            arms={
                side: ArmSpec(
                    ("torso_lift_joint", *(f"arm_{side}_{i}_joint" for i in range(1, 8))),
                    f"arm_{side}_tool_link",
                    grasp_frame=f"hand_{side}_grasping_frame",
                )
                for side in ("left", "right")
            },
            default_arm="right",
            footprint_radius=0.275,
            package_dirs=share,
        ),
    }


BUILTIN_ROBOTS = ("tiago", "pr2", "tiago_dual")


def builtin_spec(name: str) -> RobotSpec:
    """The built-in spec called ``name`` (one of :data:`BUILTIN_ROBOTS`)."""
    specs = _builtin_specs()
    if name not in specs:
        raise unknown("robot", name, [*specs, "<path to a .toml/.yaml robot file>"])
    return specs[name]


def robot_file(name_or_path: str | Path) -> Path | None:
    """The robot file a robot argument names, None for a built-in robot; nothing is read.

    :func:`load_spec`'s first step, which front ends reach before the robot model's imports
    (pinocchio, coal: seconds; ``jobs.inputs.check_robot_name``), so that a mistyped robot is
    refused at once.

    Raises:
        InputError: neither a built-in name nor a .toml/.yaml file that exists.
    """
    text = str(name_or_path)
    if text in BUILTIN_ROBOTS:
        return None
    path = Path(text)
    if path.suffix.lower() not in (".toml", ".yaml", ".yml"):
        raise unknown("robot", text, [*BUILTIN_ROBOTS, "<path to a .toml/.yaml robot file>"])
    if not path.is_file():
        raise InputError(f"robot file {path} does not exist")
    return path


def load_spec(name_or_path: str | Path) -> RobotSpec:
    """A built-in robot by name, or a custom robot from a TOML or YAML file."""
    path = robot_file(name_or_path)
    if path is None:
        return builtin_spec(str(name_or_path))
    data = read_document(path, "robot file", MAX_ROBOT_FILE_BYTES, "a robot file names its URDF and arms")
    return spec_from_dict(data, path.parent, str(path))


_KEYS = {"name", "urdf", "srdf", "package_dirs", "base_frame", "footprint", "arms", "default_arm",
         "joint_limits", "reference", "mount"}  # fmt: skip
_ARM_KEYS = {"joints", "tcp_frame", "approach", "grasp_frame"}
_MOUNT_KEYS = {"xyz", "rpy", "base_height"}


def spec_from_dict(data: Any, root: Path, source: str = "robot spec") -> RobotSpec:
    """Build a :class:`RobotSpec` from parsed TOML/YAML; relative paths resolve against ``root``."""
    if not isinstance(data, dict):
        raise InputError(f"{source}: expected a table of settings, got {type(data).__name__}")
    extra = set(data) - _KEYS
    if extra:
        raise InputError(f"{source}: unknown key(s) {sorted(extra)}; valid: {sorted(_KEYS)}")
    for key in ("name", "urdf", "base_frame", "footprint", "arms"):
        if key not in data:
            raise InputError(f"{source}: missing required key {key!r}")

    def text(value: Any, key: str) -> str:
        if not isinstance(value, (str, int)) or isinstance(value, bool):
            raise InputError(f"{source}: {key} must be a name (a string), got a {type(value).__name__}")
        return str(value)

    def path_of(value: Any, key: str) -> Path:
        if not isinstance(value, str):
            raise InputError(f"{source}: {key} must be a path string")
        if value.startswith("package://"):  # a URDF or SRDF inside a ROS package, found as meshes are
            rest = value[len("package://") :]
            for d in ros_package_roots():
                if (d / rest).is_file():
                    return d / rest
            raise InputError(
                f"{source}: {key} {value} not found under {[str(d) for d in ros_package_roots()]}"
            )
        p = Path(value)
        p = p if p.is_absolute() else root / p
        if not p.exists():
            raise InputError(f"{source}: {key} {p} does not exist")
        return p

    arms_raw = data["arms"]
    if not isinstance(arms_raw, dict) or not arms_raw:
        raise InputError(f"{source}: arms must be a table of arm name -> {{joints, tcp_frame}}")
    arms = {}
    for arm_name, arm in arms_raw.items():
        if not isinstance(arm, dict) or "joints" not in arm or "tcp_frame" not in arm:
            raise InputError(f"{source}: arm {brief(arm_name)} needs 'joints' and 'tcp_frame'")
        if set(arm) - _ARM_KEYS:
            raise InputError(f"{source}: arm {brief(arm_name)}: unknown key(s) {sorted(set(arm) - _ARM_KEYS)}; "
                             f"valid: {sorted(_ARM_KEYS)}")  # fmt: skip
        joints = arm["joints"]
        if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
            raise InputError(f"{source}: arm {brief(arm_name)} joints must be a non-empty list of names")
        approach = text(arm.get("approach", "x"), "approach")
        if approach not in APPROACH_AXES:
            raise unknown("TCP approach axis", approach, APPROACH_AXES, f"{source}: arm {brief(arm_name)}")
        grasp_frame = None if "grasp_frame" not in arm else text(arm["grasp_frame"], "grasp_frame")
        arms[text(arm_name, "an arm name")] = ArmSpec(
            tuple(joints), text(arm["tcp_frame"], "tcp_frame"), approach, grasp_frame
        )

    fp = data["footprint"]
    if not isinstance(fp, dict) or len(fp) != 1 or next(iter(fp)) not in ("radius", "polygon"):
        raise InputError(f"{source}: footprint must be {{radius = R}} or {{polygon = [[x, y], ...]}}")
    radius = polygon = None
    try:
        if "radius" in fp:
            radius = float(fp["radius"])
        else:
            polygon = tuple((float(x), float(y)) for x, y in fp["polygon"])
        limits = {
            text(k, "a joint name"): (float(v[0]), float(v[1]))
            for k, v in data.get("joint_limits", {}).items()
        }
        reference = {text(k, "a joint name"): float(v) for k, v in data.get("reference", {}).items()}
    except (TypeError, ValueError, IndexError, AttributeError):
        raise InputError(f"{source}: footprint, joint_limits and reference must hold numbers") from None

    mount = _mount(data.get("mount"), source)
    dirs = data.get("package_dirs", [])
    if not isinstance(dirs, list):
        raise InputError(f"{source}: package_dirs must be a list of directories")
    return RobotSpec(
        name=text(data["name"], "name"),
        urdf=path_of(data["urdf"], "urdf"),
        srdf=path_of(data["srdf"], "srdf") if data.get("srdf") else None,
        base_frame=text(data["base_frame"], "base_frame"),
        arms=arms,
        default_arm=text(data.get("default_arm", next(iter(arms))), "default_arm"),
        footprint_radius=radius,
        footprint_polygon=polygon,
        package_dirs=tuple(path_of(d, "package_dirs entry") for d in dirs) or (root,),
        joint_limits=limits,
        reference=reference,
        mount=mount,
    )


def _mount(raw: Any, source: str) -> Mount | None:
    if raw is None:
        return None
    if not isinstance(raw, dict) or set(raw) - _MOUNT_KEYS:
        raise InputError(f"{source}: mount must be a table with keys {sorted(_MOUNT_KEYS)}")
    try:
        xyz = tuple(float(v) for v in raw.get("xyz", (0.0, 0.0, 0.0)))
        rpy = tuple(float(v) for v in raw.get("rpy", (0.0, 0.0, 0.0)))
        height = raw.get("base_height")
        height = None if height is None else float(height)
    except (TypeError, ValueError):
        raise InputError(f"{source}: mount xyz, rpy and base_height must hold numbers") from None
    try:
        return Mount(xyz, rpy, height)  # type: ignore[arg-type]
    except InputError as exc:
        raise InputError(f"{source}: {exc}") from None
