"""The main job on built-in defaults: see :mod:`baseplace.jobs.demo` (kept for existing imports).

The map cache moved to :mod:`baseplace.reachability.cache`.
"""

from baseplace.jobs.demo import DEMO_START, DEMO_TARGET, demo_scene
from baseplace.reachability.cache import cached_map

__all__ = ["DEMO_START", "DEMO_TARGET", "cached_map", "demo_scene"]
