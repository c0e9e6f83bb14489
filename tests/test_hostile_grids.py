"""Grids sized by the user (issue 28, defect 5): refused before allocation, with the cell count and the limit.

A surface map's, a height map's, an occupancy grid's and a fusion's cells follow from an extent and
a resolution the user gives; each is compared with what ``$BASEPLACE_MAX_MEMORY_MB`` holds at the
structure's bytes per cell before anything of that size is allocated. The CLI cases run in a fresh
process under ``BASEPLACE_MAX_MEMORY_MB=512`` and an address-space limit (so that code without the
checks fails with a MemoryError instead of taking the machine's memory); their peak resident memory
(measured as tests/peak_memory.py does) must stay under the cap.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np
import pytest

from baseplace.errors import InputError
from peak_memory import CAP_MB, cli_peak


def assert_one_line_refusal(code: int, err: str, seconds: float, peak_mb: float, *fragments: str) -> None:
    assert code == 2, (code, err[-2000:])
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), err[-2000:]
    for fragment in fragments:
        assert fragment in lines[0], lines[0]
    assert seconds < 30.0, seconds
    assert peak_mb < CAP_MB, peak_mb


@pytest.fixture()
def cap_512(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", str(CAP_MB))


# --- surface maps ---


def test_cli_surface_map_of_a_100_m_square_at_1_cm_is_refused(tmp_path: Path) -> None:
    """The issue's case: 4.9 GB and a MemoryError traceback before; now exit 2 with the cells and the limit."""
    result = cli_peak("surface-map", "--polygon", "0,0;100,0;100,100;0,100", "--height", "0.7",
                        "--resolution", "0.01", "--samples", "20000", "--out", "big.smap", cwd=tmp_path)  # fmt: skip
    assert_one_line_refusal(*result, "1.6e+09 cells", "over the limit of", "BASEPLACE_MAX_MEMORY_MB=512")
    assert not (tmp_path / "big.smap").exists()


def test_surface_grid_limit_follows_the_cap(monkeypatch: pytest.MonkeyPatch) -> None:
    from baseplace.placement.surface_map import check_surface_grid, parse_polygon

    square = parse_polygon("0,0;20,0;20,20;0,20")  # 2001 x 2001 cells at 1 cm
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "512")
    with pytest.raises(InputError, match=r"16 headings x 2001 x 2001 = 6.41e\+07 cells is over the limit"):
        check_surface_grid(square, 0.01, 16)
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "4096")
    assert check_surface_grid(square, 0.01, 16) == 16 * 2001 * 2001
    # the arms' reach widens the grid on every side: the same polygon, over the limit again
    with pytest.raises(InputError, match=r"16 headings x 2801 x 2801"):
        check_surface_grid(square, 0.01, 16, margin=4.0)


def test_build_surface_map_refuses_before_allocating(tiago, monkeypatch: pytest.MonkeyPatch) -> None:
    """The library function checks the whole grid (the polygon widened by the arm's reach) first.

    5 m at 1 cm is about 7.6e6 cells with its reach, 290 MB: over a cap of 64 MB.
    """
    from baseplace.placement.surface_map import build_surface_map
    from baseplace.reachability.build import BuildSettings, build_map

    rmap = build_map(tiago, None, BuildSettings(samples=20_000, seed=0))
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "64")
    t0 = time.perf_counter()
    with pytest.raises(
        InputError, match=r"16 headings x \d+ x \d+ = 7.\de\+06 cells is over the limit of 1.68e\+06"
    ):
        build_surface_map(tiago, {"arm": rmap}, "0,0;5,0;5,5;0,5", 0.7, resolution=0.01)
    assert time.perf_counter() - t0 < 1.0


def test_surface_grid_points_are_bounded(cap_512) -> None:
    """surface_grid (also the furniture of surface-sample) checks the polygon's box before its meshgrid."""
    from baseplace.placement.surface_map import parse_polygon, surface_grid

    with pytest.raises(InputError, match="grid points at 0.01 m"):
        surface_grid(parse_polygon("0,0;1000,0;1000,1000;0,1000"), 0.01)


def test_surface_sample_furniture_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    """A surface map file's polygon and height make the furniture's voxels: counted before they are made."""
    from baseplace.placement.surface_map import SurfaceMap, parse_polygon
    from baseplace.placement.surface_sampling import furniture_voxels

    smap = SurfaceMap(np.ones((1, 2, 2), np.float32), (0.0, 0.0), 0.05, parse_polygon("0,0;5,0;5,5;0,5"),
                      1.0, "tiago", ("arm",), "any", None)  # fmt: skip
    monkeypatch.setenv(
        "BASEPLACE_MAX_MEMORY_MB", "16"
    )  # 202 x 202 cells x 40 layers and the edge: 1.7e6 voxels
    with pytest.raises(InputError, match="furniture.s 1.7e\\+06 voxels"):
        furniture_voxels(smap)


