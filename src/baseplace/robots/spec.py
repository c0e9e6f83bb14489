"""Robot specifications: which URDF, which base frame, which arms, which footprint.

Built-in specs use the URDFs and meshes of the ``example-robot-data`` wheel. Custom robots come
from a small TOML or YAML file::

    name = "my_arm"
    urdf = "my_arm.urdf"              # relative to this file
    srdf = "my_arm.srdf"              # optional: disabled self-collision pairs
    package_dirs = ["."]              # optional: where package:// mesh paths resolve
    base_frame = "base_link"
    footprint = { radius = 0.3 }      # or { polygon = [[x, y], ...] } in the base frame [m]
    [arms.arm]
    joints = ["joint1", "joint2"]     # the joints sampled for reachability
    tcp_frame = "tool0"
    [joint_limits]                    # optional overrides [rad or m]
    joint1 = [-1.5, 1.5]
    [reference]                       # optional values of joints not in an arm (default 0)
    head_joint = 0.2
"""

from __future__ import annotations

import hashlib
import importlib.metadata
import math
import sys
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path
from typing import Any

import yaml

from baseplace.errors import InputError, brief, unknown
from baseplace.guards import check_name

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib


@dataclass(frozen=True)
class ArmSpec:
    """One arm: the joints sampled for its reachability and its tool centre point frame.

    Attributes:
        joints: joint names; any order, they are sorted along the kinematic chain.
        tcp_frame: name of the TCP frame in the URDF.
    """

    joints: tuple[str, ...]
    tcp_frame: str


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
        package_dirs: directories where ``package://`` mesh URIs resolve.
        joint_limits: joint name -> (lower, upper) overriding the URDF [rad or m].
        reference: joint name -> value for joints outside the arm (default 0).
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
        """SHA-256 of the URDF file, recorded in maps to catch a changed robot."""
        return _sha256(self.urdf)

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
            arms={"arm": ArmSpec(("torso_lift_joint", *_TIAGO_ARM), "arm_tool_link")},
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
                "left": ArmSpec(("torso_lift_joint", *(f"l_{j}" for j in _PR2_ARM)), "l_gripper_tool_frame"),
                "right": ArmSpec(("torso_lift_joint", *(f"r_{j}" for j in _PR2_ARM)), "r_gripper_tool_frame"),
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


def load_spec(name_or_path: str | Path) -> RobotSpec:
    """A built-in robot by name, or a custom robot from a TOML or YAML file."""
    text = str(name_or_path)
    if text in BUILTIN_ROBOTS:
        return builtin_spec(text)
    path = Path(text)
    if path.suffix.lower() not in (".toml", ".yaml", ".yml"):
        raise unknown("robot", text, [*BUILTIN_ROBOTS, "<path to a .toml/.yaml robot file>"])
    if not path.is_file():
        raise InputError(f"robot file {path} does not exist")
    try:
        raw = path.read_text()
        data = tomllib.loads(raw) if path.suffix.lower() == ".toml" else yaml.safe_load(raw)
    except (tomllib.TOMLDecodeError, yaml.YAMLError, UnicodeDecodeError) as exc:
        first = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        raise InputError(f"cannot parse robot file {path}: {first}") from None
    except RecursionError:
        raise InputError(f"cannot parse robot file {path}: nested too deeply") from None
    return spec_from_dict(data, path.parent, str(path))


_KEYS = {"name", "urdf", "srdf", "package_dirs", "base_frame", "footprint", "arms", "default_arm",
         "joint_limits", "reference"}  # fmt: skip


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
        joints = arm["joints"]
        if not isinstance(joints, list) or not joints or not all(isinstance(j, str) for j in joints):
            raise InputError(f"{source}: arm {brief(arm_name)} joints must be a non-empty list of names")
        arms[text(arm_name, "an arm name")] = ArmSpec(tuple(joints), text(arm["tcp_frame"], "tcp_frame"))

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
    )
