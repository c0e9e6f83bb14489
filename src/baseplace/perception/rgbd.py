"""An RGB image, its aligned depth image and the camera's intrinsics, read with hostile-file checks.

* RGB: PNG or JPEG, decoded by OpenCV to (H, W, 3) uint8 in RGB order.
* Depth: a 16-bit PNG in millimetres (0 = no return, as ROS ``16UC1`` depth images) or a float32
  ``.npy`` in metres (NaN, inf or <= 0 = no return). Returned as (H, W) float32 metres, NaN where
  there is no return.
* Intrinsics: ``"fx fy cx cy"`` [px] or a ROS CameraInfo YAML (the ``camera_calibration`` file
  with ``camera_matrix: {data: [...]}`` or a ``sensor_msgs/CameraInfo`` echo with ``K``/``k``),
  read with ``yaml.safe_load``.

Before anything is decoded, the image header (read by Pillow, which decodes nothing) or the
``.npy`` header is checked: its declared size must fit the file (PNG is deflated: at most 1100
bytes per byte of file; raw ``.npy`` its bytes) and the memory cap (:func:`~baseplace.guards.check_alloc`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from baseplace.errors import InputError, brief
from baseplace.guards import check_alloc, check_input_file, read_document

RGB_FORMATS = (".png", ".jpg", ".jpeg")
DEPTH_FORMATS = (".png", ".npy")
DEFLATE_MAX_RATIO = 1100.0
"""PNG pixels are deflated: one byte of file holds at most ~1032 bytes."""
JPEG_MAX_RATIO = 2000.0
"""A JPEG's pixels per byte of file (a flat image compresses to ~0.002 bytes per pixel)."""
MAX_SIDE = 16384
"""Longest image side accepted [px]; camera images are under 8k."""
MAX_YAML_BYTES = 1 << 20
"""The largest CameraInfo YAML read [bytes] (ROS writes about 600)."""
_DECODE_BYTES_PER_PIXEL = 40.0  # what the pipeline holds per pixel: the image, float depth, xyz points


