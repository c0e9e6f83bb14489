"""ROS recordings in and out without ROS (``rosbags``): clouds, grids and tf in; results out as MCAP."""

from baseplace.io.bag import BagCloud, BagScene, read_bag
from baseplace.io.bag_writer import CloudRecord, GridRecord, TfRecord, write_input_bag
from baseplace.io.results import ResultMessages, read_result_mcap, write_result_mcap
from baseplace.io.tf import TfTree

__all__ = [
    "BagCloud",
    "BagScene",
    "CloudRecord",
    "GridRecord",
    "ResultMessages",
    "TfRecord",
    "TfTree",
    "read_bag",
    "read_result_mcap",
    "write_input_bag",
    "write_result_mcap",
]
