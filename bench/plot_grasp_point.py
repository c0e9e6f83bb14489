"""Draw docs/img/grasp_point.png: a robot's TCP frame, its grasp point and its fingertips.

``python bench/plot_grasp_point.py [--robot tiago] [--out docs/img/grasp_point.png]``

Everything is read from the robot's URDF with pinocchio at its reference configuration, in the
arm's TCP frame: the TCP (where ``--target`` puts the hand), the spec's ``grasp_frame`` (where
``--grasp-point`` puts it) and the hand's collision geometry, whose points farthest along the
approach axis are the fingertips.
"""

from __future__ import annotations

import argparse

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
import pinocchio as pin

from baseplace.robots.collision import load_collision_model
from baseplace.robots.model import Robot


def hand_points(robot: Robot, T_world_tcp: pin.SE3, q: np.ndarray) -> dict[str, np.ndarray]:
    """Collision-geometry vertices (or box corners) of the links beyond the TCP, in the TCP frame."""
    import coal

    geom = load_collision_model(robot)
    data, gdata = robot.model.createData(), None
    pin.framesForwardKinematics(robot.model, data, q)
    gdata = pin.GeometryData(geom)
    pin.updateGeometryPlacements(robot.model, data, geom, gdata)
    tcp_joint = robot.model.frames[robot.model.getFrameId(robot.spec.arm().tcp_frame)].parentJoint
    points: dict[str, np.ndarray] = {}
    for k, obj in enumerate(geom.geometryObjects):
        if tcp_joint not in list(robot.model.supports[obj.parentJoint]):  # not on the hand
            continue
        shape = obj.geometry
        if isinstance(shape, coal.BVHModelBase):
            local = np.asarray(shape.vertices())
        elif isinstance(shape, coal.Box):
            h = np.asarray(shape.halfSide)
            local = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * h
        else:
            continue
        M = T_world_tcp.inverse() * gdata.oMg[k]
        points[obj.name] = local @ M.rotation.T + M.translation
    return points


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robot", default="tiago")
    parser.add_argument("--out", default="docs/img/grasp_point.png")
    args = parser.parse_args()

    robot = Robot(args.robot)
    arm = robot.spec.arm()
    q = robot.q_reference
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    T_world_tcp = data.oMf[robot.model.getFrameId(arm.tcp_frame)]
    grasp = robot.T_tcp_grasp()[:3, 3]
    points = hand_points(robot, T_world_tcp, q)
    fingers = {n: p for n, p in points.items() if "safety" not in n}
    every = np.vstack(list(fingers.values()))
    tip = every[np.argmax(every[:, 0])]

    fig, axes = plt.subplots(1, 2, figsize=(12, 5.2))
    for ax, (i, j, name) in zip(
        axes, [(0, 2, "side view (TCP x-z)"), (0, 1, "top view (TCP x-y)")], strict=True
    ):
        for link, p in points.items():
            if "safety" in link:
                lo, hi = p.min(axis=0), p.max(axis=0)
                ax.add_patch(plt.Rectangle((lo[i], lo[j]), hi[i] - lo[i], hi[j] - lo[j], fill=False,
                                           ec="tab:red", lw=1, ls=":"))  # fmt: skip
            else:
                ax.scatter(p[:, i], p[:, j], color="0.6", s=0.3)
        ax.annotate(
            "", xy=(0.06, 0), xytext=(0, 0), arrowprops={"arrowstyle": "->", "color": "tab:red", "lw": 2}
        )
        ax.annotate("", xy=(0, 0.06), xytext=(0, 0), arrowprops={"arrowstyle": "->",
                    "color": "tab:blue" if j == 2 else "tab:green", "lw": 2})  # fmt: skip
        ax.plot(0, 0, "ko", ms=7)
        ax.text(-0.005, -0.01, f"TCP {arm.tcp_frame}\n(--target)", fontsize=8, va="top", ha="right")
        ax.plot(grasp[i], grasp[j], "*", color="tab:orange", ms=16, mec="k")
        ax.annotate(f"grasp point {arm.grasp_frame}\n(--grasp-point): {grasp[0]:.3f} m ahead",
                    (grasp[i], grasp[j]), (0.09, -0.11), fontsize=8, arrowprops={"arrowstyle": "-", "lw": 0.6})  # fmt: skip
        ax.plot(tip[i], tip[j], "v" if j == 2 else "s", color="tab:purple", ms=8, mec="k")
        ax.annotate(f"fingertips: {tip[0]:.3f} m ahead", (tip[i], tip[j]), (0.2, 0.12), fontsize=8,
                    arrowprops={"arrowstyle": "-", "lw": 0.6})  # fmt: skip
        ax.axvline(grasp[0], color="tab:orange", lw=0.6, ls="--")
        ax.axvline(tip[0], color="tab:purple", lw=0.6, ls="--")
        ax.set_xlabel(f"x [m]: approach axis ({arm.approach})")
        ax.set_ylabel("z [m]" if j == 2 else "y [m]")
        ax.set_title(name, fontsize=10)
        ax.set_xlim(-0.08, 0.32)
        ax.set_ylim(-0.16, 0.16)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
    fig.suptitle(f"{robot.name}: the hand at its reference configuration, in the TCP frame "
                 "(grey: collision geometry, red: hand safety box)", fontsize=10)  # fmt: skip
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"wrote {args.out}: grasp point {np.round(grasp, 4).tolist()} m, fingertips {tip[0]:.3f} m ahead")


if __name__ == "__main__":
    main()
