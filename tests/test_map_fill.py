"""The hole fill of the map lookup and the support settings chosen on the map's own recall (issue 27 item 4)."""

from __future__ import annotations

import dataclasses
import json

import h5py
import numpy as np
import pytest

from baseplace.errors import InputError
from baseplace.geometry.poses import pose_from_xyz_rpy
from baseplace.h5files import digest, read_text, short_text, write_text
from baseplace.jobs.text import _build_map
from baseplace.reachability import support as support_module
from baseplace.reachability.certify import measure_quality
from baseplace.reachability.grid import SE3Grid
from baseplace.reachability.rmap import MapInfo, ReachabilityMap
from baseplace.reachability.storage import load_map, save_map
from baseplace.reachability.support import LADDER, Rung, built_threshold, choose_support, climb, rungs_from
from baseplace.robots.fk import forward_kinematics

GRID = SE3Grid((0.0, 0.0, 0.0), 0.1, (10, 10, 10), 1, 4)  # 48 orientation bins
HOLE = (3, 3, 3)
"""An unreached voxel inside the reached block of :func:`block_map`."""


def block_map(fill: float, count: int = 4) -> ReachabilityMap:
    """Every orientation of the voxels 1-5 on each axis reached ``count`` times, but the voxel :data:`HOLE`."""
    ijk = np.stack(np.meshgrid(*[np.arange(1, 6)] * 3, indexing="ij"), -1).reshape(-1, 3)
    ijk = ijk[(ijk != HOLE).any(axis=1)]
    voxels = (ijk[:, 0] * 10 + ijk[:, 1]) * 10 + ijk[:, 2]
    n = GRID.n_orientations
    cells = np.sort((voxels[:, None] * n + np.arange(n)).ravel()).astype(np.int64)
    counts = np.full(len(cells), count, dtype=np.uint32)
    counts[::7] = 2 * count  # a varied index, so a filled pose's value is told from the reached ones'
    info = MapInfo("synthetic", "0" * 64, "arm", ("j",), "base", "tcp", len(cells), 0,
                   support_count=1, support_threshold=0.8, fill_threshold=fill)  # fmt: skip
    return ReachabilityMap(GRID, cells, counts, info)


def at_voxel(ijk: tuple[int, int, int], offset: float, rng: np.random.Generator, n: int = 50) -> np.ndarray:
    """(n, 4, 4) poses of random rotation, ``offset`` voxels from the voxel's centre along each axis."""
    centre = (np.asarray(ijk) + 0.5 + offset) * GRID.voxel_size
    return pose_from_xyz_rpy(np.c_[np.tile(centre, (n, 1)), rng.uniform(-np.pi, np.pi, (n, 3))])


def test_a_hole_inside_reached_cells_is_filled_and_a_far_pose_is_not(rng):
    filled_map, plain = block_map(0.3), block_map(0.0)
    near = at_voxel(HOLE, 0.4, rng)  # own voxel's trilinear weight 0.6^3: support 0.78 from the neighbours
    centre = at_voxel(HOLE, 0.0, rng)  # all weight on the unreached voxel: support 0
    far = at_voxel((8, 8, 8), 0.4, rng)  # two voxels from the reached block
    inside = at_voxel((2, 2, 2), 0.2, rng)
    filled = np.float32(0.5 / 8)  # half a one-sample cell: below every reached cell's index (>= 4/8)
    assert (plain.reachability(near) == 0).all()
    assert (filled_map.reachability(near) == filled).all()
    assert (filled_map.reachability(centre) == 0).all()
    assert (filled_map.reachability(far) == 0).all()
    assert filled < plain.reachability(inside).min()
    np.testing.assert_array_equal(filled_map.reachability(inside), plain.reachability(inside))
    # every query path gives the same answer
    assert [filled_map.value(T) for T in near[:5]] == [float(filled)] * 5
    np.testing.assert_array_equal(filled_map.inverse(near[0], np.eye(4)[None]), [filled])
    bases = np.linalg.inv(near)  # inv(base) @ identity target = the pose
    np.testing.assert_array_equal(filled_map.inverse(np.eye(4), bases), filled_map.reachability(near))
    # a fill threshold above the hole's support: not filled
    assert (block_map(0.9).reachability(near) == 0).all()


