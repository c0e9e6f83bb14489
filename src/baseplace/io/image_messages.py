"""ROS image messages <-> arrays, without ROS: sensor_msgs/Image and sensor_msgs/CameraInfo.

Readers: an Image -> an RGB (H, W, 3) uint8 array or a depth (H, W) float32 array [m]; a
CameraInfo -> :class:`~baseplace.perception.rgbd.Intrinsics`. Every declared size is checked
against the message's bytes and the memory cap before an array is made (docs/security.md, "Bags").
Writers (for :mod:`baseplace.io.bag_writer`) make the messages from arrays.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError
from baseplace.guards import check_alloc
from baseplace.io.messages import header
from baseplace.perception.rgbd import MAX_SIDE, Intrinsics

IMAGE = "sensor_msgs/msg/Image"
CAMERA_INFO = "sensor_msgs/msg/CameraInfo"
COLOUR_ENCODINGS = {"rgb8": 3, "bgr8": 3, "rgba8": 4, "bgra8": 4, "mono8": 1}
"""Colour encodings read, with their bytes per pixel."""
DEPTH_ENCODINGS = {"16UC1": 2, "mono16": 2, "32FC1": 4}
"""Depth encodings read: 16-bit millimetres (0: no return) or 32-bit float metres."""
DECODE_BYTES_PER_PIXEL = 40.0
"""What the point pipeline holds per pixel (the image, float depth, xyz points), as for image files."""


def _pixels(msg: Any, where: str, encodings: dict[str, int]) -> tuple[NDArray[np.uint8], str]:
    """The message's rows (H, W * bytes per pixel) of its data, after checking the declared sizes."""
    width, height, step = int(msg.width), int(msg.height), int(msg.step)
    encoding = str(msg.encoding)
    if encoding not in encodings:
        raise InputError(f"{where}: image encoding {encoding!r} is not read; valid: {', '.join(encodings)}")
    if not (0 < width <= MAX_SIDE and 0 < height <= MAX_SIDE):
        raise InputError(f"{where}: image is {width}x{height} pixels; each side must be 1 to {MAX_SIDE}")
    bpp = encodings[encoding]
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    if step < width * bpp or len(data) != step * height:
        raise InputError(
            f"{where}: {len(data)} bytes of data do not hold {height} rows of step {step} "
            f"({width} pixels of {bpp} bytes each)"
        )
    check_alloc(float(width) * height * DECODE_BYTES_PER_PIXEL, "image's points", where)
    return data.reshape(height, step)[:, : width * bpp], encoding


def rgb_from_msg(msg: Any, where: str) -> NDArray[np.uint8]:
    """(H, W, 3) uint8 RGB of a colour sensor_msgs/Image (rgb8, bgr8, rgba8, bgra8, mono8).

    Raises:
        InputError: another encoding, a size over the limits, or data that does not match the size.
    """
    rows, encoding = _pixels(msg, where, COLOUR_ENCODINGS)
    height, width = rows.shape[0], int(msg.width)
    px = rows.reshape(height, width, COLOUR_ENCODINGS[encoding])
    if encoding == "mono8":
        return np.ascontiguousarray(np.repeat(px, 3, axis=2))
    rgb = px[..., :3] if encoding.startswith("rgb") else px[..., 2::-1]
    return np.ascontiguousarray(rgb)


def depth_from_msg(msg: Any, where: str) -> NDArray[np.float32]:
    """(H, W) float32 depth [m] of a depth sensor_msgs/Image, NaN where there is no return.

    16UC1 (and mono16) are millimetres with 0 for no return; 32FC1 metres, with 0, NaN or inf for none.

    Raises:
        InputError: another encoding, a size over the limits, or data that does not match the size.
    """
    rows, encoding = _pixels(msg, where, DEPTH_ENCODINGS)
    height, width = rows.shape[0], int(msg.width)
    order = ">" if int(msg.is_bigendian) else "<"
    if encoding == "32FC1":
        depth = np.ascontiguousarray(rows).view(f"{order}f4").reshape(height, width).astype(np.float32)
    else:
        millimetres = np.ascontiguousarray(rows).view(f"{order}u2").reshape(height, width)
        depth = (millimetres / np.float32(1000)).astype(np.float32)
    depth[~np.isfinite(depth) | (depth <= 0)] = np.nan
    return depth


def intrinsics_from_msg(msg: Any, where: str) -> Intrinsics:
    """The pinhole camera of a sensor_msgs/CameraInfo (its K), with the image size it is for.

    Raises:
        InputError: no 3x3 K, or non-finite or non-positive focal lengths.
    """
    K = np.asarray(getattr(msg, "k", getattr(msg, "K", [])), dtype=np.float64).reshape(-1)
    if K.shape != (9,):
        raise InputError(f"{where}: CameraInfo K must have 9 numbers, got {K.size}")
    try:
        return Intrinsics(float(K[0]), float(K[4]), float(K[2]), float(K[5]), int(msg.width), int(msg.height))
    except InputError as exc:
        raise InputError(f"{where}: {exc}") from None


def image_msg(ts: Any, image: NDArray[Any], encoding: str, frame: str, ns: int) -> Any:
    """A sensor_msgs/Image of ``image``: (H, W, 3) uint8 as rgb8/bgr8, (H, W) uint16 as 16UC1, float32 as 32FC1."""
    arr = np.ascontiguousarray(image)
    dtype = {"rgb8": "u1", "bgr8": "u1", "16UC1": "<u2", "32FC1": "<f4"}.get(encoding)
    if dtype is None:
        raise InputError(f"unknown image encoding {encoding!r}; valid: rgb8, bgr8, 16UC1, 32FC1")
    arr = np.ascontiguousarray(arr.astype(dtype))
    height, width = arr.shape[:2]
    return ts.types[IMAGE](
        header=header(ts, frame, ns), height=height, width=width, encoding=encoding, is_bigendian=0,
        step=arr.nbytes // height, data=np.frombuffer(arr.tobytes(), dtype=np.uint8),
    )  # fmt: skip


def camera_info_msg(ts: Any, K: Intrinsics, width: int, height: int, frame: str, ns: int) -> Any:
    """A sensor_msgs/CameraInfo of a pinhole camera without distortion, for ``width`` x ``height`` images."""
    g = ts.types
    cls = g[CAMERA_INFO]
    k = np.array([K.fx, 0.0, K.cx, 0.0, K.fy, K.cy, 0.0, 0.0, 1.0])
    p = np.array([K.fx, 0.0, K.cx, 0.0, 0.0, K.fy, K.cy, 0.0, 0.0, 0.0, 1.0, 0.0])
    r = np.eye(3).reshape(-1)
    ros1 = "K" in cls.__dataclass_fields__  # ROS 1 spells the matrices in capitals
    matrices = (
        {"D": np.zeros(5), "K": k, "R": r, "P": p} if ros1 else {"d": np.zeros(5), "k": k, "r": r, "p": p}
    )
    roi = g["sensor_msgs/msg/RegionOfInterest"](x_offset=0, y_offset=0, height=0, width=0, do_rectify=False)
    return cls(header=header(ts, frame, ns), height=height, width=width, distortion_model="plumb_bob",
               binning_x=0, binning_y=0, roi=roi, **matrices)  # fmt: skip


__all__ = [
    "CAMERA_INFO",
    "IMAGE",
    "camera_info_msg",
    "depth_from_msg",
    "image_msg",
    "intrinsics_from_msg",
    "rgb_from_msg",
]
