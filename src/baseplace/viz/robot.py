"""A robot's collision geometry in two views, for ``baseplace robot check``.

Side (x-z) and top (x-y) views in the base frame at the reference configuration: the base's
geometry in grey, the arms' in blue, the footprint outline, and each TCP with its approach axis
as a red arrow (the direction a grasp comes from). Written offscreen (Agg), atomically.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import PolyCollection

from baseplace.files import atomic_write
from baseplace.robots.check import CollisionMesh
from baseplace.robots.model import Robot

MAX_TRIANGLES = 60_000
"""Triangles drawn per view at most (a uniform subset beyond): enough for a silhouette."""
ARROW = 0.15
"""Length [m] of a TCP's approach arrow."""


def plot_robot(robot: Robot, meshes: list[CollisionMesh], path: str | Path) -> Path:
    """Write the side and top views of ``robot`` (meshes from :func:`~baseplace.robots.check.collision_meshes`)."""
    spec = robot.spec
    fig, axes = plt.subplots(1, 2, figsize=(12, 6), layout="constrained")
    total = sum(len(m.faces) for m in meshes)
    step = max(1, total // MAX_TRIANGLES)
    data = robot.model.createData()
    import pinocchio as pin

    pin.framesForwardKinematics(robot.model, data, robot.q_reference)
    T_base_root = data.oMf[robot.model.getFrameId(spec.base_frame)].inverse()
    for ax, (i, j), title in zip(axes, [(0, 2), (0, 1)], ["side view (x-z)", "top view (x-y)"], strict=True):
        for on_arm, colour in ((False, "0.55"), (True, "tab:blue")):
            tris = [m.vertices[m.faces[::step]][:, :, [i, j]] for m in meshes if m.on_arm == on_arm]
            if tris:
                ax.add_collection(
                    PolyCollection(
                        list(np.concatenate(tris)),
                        facecolors=colour,
                        edgecolors="none",
                        alpha=0.35,
                        rasterized=True,
                    )
                )
        if j == 1:
            if spec.footprint_radius is not None:
                t = np.linspace(0, 2 * np.pi, 100)
                outline = spec.footprint_radius * np.c_[np.cos(t), np.sin(t)]
            else:
                outline = np.array(
                    [*(spec.footprint_polygon or ()), (spec.footprint_polygon or ((0, 0),))[0]]
                )
            ax.plot(outline[:, 0], outline[:, 1], "k--", lw=1.2, label="footprint")
        else:
            ax.axhline(0.0, color="k", lw=0.8)
        for name in spec.arms:
            arm = robot.arm(name)
            T = (T_base_root * data.oMf[robot.model.getFrameId(arm.tcp_frame)]).homogeneous
            p, d = T[:3, 3], T[:3, :3] @ arm.approach_axis
            ax.annotate("", xy=(p[i] + ARROW * d[i], p[j] + ARROW * d[j]), xytext=(p[i], p[j]),
                        arrowprops={"arrowstyle": "->", "color": "tab:red", "lw": 2})  # fmt: skip
            ax.plot(p[i], p[j], "o", color="tab:red", ms=4)
            ax.text(p[i], p[j], f" {arm.tcp_frame} ({spec.arm(name).approach})", fontsize=8, color="tab:red")
        ax.plot(0, 0, "k+", ms=12)
        ax.autoscale_view()
        ax.set_aspect("equal", adjustable="datalim")
        ax.set_xlabel("x [m]")
        ax.set_ylabel("z [m]" if j == 2 else "y [m]")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{spec.name}: collision geometry in {spec.base_frame} at the reference configuration; "
                 "red: TCP approach axes")  # fmt: skip
    path = Path(path)
    try:
        with atomic_write(path, "PNG") as tmp:
            fig.savefig(tmp, format="png", dpi=100)
    finally:
        plt.close(fig)
    return path
