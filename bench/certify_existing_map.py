"""Certify an existing map's sparse cells by IK and record its measured quality (``certify.py``).

The map's chunks are replayed from its seed, so pass the orientation resolution it was built
with. Used for the 0.4 rad rows of docs/maps.md:
    baseplace build-map --robot tiago --samples 2e8 --orientation-resolution 0.4 --out tiago-2e8-0.4rad.rmap
    python bench/certify_existing_map.py tiago-2e8-0.4rad.rmap 3 1 tiago-2e8-0.4rad-certified3.rmap 0.4
    python bench/bench_accuracy.py --map tiago-2e8-0.4rad-certified3.rmap --name accuracy_tiago_0.4rad_certified
(and the same with --samples 4e8 for accuracy_tiago_0.4rad_4e8_certified).
Usage: python bench/certify_existing_map.py MAP BELOW POSES OUT ORIENTATION_RESOLUTION
"""

from __future__ import annotations

import sys
import time

from baseplace.reachability.build import BuildSettings, MapAccumulator
from baseplace.reachability.certify import CertifySettings, certify_map, record_quality
from baseplace.reachability.storage import load_map, save_map
from baseplace.robots.model import Robot


def main() -> None:
    path, below, poses, out, orientation = sys.argv[1:6]
    robot = Robot("tiago")
    rmap = load_map(path, robot)
    settings = BuildSettings(
        samples=rmap.info.samples,
        seed=rmap.info.seed,
        voxel_size=rmap.grid.voxel_size,
        orientation_resolution=float(orientation),
    )
    acc = MapAccumulator(robot, rmap.info.arm, settings)
    if acc.grid != rmap.grid:
        raise SystemExit("the orientation resolution does not give the map's grid")
    start = time.perf_counter()
    certified = certify_map(
        rmap, robot, CertifySettings(below=int(below), poses=int(poses)), acc.chunk_samples
    )
    print(
        "certify",
        round(time.perf_counter() - start, 1),
        "s",
        certified.n_reached,
        certified.info.certification,
    )
    certified = record_quality(certified, robot)
    print(certified.info.quality)
    save_map(certified, out)


if __name__ == "__main__":
    main()