def _cell_values(rmap: ReachabilityMap, T: np.ndarray) -> np.ndarray:
    """Each pose's cell's ``count / max`` (0 for an unreached cell), from the cells, not the tables."""
    cell = rmap.grid.cell_index(T)
    at = np.clip(np.searchsorted(rmap.cells, cell), 0, len(rmap.cells) - 1)
    hit = (cell >= 0) & (rmap.cells[at] == cell)
    return np.where(hit, rmap.counts[at] / rmap.counts.max(), 0.0).astype(np.float32)


def test_fill_off_answers_as_before_and_fill_on_answers_only_unreached_cells(tiago, tiago_map, rng):
    arm = tiago.arm()
    fk = forward_kinematics(arm, arm.sample(rng, 4000))
    moved = fk.copy()
    moved[:, :3, 3] += rng.normal(0.0, 0.04, (len(fk), 3))
    T = np.concatenate([fk, moved])
    cell = _cell_values(tiago_map, T)
    whole = tiago_map.with_support(0, 0.0)
    np.testing.assert_array_equal(whole.reachability(T), cell)
    supported = tiago_map.with_support(1, 0.8)
    off = supported.with_support(1, 0.8, 0.0)
    assert off.info == dataclasses.replace(supported.info, fill_threshold=0.0)
    before = supported.reachability(T)
    assert np.array_equal(off.reachability(T), before) and np.array_equal(
        before[before > 0], cell[before > 0]
    )
    assert (before[cell == 0] == 0).all() and 0 < (before > 0).sum() < (cell > 0).sum()
    on = supported.with_support(1, 0.8, 0.3)
    after = on.reachability(T)
    np.testing.assert_array_equal(after[cell > 0], before[cell > 0])  # reached cells: unchanged
    newly = after[cell == 0]
    assert set(np.unique(newly)) == {0.0, np.float32(0.5 / tiago_map.counts.max())}
    # FK poses are reachable by construction: the fill answers some the map had missed
    called_before, called_after = (before[: len(fk)] > 0).mean(), (after[: len(fk)] > 0).mean()
    assert called_after > called_before + 0.01
    assert [on.value(t) for t in T[:200]] == [float(v) for v in after[:200]]
    # without the support test there is no fill
    assert (tiago_map.with_support(0, 0.0, 0.3).reachability(T) == cell).all()


def test_fill_threshold_round_trips_and_old_files_read_as_off(tmp_path):
    rmap = block_map(0.3)
    save_map(rmap, tmp_path / "m.rmap")
    assert load_map(tmp_path / "m.rmap").info == rmap.info
    assert load_map(tmp_path / "m.rmap").info.fill_threshold == 0.3

    def rewrite_info(change) -> None:  # a file as an older baseplace (or a forger) wrote it
        with h5py.File(tmp_path / "m.rmap", "r+") as f:
            info = json.loads(read_text(f, "info"))
            change(info)
            del f["info"]
            text = json.dumps(info)
            write_text(f, "info", text)
            f.attrs["sha256"] = short_text(
                digest(read_text(f, "grid"), text.encode(), f["cells"][()], f["counts"][()])
            )

    rewrite_info(lambda info: info.pop("fill_threshold"))
    old = load_map(tmp_path / "m.rmap")
    assert old.info.fill_threshold == 0.0 and old.support[2:] == (0.0, 0.0)
    rewrite_info(lambda info: info.update(fill_threshold=1.5))
    with pytest.raises(InputError, match=r"fill_threshold must be a number in \[0, 1\], got 1.5"):
        load_map(tmp_path / "m.rmap")
    with pytest.raises(InputError, match="fill_threshold"):
        dataclasses.replace(rmap.info, fill_threshold=-0.1)