# --- height maps and voxels (segment, navigate, place) ---


def _sparse_cloud(side: float) -> np.ndarray:
    rng = np.random.default_rng(0)
    floor = np.c_[rng.uniform(0, 2, (20_000, 2)), np.zeros(20_000)]
    return np.vstack([floor, [[side, side, 0.0]]])


def test_cli_segment_of_a_wide_cloud_at_1_cm_is_refused(tmp_path: Path) -> None:
    """49 m at 1 cm: 2.4e7 cells passed the old fixed limit (2.5e7) and took about 8 GB to segment."""
    np.save(tmp_path / "wide.npy", _sparse_cloud(49.0))
    result = cli_peak("segment", "wide.npy", "--resolution", "0.01", cwd=tmp_path)
    assert_one_line_refusal(*result, "4901 x 4901 = 2.4e+07 cells at 0.01 m", "over the limit of")


def test_height_map_limit_follows_the_cap(monkeypatch: pytest.MonkeyPatch) -> None:
    from baseplace.terrain.heightmap import HeightMap
    from baseplace.terrain.pipeline import terrain_from_points
    from baseplace.terrain.voxels import VoxelMap

    cloud = _sparse_cloud(4.0)  # 401 x 401 cells at 1 cm: 62 MB at 384 bytes each
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "16")
    with pytest.raises(
        InputError, match=r"401 x 401 = 1.61e\+05 cells at 0.01 m is over the limit of 3.\d+e\+04"
    ):
        terrain_from_points(cloud, resolution=0.01)  # the voxelization's 3.2 MB are kept aside
    with pytest.raises(InputError, match=r"= 1.61e\+05 cells at 0.01 m is over the limit of 4.37e\+04"):
        HeightMap.from_voxels(VoxelMap.from_points(cloud, 0.01), 0.01)


def test_voxelization_is_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    from baseplace.terrain.voxels import VoxelMap

    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "1")
    with pytest.raises(InputError, match="voxelizing 10000 points"):
        VoxelMap.from_points(np.random.default_rng(0).uniform(0, 1, (10_000, 3)), 0.025)


# --- occupancy grids ---


def test_occupancy_grid_is_bounded_when_made(monkeypatch: pytest.MonkeyPatch) -> None:
    from baseplace.world.occupancy import OccupancyGrid

    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "16")  # 2.6e5 cells at 64 bytes
    with pytest.raises(
        InputError, match=r"occupancy grid of 1000 x 2000 = 2e\+06 cells is over the limit of 2.62e\+05"
    ):
        OccupancyGrid(np.zeros((1000, 2000), np.int8), 0.05)
    assert OccupancyGrid(np.zeros((400, 600), np.int8), 0.05).width == 600


# --- fusion ---


def test_fusion_is_bounded_before_the_octree_grows(monkeypatch: pytest.MonkeyPatch) -> None:
    from baseplace.terrain.fusion import FusionSettings, PosedCloud, check_voxels, fuse_clouds

    rng = np.random.default_rng(0)
    far = np.c_[rng.uniform(-5, 5, (1000, 2)), np.full(1000, 10.0)]  # rays of 10 m at 1 cm
    clouds = [PosedCloud(far, np.zeros(3))]
    settings = FusionSettings(resolution=0.01)
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "8")
    t0 = time.perf_counter()
    with pytest.raises(
        InputError, match=r"may touch 1.\d+e\+06 voxels of 0.01 m is over the limit of 1.31e\+05 voxels"
    ):
        fuse_clouds(clouds, settings)
    assert time.perf_counter() - t0 < 1.0
    # the bound: at most the rays' L1 length in voxels, at most the box's cells
    bound = check_voxels([(far, np.zeros(3))], FusionSettings(resolution=1.0))
    assert bound <= 11 * 11 * 11
    monkeypatch.setenv("BASEPLACE_MAX_MEMORY_MB", "4096")
    near = np.c_[rng.uniform(-0.5, 0.5, (200, 2)), np.full(200, 1.0)]
    assert len(fuse_clouds([PosedCloud(near, np.zeros(3))], FusionSettings(resolution=0.05))) > 0


# --- the CLI's last line of defence ---


def test_an_unexpected_memory_error_is_one_line_exit_1(monkeypatch: pytest.MonkeyPatch) -> None:
    import baseplace.jobs.world
    from conftest import run_cli

    def exhausted(path: str) -> None:
        raise MemoryError

    monkeypatch.setattr(baseplace.jobs.world, "occupancy_job", exhausted)
    proc = run_cli("occupancy", "any.yaml")
    assert proc.returncode == 1, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: out of memory"), proc.stderr
