"""Simulated scenes with exact ground truth and the experiment runners built on them."""

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
