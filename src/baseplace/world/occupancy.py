"""2-D occupancy grids in ROS map_server format (a YAML file next to a PGM, PNG or BMP image).

The YAML and the image are interpreted exactly as nav2 map_server does (``nav2_map_server``,
``map_io.cpp``: ``loadMapYaml`` and ``loadMapFromFile``):

* keys ``image`` (relative to the YAML's directory unless absolute), ``resolution`` [m/cell],
  ``origin`` [x, y, yaw] (the pose of the lower-left cell's lower-left corner), ``negate``,
  ``occupied_thresh`` and ``free_thresh`` are required; ``mode`` (trinary, scale or raw,
  case-insensitive) defaults to trinary;
* a pixel's shade is the mean of its R, G, B channels over the channel maximum, computed as
  GraphicsMagick Q16 does (8-bit values scaled by 257, then divided by 65535); in trinary mode an
  alpha channel, when present, is averaged in as a fourth channel;
* ``occ = shade`` if ``negate`` else ``1 - shade``;
* trinary: ``occ > occupied_thresh`` -> 100, ``occ < free_thresh`` -> 0, else -1;
* scale: a pixel that is not fully opaque -> -1, then as trinary, except that values in between
  become ``rint((occ - free) / (occupied - free) * 100)``;
* raw: ``round(shade * 255)`` when in 0..100, else -1 (``negate`` is ignored);
* the image's top row is the map's last row: ``data[0]`` is the bottom row, as in
  ``nav_msgs/OccupancyGrid`` (row-major, lower-left cell first).

Beyond map_server, the loader rejects what map_server would accept silently but is wrong:
a resolution <= 0, thresholds outside [0, 1] or ``free_thresh >= occupied_thresh``.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from numpy.typing import ArrayLike, NDArray

from baseplace.errors import InputError, brief, unknown
from baseplace.guards import check_alloc, check_grid_size, check_path_length, read_document

MODES = ("trinary", "scale", "raw")
IMAGE_FORMATS = (".bmp", ".pgm", ".png")
REQUIRED_KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh")
MAX_YAML_BYTES = 64 << 10
"""The largest map YAML read [bytes]: its keys and an image path of at most 4095 bytes fit many times."""
OCCUPIED, FREE, UNKNOWN = 100, 0, -1
LETHAL = 100  # nav2 costmap StaticLayer's default lethal_cost_threshold


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """An occupancy grid: cell values -1 (unknown), 0 (free) .. 100 (occupied).

    Cell ``(i, j)`` (column i, row j) has its centre at
    ``origin_xy + R(yaw) @ ((i + 0.5) * resolution, (j + 0.5) * resolution)``.

    Attributes:
        data: (H, W) int8 cell values; row 0 is the bottom row (lower-left cell first).
        resolution: cell size [m].
        origin: (x [m], y [m], yaw [rad]) of the lower-left corner of cell (0, 0).
        source: the YAML file it was loaded from, if any.
    """

    data: NDArray[np.int8]
    resolution: float
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    source: Path | None = None
    _edt_cache: dict[int, NDArray[np.float64]] = field(default_factory=dict, repr=False, init=False)

    def __post_init__(self) -> None:
        check_grid_cells(np.shape(self.data), self.source)
        data = np.array(self.data, dtype=np.int8)
        if data.ndim != 2 or data.size == 0:
            raise InputError(f"occupancy data must be a non-empty 2-D array, got shape {data.shape}")
        data.setflags(write=False)
        object.__setattr__(self, "data", data)
        object.__setattr__(self, "resolution", float(self.resolution))
        object.__setattr__(self, "origin", tuple(float(v) for v in self.origin))
        if not self.resolution > 0 or len(self.origin) != 3:
            raise InputError(
                f"need resolution > 0 and origin (x, y, yaw), got {self.resolution}, {self.origin}"
            )

    @property
    def width(self) -> int:
        """Number of columns."""
        return int(self.data.shape[1])

    @property
    def height(self) -> int:
        """Number of rows."""
        return int(self.data.shape[0])

    def _rotation(self) -> NDArray[np.float64]:
        c, s = math.cos(self.origin[2]), math.sin(self.origin[2])
        return np.array([[c, -s], [s, c]])

    def world_to_cell(self, xy: ArrayLike) -> NDArray[np.int64]:
        """The (column, row) of the cells containing world points ``xy`` (N, 2) [m]; may lie outside."""
        p = np.atleast_2d(np.asarray(xy, dtype=float)) - np.array(self.origin[:2])
        local = p @ self._rotation()  # rows of R^T @ p
        return np.floor(local / self.resolution).astype(np.int64)

    def cell_to_world(self, cells: ArrayLike) -> NDArray[np.float64]:
        """World coordinates (N, 2) [m] of the centres of cells (column, row) (N, 2)."""
        c = np.atleast_2d(np.asarray(cells, dtype=float))
        return (c + 0.5) * self.resolution @ self._rotation().T + np.array(self.origin[:2])

    def inside(self, xy: ArrayLike) -> NDArray[np.bool_]:
        """(N,) whether each world point lies on the map."""
        ij = self.world_to_cell(xy)
        return (ij[:, 0] >= 0) & (ij[:, 0] < self.width) & (ij[:, 1] >= 0) & (ij[:, 1] < self.height)

    def _lookup(self, xy: ArrayLike, grid: NDArray[Any], outside: float) -> NDArray[Any]:
        ij = self.world_to_cell(xy)
        ok = self.inside(xy)
        out = np.full(len(ij), outside, dtype=grid.dtype)
        out[ok] = grid[ij[ok, 1], ij[ok, 0]]
        return out

    def value_at(self, xy: ArrayLike) -> NDArray[np.int8]:
        """(N,) cell values at world points ``xy`` (N, 2) [m]; -1 (unknown) off the map."""
        return self._lookup(xy, self.data, UNKNOWN)

    def is_free(
        self, xy: ArrayLike, allow_unknown: bool = False, threshold: int = LETHAL
    ) -> NDArray[np.bool_]:
        """(N,) whether the cells at ``xy`` are free: 0 <= value < ``threshold``.

        Args:
            xy: (N, 2) world points [m].
            allow_unknown: also count unknown (-1) cells as free; points off the map never are.
            threshold: values >= this are obstacles (default 100, nav2's lethal threshold).
        """
        v = self.value_at(xy)
        free = (v >= 0) & (v < threshold)
        if allow_unknown:
            free |= (v == UNKNOWN) & self.inside(xy)
        return free

    def _edt(self, threshold: int) -> NDArray[np.float64]:
        """Distance [cells] from each cell centre to the nearest occupied (>= threshold) cell centre."""
        if threshold not in self._edt_cache:
            occupied = self.data >= threshold
            if not occupied.any():
                dist = np.full(self.data.shape, np.inf)
            else:
                from scipy.ndimage import distance_transform_edt  # here: most commands never need it (0.5 s)

                dist = np.asarray(distance_transform_edt(~occupied), dtype=float)
            self._edt_cache[threshold] = dist
        return self._edt_cache[threshold]

    def inflated(self, radius: float, threshold: int = LETHAL) -> OccupancyGrid:
        """A copy in which every cell whose centre lies within ``radius`` [m] of an occupied cell centre is 100.

        A cell is occupied when its value >= ``threshold``. Distances are exact Euclidean distances
        between cell centres (scipy's EDT); ``radius = k * resolution`` includes distance k cells.
        """
        if not radius >= 0:
            raise InputError(f"inflation radius must be >= 0 m, got {radius}")
        r = radius / self.resolution
        grow = self._edt(threshold) ** 2 <= r * r + 1e-9
        return replace(self, data=np.where(grow, np.int8(OCCUPIED), self.data))

    def clearance(self, xy: ArrayLike, threshold: int = LETHAL) -> NDArray[np.float64]:
        """(N,) distance [m] from the centre of the cell at each point to the nearest occupied cell centre.

        0 for points off the map or on an occupied cell; inf when the map has no occupied cell.
        """
        return self._lookup(xy, self._edt(threshold) * self.resolution, 0.0)

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict: width, height, resolution, origin [x, y, yaw], data (row-major, lower-left first)."""
        return {
            "width": self.width,
            "height": self.height,
            "resolution": self.resolution,
            "origin": list(self.origin),
            "data": self.data.ravel().tolist(),
        }


GRID_BYTES_PER_CELL = 64.0
"""Peak bytes per cell of a grid in use: its int8 cells, the float64 distance transform kept for
clearances, and scipy's feature transform while it is computed (measured: 35)."""


def check_grid_cells(shape: tuple[int, ...], source: object = None) -> None:
    """Refuse an occupancy grid of ``shape`` (H, W) whose use would not fit the memory cap.

    Every grid is checked when it is made (:class:`OccupancyGrid`); a caller that builds one from
    a size it reads (a message's width and height) calls this first.

    Raises:
        InputError: one line with the cell count and the limit.
    """
    cells = float(np.prod(shape, dtype=float))
    check_grid_size(
        cells, GRID_BYTES_PER_CELL,
        f"{'' if source is None else f'{source}: '}an occupancy grid of "
        f"{' x '.join(str(int(v)) for v in shape)} = {cells:.3g} cells",
        "use a coarser or smaller map",
    )  # fmt: skip


def _number(doc: dict[str, Any], key: str, where: str) -> float:
    v = doc[key]
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise InputError(f"{where}: '{key}' must be a finite number, got {brief(v)}")
    return float(v)


def _read_yaml(path: Path) -> dict[str, Any]:
    if not path.is_file():
        raise InputError(f"occupancy map YAML not found: {path}")
    doc = read_document(path, "map YAML", MAX_YAML_BYTES, "map_server's holds an image path and six numbers")
    if not isinstance(doc, dict):
        raise InputError(f"{path}: expected a YAML mapping with keys {', '.join(REQUIRED_KEYS)}[, mode]")
    for key in REQUIRED_KEYS:
        if key not in doc or doc[key] is None:
            raise InputError(f"{path}: missing key '{key}'; required: {', '.join(REQUIRED_KEYS)}")
    return doc


def _read_image(path: Path, where: str) -> NDArray[Any]:
    """The image as (H, W[, C]) uint8 or uint16, as OpenCV decodes it (colour channels BGR[A])."""
    if path.suffix.lower() not in IMAGE_FORMATS:
        raise unknown("map image format", (path.suffix or path.name)[:60], IMAGE_FORMATS, owner=where)
    if not path.is_file():
        raise InputError(f"{where}: map image not found: {brief(str(path), 200)}")
    _check_image_size(path, where)
    buf = np.fromfile(path, dtype=np.uint8)
    level = cv2.utils.logging.getLogLevel()
    cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
    try:
        img = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED) if buf.size else None
    except cv2.error:
        img = None
    finally:
        cv2.utils.logging.setLogLevel(level)
    if img is None or img.size == 0 or img.dtype not in (np.uint8, np.uint16):
        raise InputError(
            f"{where}: cannot read map image {path} (corrupt, truncated or not a {path.suffix} image)"
        )
    return img


DEFLATE_MAX_RATIO = 1100.0  # PNG pixels are deflated: one byte of file holds at most ~1032 bytes
_CELL_BYTES = 80.0  # what occupancy_from_image and the grid hold per cell (float64 passes, int8 out)


def _check_image_size(path: Path, where: str) -> None:
    """Refuse an image whose declared size does not fit its file or the memory cap, before decoding.

    The header (read by Pillow, which decodes nothing until asked) declares width, height and
    bands; OpenCV would allocate them. PGM and BMP store pixels raw, PNG deflated.

    Raises:
        InputError: the image cannot hold its declared size, or decoding it would exceed the cap.
    """
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # Pillow warns about large images on stderr
            with Image.open(path) as im:
                width, height = im.size
                bands = len(im.getbands())
                depth = 2 if im.mode.startswith("I;16") or im.mode in ("I", "F") else 1
                compressed = im.format == "PNG"
    except Image.DecompressionBombError:
        raise InputError(f"{where}: map image {path} declares more pixels than any map has") from None
    except Exception:
        return  # OpenCV's decoder gives the one-line error for a corrupt image
    n_pixels = float(width) * float(height)
    check_alloc(n_pixels * bands * depth, "the map image", f"{where}: {path}", path.stat().st_size,
                DEFLATE_MAX_RATIO if compressed else 1.05)  # fmt: skip
    check_alloc(n_pixels * (_CELL_BYTES + 8 * bands), "the occupancy grid", f"{where}: {path}")


def occupancy_from_image(
    img: NDArray[Any], mode: str, negate: bool, occupied_thresh: float, free_thresh: float
) -> NDArray[np.int8]:
    """Cell values (H, W), bottom row first, of an image decoded by OpenCV, as nav2 map_server computes them."""
    if img.ndim == 2:
        img = img[..., None]
    scale = 257.0 if img.dtype == np.uint8 else 1.0  # to GraphicsMagick Q16 quantums
    q = img.astype(np.float64) * scale
    n_colour = 1 if q.shape[2] <= 2 else 3
    colour = q[..., :n_colour].sum(axis=2) * (3 / n_colour)  # grey counts as R = G = B
    has_alpha = q.shape[2] in (2, 4)
    alpha = q[..., -1] if has_alpha else np.full(q.shape[:2], 65535.0)
    if mode == "trinary" and has_alpha:
        shade = (colour + alpha) / 4 / 65535.0
    else:
        shade = colour / 3 / 65535.0
    occ = shade if negate else 1.0 - shade
    out = np.full(shade.shape, UNKNOWN, dtype=np.int8)
    if mode == "raw":
        x = shade * 255
        pct = np.floor(x)
        pct += x - pct >= 0.5  # std::round: halves away from zero (x >= 0 here)
        ok = (pct >= FREE) & (pct <= OCCUPIED)
        out[ok] = pct[ok]
    else:
        between = np.rint((occ - free_thresh) / (occupied_thresh - free_thresh) * 100.0)
        if mode == "scale":
            out[:] = np.clip(between, FREE, OCCUPIED)
        out[occ < free_thresh] = FREE
        out[occupied_thresh < occ] = OCCUPIED
        if mode == "scale":
            out[alpha != 65535.0] = UNKNOWN
    return out[::-1].copy()


def load_occupancy(path: str | Path) -> OccupancyGrid:
    """Load a ROS map_server map (YAML + PGM/PNG/BMP image), interpreted as nav2 map_server does.

    Args:
        path: the map's YAML file.

    Returns:
        The occupancy grid, with ``source`` set to ``path``.

    Raises:
        InputError: a missing or malformed YAML or image, with a one-line message.
    """
    path = Path(path)
    doc = _read_yaml(path)
    where = str(path)
    image = doc["image"]
    if not isinstance(image, str) or not image.strip():
        raise InputError(f"{where}: 'image' must be a non-empty file name, got {brief(image)}")
    check_path_length(image, f"{where}: 'image'")
    mode = doc.get("mode")
    mode = "trinary" if mode is None else mode.lower() if isinstance(mode, str) else mode
    if mode not in MODES:
        raise unknown(
            "map mode", mode if isinstance(mode, str) and len(mode) < 60 else brief(mode), MODES, owner=where
        )
    resolution = _number(doc, "resolution", where)
    if resolution <= 0:
        raise InputError(f"{where}: 'resolution' must be > 0 m/cell, got {resolution}")
    origin = doc["origin"]
    if not (
        isinstance(origin, list)
        and len(origin) == 3
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in origin)
    ):
        raise InputError(f"{where}: 'origin' must be 3 numbers [x, y, yaw], got {brief(origin)}")
    occupied, free = _number(doc, "occupied_thresh", where), _number(doc, "free_thresh", where)
    if not (0.0 <= free < occupied <= 1.0):
        raise InputError(
            f"{where}: need 0 <= free_thresh < occupied_thresh <= 1, got free_thresh={free}, occupied_thresh={occupied}"
        )
    negate = doc["negate"]
    if not isinstance(negate, int):  # bool is an int; map_server reads an int, else a bool
        raise InputError(f"{where}: 'negate' must be 0, 1, true or false, got {brief(negate)}")
    img = _read_image(path.parent / image, where)
    data = occupancy_from_image(img, mode, bool(negate), occupied, free)
    return OccupancyGrid(
        data, resolution, (float(origin[0]), float(origin[1]), float(origin[2])), source=path
    )


__all__ = ["IMAGE_FORMATS", "MODES", "OccupancyGrid", "load_occupancy", "occupancy_from_image"]
