"""Write a recording of PCL's mug cloud in the depot map, as a robot would record it.

    python bench/make_mug_room_bag.py out/mug_room [--format mcap|sqlite3|ros1]

Topics: /head/points (sensor_msgs/PointCloud2, frame head_camera), /tf (map -> base_link, the base
driving 0.2 m in 2 s around the cloud's stamp), /tf_static (base_link -> head_camera) and /map
(nav_msgs/OccupancyGrid: the depot map of ROS 2 Navigation). The camera stands so that PCL's
reference table plane (normal (-0.0162, 0.8378, 0.5458), d = -0.5287 in the camera frame) is 0.74 m
above the floor, centred near (4.6, 7.7) in the depot's largest free area. The same scene as
tests/test_io_bag.py.
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from baseplace.io.bag_writer import CloudRecord, GridRecord, TfRecord, write_input_bag
from baseplace.terrain.io import load_cloud, load_transform
from baseplace.world.occupancy import load_occupancy

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
T0 = 1_700_000_000_000_000_000


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="bag to write (a directory for ROS 2, a .bag file for ROS 1)")
    parser.add_argument("--format", default="mcap", choices=["mcap", "sqlite3", "ros1"])
    parser.add_argument("--data", default=str(DATA), help="the shared data folder")
    args = parser.parse_args()
    data = Path(args.data)
    T_map_camera = load_transform("0.0162 -0.8378 -0.5458")
    T_map_camera[:3, 3] = [4.55, 6.98, 0.74 + 0.5287]
    T_base_camera = np.eye(4)
    T_base_camera[:3, :3] = Rotation.from_euler("xyz", [0.1, -0.3, 0.2]).as_matrix()
    T_base_camera[:3, 3] = [0.1, 0.0, 1.1]

    def base_at(dx: float) -> np.ndarray:
        T = T_map_camera @ np.linalg.inv(T_base_camera)
        T[0, 3] += dx
        return T

    cloud = load_cloud(data / "pointclouds" / "table_scene_mug_stereo_textured.pcd")
    write_input_bag(
        args.out, args.format,
        clouds=[CloudRecord("/head/points", "head_camera", T0, cloud.points)],
        tf=[TfRecord("map", "base_link", T0 - 10**9, base_at(-0.1)), TfRecord("map", "base_link", T0 + 10**9, base_at(0.1)),
            TfRecord("base_link", "head_camera", T0 - 5 * 10**9, T_base_camera, static=True)],
        grids=[GridRecord("/map", "map", T0 - 5 * 10**9, load_occupancy(data / "maps" / "depot.yaml"))],
    )  # fmt: skip
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