@dataclass(frozen=True)
class Intrinsics:
    """A pinhole camera (optical frame: x right, y down, z forward).

    Attributes:
        fx, fy: focal lengths [px].
        cx, cy: principal point [px] (pixel centres at integers, as ROS).
        width, height: image size [px] from a CameraInfo file (None when given as text).
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int | None = None
    height: int | None = None

    def __post_init__(self) -> None:
        values = (self.fx, self.fy, self.cx, self.cy)
        if not all(math.isfinite(v) for v in values):
            raise InputError(f"intrinsics must be finite numbers, got fx fy cx cy = {_fmt(values)}")
        if self.fx <= 0 or self.fy <= 0:
            raise InputError(f"focal lengths fx, fy must be positive pixels, got {_fmt(values[:2])}")

    def check_image(self, width: int, height: int) -> None:
        """Raise unless the principal point lies in a ``width`` x ``height`` image (and sizes agree)."""
        if self.width is not None and (self.width, self.height) != (width, height):
            raise InputError(
                f"the CameraInfo is for {self.width}x{self.height} images, the RGB image is {width}x{height}"
            )
        if not (0 <= self.cx < width and 0 <= self.cy < height):
            raise InputError(
                f"principal point cx, cy = {_fmt((self.cx, self.cy))} lies outside the {width}x{height} image"
            )

    def pixel_rays(self, u: NDArray[Any], v: NDArray[Any]) -> NDArray[np.float64]:
        """Camera-frame directions (N, 3) with z = 1 through pixels (u, v) (N,)."""
        u, v = np.asarray(u, dtype=float), np.asarray(v, dtype=float)
        return np.stack([(u - self.cx) / self.fx, (v - self.cy) / self.fy, np.ones_like(u)], axis=-1)

    def project(self, p_cam: NDArray[Any]) -> NDArray[np.float64]:
        """Pixels (N, 2) (u, v) of camera-frame points (N, 3) [m] in front of the camera."""
        p = np.asarray(p_cam, dtype=float).reshape(-1, 3)
        return np.stack(
            [self.fx * p[:, 0] / p[:, 2] + self.cx, self.fy * p[:, 1] / p[:, 2] + self.cy], axis=1
        )


@dataclass(frozen=True)
class RgbdFrame:
    """One aligned RGB-D frame.

    Attributes:
        rgb: (H, W, 3) uint8, RGB order.
        depth: (H, W) float32 [m], NaN where there is no return.
        intrinsics: the camera.
    """

    rgb: NDArray[np.uint8]
    depth: NDArray[np.float32]
    intrinsics: Intrinsics

    @property
    def width(self) -> int:
        """Image width [px]."""
        return int(self.rgb.shape[1])

    @property
    def height(self) -> int:
        """Image height [px]."""
        return int(self.rgb.shape[0])

    def points_camera(self) -> NDArray[np.float64]:
        """(H, W, 3) camera-frame points [m], NaN where the depth has no return."""
        v, u = np.mgrid[0 : self.height, 0 : self.width]
        rays = self.intrinsics.pixel_rays(u, v)
        return rays * self.depth[..., None].astype(np.float64)


def _fmt(values: Any) -> str:
    return " ".join(f"{float(v):.6g}" for v in values)


def _image_header(path: Path, what: str) -> tuple[int, int, int, str, str]:
    """(width, height, bands, Pillow mode, format) from the header; nothing decoded."""
    from PIL import Image, UnidentifiedImageError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Pillow warns about large images on stderr
            with Image.open(path) as im:
                width, height = im.size
                return int(width), int(height), len(im.getbands()), str(im.mode), str(im.format)
    except Image.DecompressionBombError:
        raise InputError(f"{what} {path} declares more pixels than any camera image has") from None
    except (UnidentifiedImageError, OSError, ValueError, SyntaxError):
        raise InputError(f"cannot read {what} {path}: corrupt, truncated or not an image") from None


def _check_size(path: Path, what: str, width: int, height: int, bytes_per_pixel: float, ratio: float) -> None:
    if not (0 < width <= MAX_SIDE and 0 < height <= MAX_SIDE):
        raise InputError(f"{what} {path} is {width}x{height} pixels; each side must be 1 to {MAX_SIDE}")
    n = float(width) * float(height)
    check_alloc(n * bytes_per_pixel, what, path, path.stat().st_size, ratio)
    check_alloc(n * _DECODE_BYTES_PER_PIXEL, f"{what}'s points", path)


def _decode(path: Path, what: str, flags: int) -> NDArray[Any]:
    import cv2

    buf = np.fromfile(path, dtype=np.uint8)
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        img = cv2.imdecode(buf, flags) if buf.size else None
    except cv2.error:
        img = None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if img is None or img.size == 0:
        raise InputError(f"cannot read {what} {path}: corrupt, truncated or not a {path.suffix} image")
    return np.asarray(img)


def load_rgb(path: str | Path) -> NDArray[np.uint8]:
    """An RGB image (H, W, 3) uint8 from a PNG or JPEG file (grey is repeated, alpha dropped).

    Raises:
        InputError: unknown format, missing, corrupt, or a declared size beyond the file or the cap.
    """
    import cv2

    p = check_input_file(path, "RGB image", RGB_FORMATS)
    width, height, bands, mode, fmt = _image_header(p, "RGB image")
    depth = 2 if mode.startswith("I;16") or mode in ("I", "F") else 1
    ratio = DEFLATE_MAX_RATIO if fmt == "PNG" else JPEG_MAX_RATIO
    _check_size(p, "RGB image", width, height, max(bands, 3) * depth, ratio)
    img = _decode(p, "RGB image", cv2.IMREAD_COLOR)
    if img.dtype != np.uint8:  # a 16-bit PNG
        img = (img // 257).astype(np.uint8)
    return np.ascontiguousarray(img[..., ::-1])


def load_depth(path: str | Path) -> NDArray[np.float32]:
    """An aligned depth image (H, W) float32 [m], NaN where there is no return.

    Args:
        path: a 16-bit single-channel PNG in millimetres (0: no return) or a float32 (or float64)
            ``.npy`` of shape (H, W) in metres.

    Raises:
        InputError: another format, dtype or shape; a declared size beyond the file or the cap.
    """
    import cv2

    p = check_input_file(path, "depth image", DEPTH_FORMATS)
    if p.suffix.lower() == ".npy":
        return _load_depth_npy(p)
    width, height, bands, mode, _ = _image_header(p, "depth image")
    if bands != 1 or not (mode.startswith("I;16") or mode == "I"):
        raise InputError(
            f"depth image {p} is a {mode} PNG; depth must be a 16-bit single-channel PNG in millimetres "
            "or a float32 .npy in metres"
        )
    _check_size(p, "depth image", width, height, 2, DEFLATE_MAX_RATIO)
    img = _decode(p, "depth image", cv2.IMREAD_UNCHANGED)
    if img.ndim != 2 or img.dtype != np.uint16:
        raise InputError(f"depth image {p} decodes to {img.dtype} {img.shape}, not 16-bit single-channel")
    depth = img.astype(np.float32) / 1000.0
    depth[img == 0] = np.nan
    return depth


def _load_depth_npy(p: Path) -> NDArray[np.float32]:
    try:
        with p.open("rb") as f:
            version = np.lib.format.read_magic(f)
            read = (
                np.lib.format.read_array_header_1_0
                if version == (1, 0)
                else np.lib.format.read_array_header_2_0
            )
            shape, _fortran, dtype = read(f)
    except (ValueError, OSError, SyntaxError) as exc:
        raise InputError(
            f"cannot read depth image {p}: not a .npy file ({' '.join(str(exc).split())[:120]})"
        ) from None
    if dtype.hasobject or dtype.kind != "f" or dtype.itemsize not in (4, 8):
        raise InputError(f"depth image {p} holds {dtype}; a .npy depth image must be float32 metres")
    if len(shape) != 2:
        raise InputError(f"depth image {p} has shape {shape}; a .npy depth image must be (H, W) metres")
    height, width = int(shape[0]), int(shape[1])
    _check_size(p, "depth image", width, height, dtype.itemsize, 1.0)
    try:
        arr = np.load(p, allow_pickle=False)
    except (ValueError, OSError, EOFError) as exc:
        raise InputError(f"cannot read depth image {p}: {' '.join(str(exc).split())[:120]}") from None
    depth = np.asarray(arr, dtype=np.float32)
    with np.errstate(invalid="ignore"):
        depth[~(np.isfinite(depth) & (depth > 0))] = np.nan
    return depth


def parse_intrinsics(spec: str) -> Intrinsics:
    """Intrinsics from ``"fx fy cx cy"`` [px] or the path of a ROS CameraInfo YAML.

    Raises:
        InputError: neither 4 numbers nor a readable CameraInfo file; non-finite or non-positive focal lengths.
    """
    text = spec.strip()
    try:
        path = Path(text).expanduser()
        is_file = path.suffix.lower() in (".yaml", ".yml") or path.is_file()
    except (OSError, ValueError, RuntimeError):
        is_file = False
    if is_file:
        return _camera_info(path)
    tokens = text.replace(",", " ").split()
    try:
        numbers = [float(t) for t in tokens]
    except ValueError:
        numbers = []
    if len(numbers) != 4:
        raise InputError(
            f"--intrinsics {brief(spec)} is neither 4 numbers 'fx fy cx cy' [px] nor a CameraInfo YAML file"
        )
    return Intrinsics(numbers[0], numbers[1], numbers[2], numbers[3])


def _camera_info(path: Path) -> Intrinsics:
    if not path.is_file():
        raise InputError(f"CameraInfo YAML not found: {brief(str(path), 200)}")
    doc = read_document(path, "CameraInfo YAML", MAX_YAML_BYTES)
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected a CameraInfo mapping with camera_matrix (or K / k)")
    matrix: Any = doc.get("camera_matrix")
    if isinstance(matrix, dict):
        matrix = matrix.get("data")
    if matrix is None:
        matrix = doc.get("K", doc.get("k"))
    if not isinstance(matrix, list) or len(matrix) != 9:
        raise InputError(
            f"{path}: camera_matrix.data (or K / k) must be a list of 9 numbers, got {brief(matrix)}"
        )
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in matrix):
        raise InputError(f"{path}: camera_matrix.data must hold numbers, got {brief(matrix)}")
    size = []
    for key in ("image_width", "image_height", "width", "height"):
        value = doc.get(key)
        if isinstance(value, int) and not isinstance(value, bool) and value > 0:
            size.append(value)
    width, height = (size[0], size[1]) if len(size) >= 2 else (None, None)
    k = [float(v) for v in matrix]
    return Intrinsics(k[0], k[4], k[2], k[5], width, height)


def load_frame(rgb: str | Path, depth: str | Path, intrinsics: str | Intrinsics) -> RgbdFrame:
    """The RGB image, the aligned depth image and the intrinsics, checked to agree in size.

    Raises:
        InputError: any file unreadable or too large, the two images of different sizes, or a
            principal point outside the image.
    """
    K = intrinsics if isinstance(intrinsics, Intrinsics) else parse_intrinsics(intrinsics)
    image = load_rgb(rgb)
    d = load_depth(depth)
    if image.shape[:2] != d.shape:
        raise InputError(
            f"the RGB image is {image.shape[1]}x{image.shape[0]} and the depth image {d.shape[1]}x{d.shape[0]}; "
            "they must be aligned (the same size)"
        )
    K.check_image(image.shape[1], image.shape[0])
    return RgbdFrame(image, d, K)


__all__ = ["Intrinsics", "RgbdFrame", "load_depth", "load_frame", "load_rgb", "parse_intrinsics"]
