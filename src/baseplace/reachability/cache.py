"""The per-user cache of default reachability maps, and "the given map, or the cached default".

A map is keyed by robot, arm, URDF hash and build settings; the file name is a hash, so no name
from a robot file ever becomes part of a path. The first use builds the map (tens of seconds,
resumable: a killed build continues from its checkpoint) and every later use loads it. The first
load stores it again without compression (TIAGo's: 40 MB instead of 3.6 MB), which every later
command opens in 0.07 s instead of 0.22 s (a new process per command pays it each time).
"""

from __future__ import annotations

import hashlib
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from baseplace.errors import InputError
from baseplace.files import OutputError, cache_root, private_dir, skip_cache_entry
from baseplace.reachability.settings import BuildSettings
from baseplace.reachability.storage import FORMAT_VERSION, is_compressed, load_map, save_map
from baseplace.status import map_step, step_progress

if TYPE_CHECKING:
    from baseplace.reachability.rmap import ReachabilityMap
    from baseplace.robots.model import Robot


def cached_map_path(robot: Robot, settings: BuildSettings, arm: str | None = None) -> Path:
    """Where the cache keeps the map of ``robot``'s ``arm`` (default arm) built with ``settings``."""
    arm_name = arm or robot.spec.default_arm
    key = (
        f"{robot.name}-{arm_name}-{robot.spec.urdf_sha256[:12]}-s{settings.samples}-seed{settings.seed}"
        f"-v{settings.voxel_size}-o{settings.orientation_resolution}-f{FORMAT_VERSION}"
    )
    # settings that change the cells: part of the key only when set, so default maps keep their files
    for name in ("self_collision", "manipulability", "certify", "support_threshold"):
        if getattr(settings, name):
            key += f"-{name}{getattr(settings, name)}"
    return cache_root() / "maps" / f"map-{hashlib.sha256(key.encode()).hexdigest()[:32]}.rmap"


def cached_map(
    robot: Robot,
    settings: BuildSettings,
    arm: str | None = None,
    progress: Callable[[int], None] | None = None,
) -> tuple[ReachabilityMap, Path, bool]:
    """Load the map for these settings from the cache, building and saving it if absent.

    Args:
        robot: the robot.
        settings: the build settings (part of the cache key).
        arm: the arm (None: the robot's default arm).
        progress: called with the samples done so far while a map is built.

    Returns:
        (map, path, built) where built tells whether it was built now; with the cache's disk
        full, the map is built and returned but not stored at ``path`` (a one-line warning,
        :class:`~baseplace.files.CacheSkipped`).
    """
    arm_name = arm or robot.spec.default_arm
    path = cached_map_path(robot, settings, arm_name)
    if path.is_file():
        rmap = load_map(path, robot, arm_name)
        if is_compressed(path):  # built (or cached by an older baseplace) with gzip: store it plain once
            try:
                save_map(rmap, path, compress=False)
            except OutputError as exc:
                skip_cache_entry("the uncompressed map", path.parent, exc)
            except (OSError, InputError):
                pass  # a read-only cache opens slower, nothing else
        return rmap, path, False
    from baseplace.reachability.build import build_map  # a query that loads the map never builds one
    from baseplace.reachability.checkpoint import default_checkpoint_path

    try:
        private_dir(path.parent)
    except OutputError as exc:  # no room for the folder: the map is built all the same
        skip_cache_entry("the map", path.parent, exc)
        return build_map(robot, arm_name, settings, progress), path, True
    # build_map locks the entry: a second process waits, then reuses the first one's map. A full
    # disk skips the checkpoints and the entry, not the map.
    rmap = build_map(
        robot, arm_name, settings, progress, default_checkpoint_path(path), save_to=path, cache=True
    )
    return rmap, path, True


DEFAULT_MAP = "default"
"""The name a ``--map`` option takes for the robot's cached default map (as if no map were given)."""


@dataclass(frozen=True)
class MapChoice:
    """The map a job uses: the given file or object, or the cached default.

    Attributes:
        rmap: the map.
        cached_at: where the cache keeps the default map (None: a map was given).
        built: whether the default map was built now (first run).
    """

    rmap: ReachabilityMap
    cached_at: Path | None = None
    built: bool = False


def resolve_map(
    robot: Robot,
    rmap: ReachabilityMap | str | Path | None,
    arm: str | None = None,
    progress: Callable[[str, int, int], None] | None = None,
    settings: BuildSettings | None = None,
) -> MapChoice:
    """The map given (loaded, or a file checked against ``robot`` and ``arm``), else the cached default.

    ``rmap`` None or ``"default"`` is the robot's cached default map, built on first use with
    ``settings`` (None: :class:`BuildSettings`' defaults); its build reports to
    ``progress(step, done, total)`` under one step per arm, with the build's sample count. Every
    job and the service find their maps here.

    Raises:
        InputError: the file is missing, corrupt, or built for another robot or arm.
    """
    from baseplace.reachability.rmap import ReachabilityMap

    if isinstance(rmap, ReachabilityMap):
        if arm is not None and rmap.info.arm != arm:
            raise InputError(f"the map was built for arm {rmap.info.arm!r}, not {arm!r}")
        return MapChoice(rmap)
    if rmap is not None and str(rmap) != DEFAULT_MAP:
        return MapChoice(load_map(rmap, robot, arm))
    settings = settings or BuildSettings()
    arm_name = arm or robot.spec.default_arm
    update = step_progress(progress, map_step(robot.name, arm_name), settings.samples)
    loaded, path, built = cached_map(robot, settings, arm_name, update)
    return MapChoice(loaded, path, built)


def map_or_default(
    robot: Robot,
    rmap: ReachabilityMap | str | Path | None,
    arm: str | None = None,
    progress: Callable[[str, int, int], None] | None = None,
) -> ReachabilityMap:
    """:func:`resolve_map`'s map alone."""
    return resolve_map(robot, rmap, arm, progress).rmap
