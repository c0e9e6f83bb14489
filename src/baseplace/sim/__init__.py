"""Generated scenes with exact ground truth: planes, boxes and objects, their clouds and depth images.

A library feature, not an experiment: the demo builds its scene here, and tests and benchmarks use
the exact geometry as their oracle. The papers' experiments built on these scenes live in
:mod:`baseplace_experiments`.
"""

from baseplace.sim.scenes import (
    NONPLANAR,
    OUTSIDE,
    SIZE_CLASSES,
    Box,
    Plane,
    Scene,
    SceneObject,
    SceneSettings,
    generate_scene,
    load_scene,
    save_scene,
    truth_grid,
)

__all__ = [
    "NONPLANAR",
    "OUTSIDE",
    "SIZE_CLASSES",
    "Box",
    "Plane",
    "Scene",
    "SceneObject",
    "SceneSettings",
    "generate_scene",
    "load_scene",
    "save_scene",
    "truth_grid",
]
