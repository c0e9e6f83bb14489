"""Seed 004's pointing application on generated RGB-D scenes (issue 30's must-show).

The protocol is docs/protocols/pointing_v3.md (v2: pointing_v2.md, v1: pointing.md), committed before
the held-out run; in short: each
seed's frame (:func:`~baseplace.sim.pointing_scenes.generate_pointing_scene`, default settings) is
written to files as a camera would deliver it (RGB PNG, 16-bit depth PNG in millimetres, MediaPipe
landmarks JSON, the camera's pose) and read back by the ``point`` job, exactly as
``baseplace point --landmarks`` runs, with the primary rule (``finger3d``); the other rules
(``first``, the seed's, and ``nearest``) choose among the same objects on the same frame. A scene is
**selected** when the job exits 0 and the selected
object's position lies nearer (horizontally) to the target's true centre than to any other true
object's; its **position error** is the 3-D distance from the reported position (the centre of the
object's world box, its bottom on the support plane) to the target's true centre. Rates are given
with Wilson 95 % intervals.
"""

from __future__ import annotations

import math
import tempfile
import time
from collections import Counter
from collections.abc import Sequence
from typing import Any

import numpy as np

from baseplace.errors import BaseplaceError
from baseplace.jobs.point import PointJob, point_job
from baseplace.jobs.report import NoResultError, Report
from baseplace.perception.selection import SELECTION_RULES
from baseplace.sim.pointing_scenes import PointingSceneSettings, generate_pointing_scene, save_pointing_scene
from baseplace_experiments.results import SeedSplit

SEEDS = SeedSplit(dev=tuple(range(600)), held_out=tuple(range(30_000, 30_250)))
"""600 development scenes to choose parameters (v2's 0-99 and 100-599); 250 held-out scenes for the report (protocol v3)."""
HELD_OUT_V1 = tuple(range(10_000, 10_250))
"""Protocol v1's held-out scenes, run once (docs/protocols/pointing.md): spent, never to be used again."""
HELD_OUT_V2 = tuple(range(20_000, 20_250))
"""Protocol v2's held-out scenes, run once (docs/protocols/pointing_v2.md): spent, never to be used again."""
PRIMARY_RULE = "finger3d"
"""The rule the job runs with (the protocol's primary); the others are measured beside it."""
POSITION_TOLERANCE = 0.02
"""A selected object's reported position within this [m] of the truth counts (the issue's 2 cm)."""


