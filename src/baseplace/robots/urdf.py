"""The URDF a robot file describes: its meshes found, and an arm mounted on its mobile base.

A robot file names a URDF; this module turns it into the URDF text that pinocchio, coal and the
viewer load:

* every mesh URI (``package://``, ``file://``, relative or absolute) is resolved to an absolute
  path, searching the robot file's ``package_dirs`` and then folders found automatically: the
  URDF's ancestors that are, or hold, the referenced package, ``ROS_PACKAGE_PATH``,
  ``AMENT_PREFIX_PATH``'s ``share`` folders and example-robot-data's share folder. A collision
  mesh found nowhere is a one-line error at load time, not a failure in the first collision check;
* with a ``[mount]``, the URDF's root link is attached to a new mobile-base link ``base_frame`` at
  the mount pose, and the base gets a collision body from its footprint: no wrapper URDF.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from xml.etree import ElementTree

from baseplace.errors import InputError, brief
from baseplace.guards import check_file_size
from baseplace.robots.spec import BASE_CLEARANCE, RobotSpec, ros_package_roots

PACKAGE = "package://"
FILE = "file://"

MAX_URDF_BYTES = 16 * 2**20
"""The largest URDF file read (a robot's URDF with inline meshes' names is a few hundred kB)."""
MAX_LINKS = MAX_JOINTS = 512
"""The most links and joints of a URDF (TIAGo dual has 130 links, PR2 82)."""
MAX_CHAIN_DEPTH = 256
"""The most joints from the root link to any link (a 7-joint arm on a torso is about 20)."""
MAX_XML_DEPTH = 64
"""The deepest nesting of XML elements (a URDF nests 5: robot, link, visual, geometry, mesh)."""


@dataclass(frozen=True)
class RobotUrdf:
    """The URDF text of a robot file, ready to load.

    Attributes:
        xml: the URDF with absolute mesh paths (and the mount, if any).
        package_dirs: the folders searched for ``package://`` URIs, in order.
        root_link: the root link of the file's URDF (before mounting).
        missing_visual: visual mesh URIs found nowhere (collision meshes must all be found).
    """

    xml: str
    package_dirs: tuple[Path, ...]
    root_link: str
    missing_visual: tuple[str, ...] = ()


def check_urdf_file(path: Path) -> None:
    """Refuse a URDF file over :data:`MAX_URDF_BYTES` before it is read.

    Raises:
        InputError: one line with the size and the limit.
    """
    check_file_size(path, "URDF", MAX_URDF_BYTES)


def check_xml_depth(root: ElementTree.Element, what: str, usual: int) -> None:
    """Refuse XML nested over :data:`MAX_XML_DEPTH` elements deep (checked without recursion).

    ``what`` names the file in the message ("URDF path"), ``usual`` how deep such a file nests.
    C++ parsers (urdfdom's, pinocchio's SRDF reader) recurse once per level: a deep file
    exhausts their stack.
    """
    stack = [(root, 1)]
    while stack:
        element, depth = stack.pop()
        if depth > MAX_XML_DEPTH:
            raise InputError(f"{what}: XML elements nested over {MAX_XML_DEPTH} deep; a {what.split()[0]} "
                             f"nests {usual}")  # fmt: skip
        stack.extend((child, depth + 1) for child in element)


def check_urdf_tree(robot: ElementTree.Element, path: Path) -> None:
    """Refuse a URDF whose size or kinematic depth no robot has, before pinocchio or a viewer walks it.

    pinocchio's and urdfdom's parsers recurse once per joint of a chain, and a deep chain
    exhausts the C stack (a segfault) or memory; the limits (:data:`MAX_LINKS`,
    :data:`MAX_JOINTS`, :data:`MAX_CHAIN_DEPTH`, :data:`MAX_XML_DEPTH`) are checked here
    without recursion.

    Raises:
        InputError: one line naming the count and the limit, or a joint cycle.
    """
    check_xml_depth(robot, f"URDF {path}", 5)
    n_links, joints = len(robot.findall("link")), robot.findall("joint")
    for what, count, limit in (("links", n_links, MAX_LINKS), ("joints", len(joints), MAX_JOINTS)):
        if count > limit:
            raise InputError(f"URDF {path} has {count} {what}; the limit is {limit}")
    parent_of: dict[str | None, str | None] = {}
    for joint in joints:
        child, parent = joint.find("child"), joint.find("parent")
        if child is not None and parent is not None:
            parent_of[child.get("link")] = parent.get("link")
    depth_of: dict[str | None, int] = {}
    for link in parent_of:
        chain: list[str | None] = []
        node: str | None = link
        while node in parent_of and node not in depth_of:
            chain.append(node)
            if len(chain) > len(parent_of):
                raise InputError(f"URDF {path}: the joints form a cycle through link {brief(node, 60)}")
            node = parent_of[node]
        base = depth_of.get(node, 0)
        for k, name in enumerate(reversed(chain), start=1):
            depth_of[name] = base + k
        if depth_of.get(link, 0) > MAX_CHAIN_DEPTH:
            raise InputError(
                f"URDF {path}: link {brief(link, 60)} is {depth_of[link]} joints from the root; "
                f"the limit is {MAX_CHAIN_DEPTH}"
            )


def _package_name(uri: str) -> str:
    return uri[len(PACKAGE) :].split("/", 1)[0]


def package_search_dirs(urdf: Path, explicit: Sequence[Path], packages: Iterable[str]) -> tuple[Path, ...]:
    """Folders where ``package://NAME/...`` may resolve, explicit ones first (no duplicates).

    Found automatically: an ancestor of the URDF called NAME (its parent is the package root),
    an ancestor holding a folder NAME, every ``ROS_PACKAGE_PATH`` entry, ``share`` under every
    ``AMENT_PREFIX_PATH`` entry, and example-robot-data's share folder.
    """
    names = set(packages)
    found: list[Path] = list(explicit)
    for ancestor in (urdf.resolve().parent, *urdf.resolve().parent.parents):
        if ancestor.name in names:
            found.append(ancestor.parent)
        if any((ancestor / name).is_dir() for name in names):
            found.append(ancestor)
    found.extend(ros_package_roots())
    unique: dict[Path, None] = {}
    for d in found:
        unique.setdefault(d, None)
    return tuple(unique)


def resolve_mesh(uri: str, urdf_dir: Path, package_dirs: Sequence[Path]) -> Path | None:
    """The file a mesh URI names, or None where it is found nowhere.

    ``package://NAME/rest`` is ``DIR/NAME/rest`` for the first of ``package_dirs`` that has it
    (or ``DIR/rest``, for a folder that is the package itself, as pinocchio also accepts);
    ``file://`` and absolute paths are taken as they are; relative paths resolve against the
    URDF's folder.
    """
    if uri.startswith(PACKAGE):
        rest = uri[len(PACKAGE) :]
        tail = rest.split("/", 1)[1] if "/" in rest else rest
        for d in package_dirs:
            for candidate in (d / rest, d / tail):
                if candidate.is_file():
                    return candidate.resolve()
        return None
    path = Path(uri[len(FILE) :]) if uri.startswith(FILE) else Path(uri)
    path = path if path.is_absolute() else urdf_dir / path
    return path.resolve() if path.is_file() else None


def _fmt(values: Sequence[float]) -> str:
    return " ".join(f"{v:.17g}" for v in values)


def _base_link(spec: RobotSpec) -> ElementTree.Element:
    """The mobile base link of a mounted arm, with a collision body from the footprint."""
    assert spec.mount is not None
    link = ElementTree.Element("link", name=spec.base_frame)
    top = spec.mount.body_top
    if top <= BASE_CLEARANCE:
        return link
    height = top - BASE_CLEARANCE
    if spec.footprint_radius is not None:
        centre, shape = (
            (0.0, 0.0),
            ElementTree.Element("cylinder", radius=f"{spec.footprint_radius:.17g}", length=f"{height:.17g}"),
        )
    else:
        assert spec.footprint_polygon is not None
        xs, ys = zip(*spec.footprint_polygon, strict=True)
        centre = ((max(xs) + min(xs)) / 2, (max(ys) + min(ys)) / 2)
        shape = ElementTree.Element("box", size=_fmt((max(xs) - min(xs), max(ys) - min(ys), height)))
    for kind in ("visual", "collision"):
        element = ElementTree.SubElement(link, kind, name="mobile_base_body")
        ElementTree.SubElement(
            element, "origin", xyz=_fmt((*centre, BASE_CLEARANCE + height / 2)), rpy="0 0 0"
        )
        ElementTree.SubElement(element, "geometry").append(shape)
    return link


def robot_urdf(spec: RobotSpec) -> RobotUrdf:
    """The URDF text of ``spec``: absolute mesh paths, and the arm on its base if it has a mount.

    Raises:
        InputError: a file, chain or tree over the limits (:func:`check_urdf_file`,
            :func:`check_urdf_tree`), malformed XML, a URDF without exactly one root link, a
            collision mesh found in none of the package folders, or a mount whose
            ``base_frame`` is already a link.
    """
    check_urdf_file(spec.urdf)
    try:
        tree = ElementTree.parse(spec.urdf)
    except ElementTree.ParseError as exc:
        raise InputError(f"cannot parse URDF {spec.urdf}: malformed XML ({exc})") from None
    except OSError as exc:
        raise InputError(f"cannot read URDF {spec.urdf}: {exc.strerror or exc}") from None
    robot = tree.getroot()
    if robot.tag != "robot":
        raise InputError(f"cannot parse URDF {spec.urdf}: its root element is <{robot.tag}>, not <robot>")
    check_urdf_tree(robot, spec.urdf)
    links = [link.get("name", "") for link in robot.findall("link")]
    children = {child.get("link") for child in robot.findall("joint/child")}
    roots = [name for name in links if name not in children]
    packages = {
        _package_name(m.get("filename", ""))
        for m in robot.iter("mesh")
        if m.get("filename", "").startswith(PACKAGE)
    }
    dirs = package_search_dirs(spec.urdf, spec.package_dirs, packages)
    missing_visual: list[str] = []
    for link in robot.findall("link"):
        for kind in ("collision", "visual"):
            for mesh in link.findall(f"{kind}/geometry/mesh"):
                uri = mesh.get("filename", "")
                path = resolve_mesh(uri, spec.urdf.parent, dirs)
                if path is not None:
                    mesh.set("filename", str(path))
                elif kind == "visual":
                    missing_visual.append(uri)
                else:
                    where = ", ".join(str(d) for d in dirs[:4]) + (" ..." if len(dirs) > 4 else "")
                    hint = (
                        f"add the folder holding '{_package_name(uri)}' to package_dirs"
                        if uri.startswith(PACKAGE)
                        else "fix the path (relative paths start at the URDF's folder)"
                    )
                    raise InputError(
                        f"robot {spec.name!r}: collision mesh {uri!r} of link {link.get('name')!r} not found "
                        f"(searched {where}); {hint}"
                    )
    root_link = roots[0] if len(roots) == 1 else ""
    if spec.mount is not None:
        if len(roots) != 1:
            raise InputError(
                f"cannot mount URDF {spec.urdf}: it needs exactly one root link to attach, found {roots[:5]}"
            )
        if spec.base_frame in links:
            raise InputError(
                f"robot {spec.name!r}: with a mount, base_frame names the new mobile-base link, but "
                f"{spec.base_frame!r} is already a link of {spec.urdf.name}; choose another name"
            )
        joint = ElementTree.Element("joint", name=f"{spec.base_frame}_mount_joint", type="fixed")
        ElementTree.SubElement(joint, "parent", link=spec.base_frame)
        ElementTree.SubElement(joint, "child", link=root_link)
        ElementTree.SubElement(joint, "origin", xyz=_fmt(spec.mount.xyz), rpy=_fmt(spec.mount.rpy))
        robot.insert(0, joint)
        robot.insert(0, _base_link(spec))
    xml = ElementTree.tostring(robot, encoding="unicode")
    return RobotUrdf(xml, dirs, root_link, tuple(missing_visual))
