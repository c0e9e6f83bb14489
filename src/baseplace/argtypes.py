"""Argument types shared by the ``baseplace`` command and the experiments' commands (argparse ``type=``)."""

from __future__ import annotations

import argparse
import math


def count(text: str) -> int:
    """Parse sample counts such as 5e7 or 50000000."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value) or value < 1 or value != int(value):
        raise argparse.ArgumentTypeError(f"must be a positive whole number, got {text!r}")
    return int(value)


def finite_float(text: str) -> float:
    """Parse a finite number."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
    return value


def nonneg_int(text: str) -> int:
    """Parse an integer >= 0."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not an integer: {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be >= 0, got {value}")
    return value


ANGLE_OPTIONS: dict[str, tuple[tuple[str, int, int], ...]] = {
    "place": (("target", 6, 3), ("grasp_point", 6, 3), ("start", 3, 1), ("object", 8, 1), ("obstacle", 8, 1)),
    "reach": (("target", 6, 3), ("targets", 6, 3), ("base", 3, 1), ("bases", 3, 1)),
    "candidates": (("robot_pose", 3, 1), ("object_shape", 8, 1), ("obstacle", 8, 1)),
    "navigate": (("start", 3, 1), ("goal", 3, 1)),
    "explain": (
        ("target", 6, 3),
        ("grasp_point", 6, 3),
        ("base", 3, 1),
        ("object", 8, 1),
        ("obstacle", 8, 1),
    ),
}
"""Command -> (option's dest, words of a value, angles among its last words) of the angles
``--degrees`` converts; an object or obstacle spec counts as "box" and 7 numbers, its yaw last."""


def _words_in_radians(text: str, width: int, angles: int) -> str:
    """``text`` with its last ``angles`` numbers converted from degrees, if it has ``width`` words.

    Anything else is left as it is: the job names the problem in the value as given.
    """
    words = text.replace(",", " ").split()
    if len(words) != width:
        return text
    try:
        converted = [repr(math.radians(float(w))) for w in words[width - angles :]]
    except ValueError:
        return text
    return " ".join(words[: width - angles] + converted)


def in_radians(args: argparse.Namespace) -> argparse.Namespace:
    """With ``--degrees``: the angles given on the command line, converted to radians in place.

    Poses (targets, base poses, start, goal, the robot's pose, an object box's yaw), pose files
    (read here, passed on as their rows) and ``--yaw-tolerance``; the jobs read radians only.
    """
    if not getattr(args, "degrees", False):
        return args
    for dest, width, angles in ANGLE_OPTIONS.get(args.command, ()):
        value = getattr(args, dest, None)
        if dest in ("targets", "bases") and isinstance(value, str):  # a file: its rows, converted
            from baseplace.jobs.reach import read_pose_file

            rows = read_pose_file(value, width, "target pose" if dest == "targets" else "base pose")
            value = [" ".join(repr(float(v)) for v in row) for row in rows]
        if isinstance(value, str):
            setattr(args, dest, _words_in_radians(value, width, angles))
        elif isinstance(value, list):
            setattr(args, dest, [_words_in_radians(v, width, angles) for v in value])
    if getattr(args, "yaw_tolerance", None) is not None:
        args.yaw_tolerance = math.radians(args.yaw_tolerance)
    return args
