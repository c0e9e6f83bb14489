"""Choosing a map's support settings from its own measured recall (issue 27 item 4).

The support test (:mod:`baseplace.reachability.rmap`) trades recall for precision, and how much
recall it costs depends on the samples per reached cell: at the default 2e8 samples on TIAGo the
threshold 0.8 keeps 99 % of reachable poses, at 1e7 samples only 83 %. So a map of
:data:`LADDER_FROM` samples or more does not take one fixed setting: the build measures its recall
on FK poses of its own (``certify.measure_quality``'s seed stream, disjoint from the build's
samples and from the benches' seeds) for each rung of a ladder of (support threshold, fill
threshold) settings from strict to loose, and keeps the first rung whose recall reaches
:data:`TARGET_RECALL`, or the loosest when none does (``met`` false in the record). Its precision
against IK is then measured for the kept rung. The support count keeps its rule
(``build.support_count``). Smaller maps keep the threshold they were built with.

The rungs were chosen on development data only (``bench/bench_map_precision.py --split dev`` and
the build's own stream; docs/maps.md).
"""

from __future__ import annotations

import dataclasses
import json
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from baseplace.reachability.rmap import MapInfo, ReachabilityMap
from baseplace.robots.model import Robot

LADDER_FROM = 10_000_000
"""Maps of at least this many samples choose their support settings on the ladder."""
TARGET_RECALL = 0.985
"""The recall on the build's own FK poses that a rung must reach to be kept."""


@dataclass(frozen=True)
class Rung:
    """One support setting of the ladder.

    Attributes:
        threshold: the support a pose in a reached cell needs, in (0, 1].
        fill: the support a pose in an unreached cell needs (the hole fill), in [0, 1]; 0: off.
    """

    threshold: float
    fill: float


LADDER = (
    Rung(0.8, 0.0),
    Rung(0.8, 0.5),
    Rung(0.7, 0.5),
    Rung(0.6, 0.5),
    Rung(0.5, 0.3),
    Rung(0.4, 0.3),
    Rung(0.4, 0.2),
    Rung(0.2, 0.2),
    Rung(0.2, 0.1),
)
"""From strict to loose, each rung calling reachable every pose the one before does (a threshold and a
fill no higher); a build starts at its own threshold (:func:`rungs_from`). On the dev data (TIAGo,
build seed 0) the 2e8-sample map keeps the first, 5e7 samples (0.7, 0.5), 1e7 samples (0.4, 0.3)."""


def rungs_from(threshold: float) -> list[Rung]:
    """The ladder for a build whose support threshold is ``threshold`` (> 0).

    Its own threshold without fill first, then the rungs of :data:`LADDER` that are looser
    (a lower threshold, or the same one with a fill).
    """
    first = Rung(threshold, 0.0)
    looser = [r for r in LADDER if r.threshold < threshold or (r.threshold == threshold and r.fill > 0)]
    return [first, *looser]


def built_threshold(info: MapInfo) -> float:
    """The support threshold a map was built with: its ladder's first rung, else the one it reads with."""
    quality = json.loads(info.quality) if info.quality else {}
    ladder = quality.get("ladder") if isinstance(quality, dict) else None
    return float(ladder[0]["threshold"]) if ladder else float(info.support_threshold)


def climb(
    rungs: Sequence[Rung], recall_of: Callable[[Rung], float], target: float = TARGET_RECALL
) -> tuple[int, list[float]]:
    """Index of the first rung whose recall reaches ``target`` (else the last), and the recalls measured.

    Rungs after the kept one are not measured.
    """
    recalls: list[float] = []
    for i, rung in enumerate(rungs):
        recalls.append(recall_of(rung))
        if recalls[-1] >= target:
            return i, recalls
    return len(rungs) - 1, recalls


def choose_support(
    rmap: ReachabilityMap, robot: Robot, count: int, threshold: float, n_precision: int = 1000
) -> ReachabilityMap:
    """The map with its support settings chosen and its measured quality recorded in ``info.quality``.

    Args:
        rmap: the built map (any support settings).
        robot: its robot.
        count: the support count (> 0).
        threshold: the build's support threshold (> 0), the ladder's first rung.
        n_precision: IK poses of the precision measurement.

    Returns:
        The map read with the kept rung; ``info.quality`` holds the recall and precision
        (``certify.measure_quality``) and, on the ladder, the rungs measured and whether the
        target was met.
    """
    from baseplace.reachability.certify import measure_quality

    start = time.perf_counter()
    seed = rmap.info.seed
    rungs = rungs_from(threshold) if rmap.info.samples >= LADDER_FROM else [Rung(threshold, 0.0)]

    def recall_of(rung: Rung) -> float:
        read = rmap.with_support(count, rung.threshold, rung.fill)
        return measure_quality(read, robot, n_precision=0, seed=seed)["recall"]

    if len(rungs) > 1:
        kept, recalls = climb(rungs, recall_of)
    else:
        kept, recalls = 0, []
    rung = rungs[kept]
    chosen = rmap.with_support(count, rung.threshold, rung.fill)
    quality: dict[str, object] = dict(measure_quality(chosen, robot, n_precision=n_precision, seed=seed))
    quality["support"] = {"count": count, "threshold": rung.threshold, "fill": rung.fill}
    if recalls:
        quality["ladder"] = [
            {"threshold": r.threshold, "fill": r.fill, "recall": v}
            for r, v in zip(rungs, recalls, strict=False)
        ]
        quality["target_recall"] = TARGET_RECALL
        quality["met"] = recalls[kept] >= TARGET_RECALL
    quality["measure_time_s"] = round(time.perf_counter() - start, 2)
    return dataclasses.replace(chosen, info=dataclasses.replace(chosen.info, quality=json.dumps(quality)))