def test_the_ladder_keeps_the_first_rung_that_reaches_the_recall():
    rungs = rungs_from(0.8)
    assert rungs == list(LADDER) and rungs[0] == Rung(0.8, 0.0)
    assert rungs_from(0.9)[:2] == [Rung(0.9, 0.0), Rung(0.8, 0.0)]
    assert all(r.threshold < 0.65 for r in rungs_from(0.65)[1:])
    asked: list[Rung] = []
    table = dict(zip(rungs, [0.90, 0.97, 0.984, 0.986, 0.99, 0.995, 0.996, 0.997, 0.999], strict=True))

    def recall_of(rung: Rung) -> float:
        asked.append(rung)
        return table[rung]

    assert climb(rungs, recall_of) == (3, [0.90, 0.97, 0.984, 0.986])
    assert asked == rungs[:4]  # the looser rungs are not measured
    assert climb(rungs, lambda r: 0.5) == (len(rungs) - 1, [0.5] * len(rungs))  # none: the loosest
    assert climb(rungs, lambda r: 0.99) == (0, [0.99])


def test_a_sparse_map_climbs_the_ladder_on_its_own_recall(tiago, tiago_map, monkeypatch):
    monkeypatch.setattr(support_module, "LADDER_FROM", 1)  # the 2e6-sample test map, its support forced
    chosen = choose_support(tiago_map, tiago, 1, 0.8, n_precision=40)
    q = json.loads(chosen.info.quality)
    ladder = q["ladder"]
    recalls = [r["recall"] for r in ladder]
    assert recalls[0] < 0.985 and len(ladder) > 1  # too sparse for the strict rung: a looser one kept
    assert recalls == sorted(recalls)  # each rung calls reachable all the previous one did
    kept = ladder[-1]
    assert q["met"] == (kept["recall"] >= 0.985)
    assert q["support"] == {"count": 1, "threshold": kept["threshold"], "fill": kept["fill"]}
    info = chosen.info
    assert (info.support_count, info.support_threshold, info.fill_threshold) == (
        1,
        kept["threshold"],
        kept["fill"],
    )
    assert built_threshold(info) == 0.8
    # the recorded recall is the kept map's on an independent check of the same FK stream
    assert q["recall"] == kept["recall"] == measure_quality(chosen, tiago, n_precision=0, seed=3)["recall"]
    assert q["n_precision"] == 40 and 0.0 <= q["precision"] <= 1.0
    # on FK poses of another seed (reachable by construction) the kept rung calls more reachable
    arm = tiago.arm()
    fk = forward_kinematics(arm, arm.sample(np.random.default_rng(99), 3000))
    strict = tiago_map.with_support(1, 0.8)
    assert (chosen.reachability(fk) > 0).mean() > (strict.reachability(fk) > 0).mean() + 0.05
    # small maps keep their threshold
    monkeypatch.setattr(support_module, "LADDER_FROM", 10**9)
    small = choose_support(tiago_map, tiago, 1, 0.8, n_precision=10)
    assert "ladder" not in json.loads(small.info.quality) and small.info.fill_threshold == 0.0


def test_build_map_prints_the_chosen_support_settings():
    quality = {"recall": 0.9881, "precision": 0.98, "n_recall": 10000, "n_precision": 1000, "target_recall": 0.985,
               "met": True, "ladder": [{"threshold": 0.8, "fill": 0.0, "recall": 0.838},
                                       {"threshold": 0.4, "fill": 0.3, "recall": 0.9881}]}  # fmt: skip
    report = {"outputs": {"map": "m.rmap"}, "cells_reached": 5, "samples": 1e7, "build_time_s": 3.0,
              "samples_per_s": 3e6, "file_bytes": 1e6, "support": {"count": 1, "threshold": 0.4, "fill": 0.3},
              "quality": quality}  # fmt: skip
    text = "\n".join(_build_map(report))
    assert "support test: count 1, threshold 0.4, fill 0.3" in text
    assert "0.8/0.0: 83.80%; 0.4/0.3: 98.81%; kept the first at >= 98.5%" in text
    assert "measured: recall 98.81% on 10000 FK poses, precision 98.0%" in text
    report["quality"] = {**quality, "met": False}
    assert "none reached 98.5%: kept the loosest" in "\n".join(_build_map(report))