def wilson(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson score interval (lower, upper) of a binomial rate; (0, 1) for n = 0."""
    if n == 0:
        return 0.0, 1.0
    p = successes / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / (1 + z * z / n)
    return max(0.0, centre - half), min(1.0, centre + half)


def run_scene(seed: int, settings: PointingSceneSettings | None = None) -> dict[str, Any]:
    """One scene through the ``point`` job: its outcome, selection and position error."""
    scene = generate_pointing_scene(seed, settings)
    truth = [o.centre for o in scene.objects]
    with tempfile.TemporaryDirectory() as folder:
        files = save_pointing_scene(scene, folder)
        job = PointJob(files["rgb"], files["depth"], files["intrinsics"], files["transform"], files["landmarks"],
                       selection=PRIMARY_RULE)  # fmt: skip
        t0 = time.perf_counter()
        report: Report
        try:
            report = point_job(job)
            outcome = "ok"
        except NoResultError as exc:
            report, outcome = exc.report, str(exc).split(":")[0]
        except BaseplaceError as exc:  # an input error on a generated scene is a bug of the experiment
            raise RuntimeError(f"scene {seed}: {exc}") from exc
        seconds = time.perf_counter() - t0
        row: dict[str, Any] = {"seed": seed, "objects": len(truth), "found": len(report.to_json()["objects"]),
                               "outcome": outcome, "selected": False, "error_m": None, "seconds": round(seconds, 3)}  # fmt: skip
        obj = report.to_json()
        if outcome == "ok" and obj["object"] is not None:
            row["picked"] = _truth_of(obj, truth, obj["selected"])
            row["selected"] = row["picked"] == scene.target
            row["error_m"] = round(
                float(np.linalg.norm(np.array(obj["object"]["position"]) - truth[scene.target])), 5
            )
        row["rules"] = {PRIMARY_RULE: {"selected": row["selected"], "error_m": row["error_m"]}}
        row["rules"].update(_other_rules(obj, files, truth, scene.target))
    ray3 = obj.get("ray_3d")  # the 3-D finger line from depth (finger3d's), reported with any rule
    row["ray_3d"] = (
        None
        if ray3 is None
        else ray3["hit"] is not None and _truth_of(obj, truth, ray3["hit"]) == scene.target
    )
    return row


def _truth_of(obj: dict[str, Any], truth: list[np.ndarray], k: int) -> int:
    """The true object nearest (horizontally) to detected object ``k`` of a report."""
    p = np.array(obj["objects"][k]["position"])
    return int(np.argmin([np.hypot(*(p[:2] - c[:2])) for c in truth]))


def _other_rules(obj: dict[str, Any], files: dict[str, str], truth: list[np.ndarray],
                 target: int) -> dict[str, dict[str, Any]]:  # fmt: skip
    """The rules other than the primary on the job's objects and frame: whether each selects the target, its error [m]."""
    from baseplace.jobs.point import read_landmarks
    from baseplace.perception.rgbd import load_frame
    from baseplace.perception.selection import SELECTION_RULES, select
    from baseplace.terrain.io import load_transform

    others = [r for r in SELECTION_RULES if r != PRIMARY_RULE]
    if obj.get("ray_2d") is None:  # no Point gesture, or no support: no rule selects
        return {r: {"selected": False, "error_m": None} for r in others}
    frame = load_frame(files["rgb"], files["depth"], files["intrinsics"])
    T = load_transform(files["transform"])
    hand = read_landmarks(files["landmarks"], frame.width, frame.height)
    assert hand is not None
    points = frame.points_camera() @ T[:3, :3].T + T[:3, 3]
    image_boxes = np.array([o["image_box"] for o in obj["objects"]], dtype=float).reshape(-1, 2, 2)
    boxes_world = np.array([o["box_world"] for o in obj["objects"]], dtype=float).reshape(-1, 2, 3)
    K = frame.intrinsics
    out: dict[str, dict[str, Any]] = {}
    for rule in others:
        ray, _ = select(rule, hand[:, :2], image_boxes, boxes_world, points, T, (K.fx, K.fy, K.cx, K.cy),
                        frame.width, frame.height)  # fmt: skip
        if ray.hit is None:
            out[rule] = {"selected": False, "error_m": None}
            continue
        p = np.array(obj["objects"][ray.hit]["position"])
        out[rule] = {"selected": _truth_of(obj, truth, ray.hit) == target,
                     "error_m": round(float(np.linalg.norm(p - truth[target])), 5)}  # fmt: skip
    return out


def _rule_summary(rows: Sequence[dict[str, Any]], rule: str) -> dict[str, Any]:
    n = len(rows)
    got = [r["rules"].get(rule, {"selected": False, "error_m": None}) for r in rows]
    selected = sum(g["selected"] for g in got)
    within = sum(
        g["selected"] and g["error_m"] is not None and g["error_m"] <= POSITION_TOLERANCE for g in got
    )
    return {"selected": selected, "selection_rate": selected / n if n else None,
            "selection_wilson95": list(wilson(selected, n)), "within_2cm": within,
            "within_2cm_rate": within / n if n else None, "within_2cm_wilson95": list(wilson(within, n))}  # fmt: skip


def summarize(rows: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Selection rate and position-within-2-cm rate with Wilson 95 % intervals, failure counts."""
    n = len(rows)
    selected = sum(r["selected"] for r in rows)
    within = sum(
        r["selected"] and r["error_m"] is not None and r["error_m"] <= POSITION_TOLERANCE for r in rows
    )
    errors = [r["error_m"] for r in rows if r["selected"]]
    return {
        "scenes": n,
        "selected": selected,
        "selection_rate": selected / n if n else None,
        "selection_wilson95": list(wilson(selected, n)),
        "within_2cm": within,
        "within_2cm_rate": within / n if n else None,
        "within_2cm_wilson95": list(wilson(within, n)),
        "position_error_m": {
            "median": float(np.median(errors)) if errors else None,
            "p95": float(np.percentile(errors, 95)) if errors else None,
            "max": float(max(errors)) if errors else None,
        },
        "outcomes": dict(
            Counter(r["outcome"] if r["outcome"] != "ok" or r["selected"] else "wrong object" for r in rows)
        ),
        "primary_rule": PRIMARY_RULE,
        "rules": {rule: _rule_summary(rows, rule) for rule in SELECTION_RULES},
        "ray_3d": {
            "valid": sum(r["ray_3d"] is not None for r in rows),
            "selected": sum(bool(r["ray_3d"]) for r in rows),
        },
        "median_seconds": float(np.median([r["seconds"] for r in rows])) if rows else None,
    }


__all__ = [
    "HELD_OUT_V1",
    "HELD_OUT_V2",
    "POSITION_TOLERANCE",
    "PRIMARY_RULE",
    "SEEDS",
    "run_scene",
    "summarize",
    "wilson",
]
