"""Reading a recording's /tf: time per transform, and the share the garbage collector takes.

Writes a ROS 1 bag of one small cloud and N /tf messages of one transform each (10 frames, 100 Hz),
then times ``read_bag`` (median of repeats) with Python's garbage collector on, as the library runs,
and off, the floor for this decoder: their ratio is what the collector costs. Held in a batch, the
decoded messages once outlived its young generations, and its full collections (every object of the
process) took about half of a large read; the batch now keeps plain numbers.
Usage: python bench/bench_tf_read.py [--transforms 50000] [--repeats 5]
"""

from __future__ import annotations

import argparse
import gc
import tempfile
from pathlib import Path

import numpy as np

from baseplace.io.bag import read_bag
from baseplace.io.bag_writer import CloudRecord, TfRecord, write_input_bag
from common import median_time, report

T0 = 1_700_000_000_000_000_000


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("--transforms", type=int, default=50_000)
    parser.add_argument("--repeats", type=int, default=5)
    args = parser.parse_args()
    n = args.transforms
    tf = [TfRecord("map", f"f{k % 10}", T0 + k * 1_000_000, np.eye(4)) for k in range(n)]
    tf.append(TfRecord("map", "cam", T0, np.eye(4), static=True))
    cloud = CloudRecord("/points", "cam", T0, np.random.default_rng(0).random((100, 3)))
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "tf.bag"
        write_input_bag(path, "ros1", clouds=[cloud], tf=tf)
        read_bag(path, ["/points"])  # imports and first use outside the timing

        def without_collector() -> None:
            gc.disable()
            try:
                read_bag(path, ["/points"])
            finally:
                gc.enable()

        on = median_time(lambda: read_bag(path, ["/points"]), args.repeats)
        off = median_time(without_collector, args.repeats)
    report(
        "tf_read",
        {
            "transforms": n,
            "messages": n + 1,
            "read_s_median": round(on, 3),
            "read_s_median_collector_off": round(off, 3),
            "collector_on_over_off": round(on / off, 2),
            "us_per_transform": round(on / n * 1e6, 1),
        },
    )


if __name__ == "__main__":
    main()
