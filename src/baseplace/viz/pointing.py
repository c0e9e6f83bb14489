"""A picture of a ``point`` result: the frame with the hand, the line, the objects, and the candidates."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from numpy.typing import NDArray

from baseplace.files import atomic_write

BONES = ((0, 1), (1, 2), (2, 3), (3, 4), (0, 5), (5, 6), (6, 7), (7, 8), (5, 9), (9, 10), (10, 11), (11, 12),
         (9, 13), (13, 14), (14, 15), (15, 16), (13, 17), (0, 17), (17, 18), (18, 19), (19, 20))  # fmt: skip
"""MediaPipe's hand connections."""


OBJECT_RGB = (60, 220, 60)
SELECTED_RGB = (255, 200, 0)
RAY_RGB = (0, 160, 255)
HAND_RGB = (255, 40, 40)


def annotated_image(
    rgb: NDArray[np.uint8],
    landmarks: NDArray[np.float64] | None,
    ray_2d: NDArray[np.float64] | None,
    image_boxes: NDArray[np.float64],
    selected: int | None,
) -> NDArray[np.uint8]:
    """A copy of the frame with the objects' image boxes (the selected one thick, gold), the hand and the line.

    Args:
        rgb: (H, W, 3) the frame's image.
        landmarks: (21, 2) hand landmarks [px], or None.
        ray_2d: (2, 2) the finger's line from the fingertip to where it stops [px], or None.
        image_boxes: (K, 2, 2) ``[[u0, v0], [u1, v1]]`` [px], inclusive.
        selected: index of the chosen box, or None.
    """
    import cv2

    out = np.ascontiguousarray(rgb.copy())
    thin = max(1, round(max(out.shape[:2]) / 400))
    for k, ((u0, v0), (u1, v1)) in enumerate(np.rint(image_boxes).astype(int)):
        chosen = k == selected
        cv2.rectangle(
            out, (u0, v0), (u1, v1), SELECTED_RGB if chosen else OBJECT_RGB, 3 * thin if chosen else thin
        )
    if landmarks is not None:
        L = np.rint(landmarks).astype(int)
        for a, b in BONES:
            cv2.line(out, tuple(L[a]), tuple(L[b]), (255, 255, 255), thin, cv2.LINE_AA)
        for p in L:
            cv2.circle(out, tuple(p), 2 * thin, HAND_RGB, -1, cv2.LINE_AA)
    if ray_2d is not None:
        a, b = np.rint(ray_2d).astype(int)
        cv2.line(out, tuple(a), tuple(b), RAY_RGB, 2 * thin, cv2.LINE_AA)
    return out


def plot_point(rgb: NDArray[np.uint8], report: dict[str, Any], out: Path) -> None:
    """Write a PNG of a ``point`` report over its RGB image (and, with candidates, a top view).

    Drawn on the image: the objects' image boxes (the selected one thick, gold), the hand's 21
    landmarks and bones, the index finger's line from the fingertip to where it stops. In the top
    view (world x, y [m]): the objects' footprints, the selected one gold, and the candidates
    (green arrows facing the object; the best one larger).

    Args:
        rgb: (H, W, 3) the frame's image.
        report: the ``point`` report as JSON (``report.to_json()``).
        out: PNG path (written atomically).
    """
    top = report.get("candidates") is not None
    fig, axes = plt.subplots(1, 2 if top else 1, figsize=(12.8 if top else 6.4, 5.0), dpi=110, squeeze=False)
    ax = axes[0, 0]
    ax.imshow(rgb)
    for k, obj in enumerate(report.get("objects", [])):
        (u0, v0), (u1, v1) = obj["image_box"]
        chosen = k == report.get("selected")
        ax.add_patch(plt.Rectangle((u0 - 0.5, v0 - 0.5), u1 - u0 + 1, v1 - v0 + 1, fill=False,
                                   color="gold" if chosen else "lime", linewidth=2.5 if chosen else 1.0))  # fmt: skip
    if report.get("landmarks"):
        L = np.asarray(report["landmarks"])
        for a, b in BONES:
            ax.plot(L[[a, b], 0], L[[a, b], 1], color="white", linewidth=1.0)
        ax.plot(L[:, 0], L[:, 1], "o", color="red", markersize=2.5)
    if report.get("ray_2d"):
        ray = report["ray_2d"]
        ax.plot([ray["origin"][0], ray["end"][0]], [ray["origin"][1], ray["end"][1]], color="deepskyblue",
                linewidth=1.8)  # fmt: skip
    gesture = (report.get("gesture") or {}).get("name", "no hand")
    ax.set_title(
        f"gesture {gesture}; {len(report.get('objects', []))} objects; selected {report.get('selected')}"
    )
    ax.axis("off")
    if top:
        ax = axes[0, 1]
        for k, obj in enumerate(report["objects"]):
            (x0, y0, _), (x1, y1, _) = obj["box_world"]
            chosen = k == report.get("selected")
            ax.add_patch(plt.Rectangle((x0, y0), x1 - x0, y1 - y0, color="gold" if chosen else "grey"))
        for i, c in enumerate(report["candidates"]):
            size = 0.2 if i == 0 else 0.12
            ax.arrow(c["x"], c["y"], size * np.cos(c["yaw"]), size * np.sin(c["yaw"]), color="green",
                     width=0.015 if i == 0 else 0.008, length_includes_head=True)  # fmt: skip
        if report.get("path"):
            path = np.asarray(report["path"])
            ax.plot(path[:, 0], path[:, 1], color="dodgerblue", linewidth=1.5)
        ax.set_aspect("equal")
        ax.autoscale()
        ax.set_xlabel("x [m]")
        ax.set_ylabel("y [m]")
        ax.set_title(f"{len(report['candidates'])} candidates to pick it up (world, top view)")
    fig.tight_layout()
    with atomic_write(out, "plot") as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


__all__ = ["annotated_image", "plot_point"]
