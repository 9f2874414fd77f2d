"""Floor plans from real map files: ROS ``map_server`` PGM + YAML and DungeonMaps PNG.

A :class:`FloorPlan` is a free/occupied mask with a resolution and an origin, in the project's
grid convention (CONTRIBUTING.md): arrays ``[iy, ix]`` with **row 0 at the bottom** (image files
have row 0 at the top, so loaders flip them), ``origin`` = world position of the lower-left
corner of cell ``(0, 0)``. The env turns floor plans into worlds; ``topo.extract_topomap`` turns
them into ground-truth topological maps.

* ROS (``load_ros_map``): the YAML's ``image`` (PGM/PNG, relative to the YAML), ``resolution``,
  ``origin [x, y, yaw]``, ``negate``, ``occupied_thresh``, ``free_thresh`` and optional ``mode``
  (``trinary``/``scale``: ``p = (255 − v) / 255``, or ``1 − p`` with ``negate``; ``raw``:
  ``p = v / 100``). ``p > occupied_thresh`` is occupied, ``p < free_thresh`` free, the rest
  unknown — map_server's rule.
* DungeonMaps (``load_dungeon_png``): grey > 150 is free (the 208-grey start square too),
  darker is an obstacle; no scale is stored, so ``resolution`` is an argument.

Every problem with a file (missing, truncated, bad header, missing YAML key, an image over
:data:`MAX_MAP_PIXELS`) raises
:class:`MapFileError` naming the file and what is wrong.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from topo.validation import check_real

MAX_MAP_PIXELS = 2 ** 26
"""Largest map image read, in pixels: the image is held as float64 grey levels (8 bytes a
pixel, 512 MiB at this size) before it becomes masks, so a larger one is refused from its header
before it is decoded."""

DUNGEON_FREE_ABOVE = 150
"""DungeonMaps grey levels above this are free space."""


class MapFileError(ValueError):
    """A map file that cannot be read; the message names the file and the problem."""


@dataclass(frozen=True, slots=True, eq=False)
class FloorPlan:
    """A known map: ``free`` and ``occupied`` boolean masks ``(H, W)`` (neither = unknown),
    ``resolution`` in m/cell, ``origin`` of cell (0, 0)'s lower-left corner, a ``name`` and
    the origin's ``yaw``."""

    free: np.ndarray
    occupied: np.ndarray
    resolution: float
    origin: tuple[float, float]
    name: str
    yaw: float = 0.0
    """The ROS origin's yaw (radians): the map's frame turned by this about ``origin``
    (read only with ``load_ros_map(..., allow_yaw=True)``; the env's worlds need 0)."""

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.free.shape)

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """``(xmin, ymin, xmax, ymax)`` in metres."""
        h, w = self.free.shape
        x0, y0 = self.origin
        return (x0, y0, x0 + w * self.resolution, y0 + h * self.resolution)

    def free_area_m2(self) -> float:
        return float(self.free.sum()) * self.resolution ** 2


_WIDE_MODES = ("I", "I;16", "I;16B", "I;16L", "I;16N")
"""16-bit images (PGM with maxval > 255, 16-bit PNG): Pillow gives 0..65535 here."""


def _read_image(path: Path, what: str) -> np.ndarray:
    """The image's grey levels as float64 in ``[0, 255]``, image order (row 0 at the top).

    8-bit images are Pillow's luma (``convert("L")``); 16-bit ones are scaled by 255/65535
    (Pillow already stretches a PGM's ``maxval`` to the full range), not clipped."""
    from PIL import Image, UnidentifiedImageError

    if not path.is_file():
        raise MapFileError(f"{path}: {what} file not found")
    try:
        with Image.open(path) as im:
            width, height = im.size
            if width * height > MAX_MAP_PIXELS:
                raise MapFileError(f"{path}: {what} of {width} x {height} pixels is larger "
                                   f"than MAX_MAP_PIXELS = {MAX_MAP_PIXELS}")
            im.load()
            if im.mode in _WIDE_MODES:
                grey = np.asarray(im, dtype=np.float64) * (255.0 / 65535.0)
            elif im.mode in ("1", "L", "P", "RGB", "RGBA", "LA", "PA"):
                grey = np.asarray(im.convert("L"), dtype=np.float64)
            else:
                raise MapFileError(f"{path}: unsupported image mode {im.mode!r}; expected a "
                                   "grey, palette or RGB(A) image")
    except MapFileError:
        raise
    except (UnidentifiedImageError, Image.DecompressionBombError, OSError, SyntaxError,
            ValueError) as exc:
        raise MapFileError(f"{path}: cannot read the image (truncated or bad header: {exc})"
                           ) from exc
    if grey.ndim != 2 or min(grey.shape) < 2:
        raise MapFileError(f"{path}: image must be 2-D and at least 2x2, got {grey.shape}")
    return np.clip(grey, 0.0, 255.0)


def _yaml_number(meta: dict[str, Any], key: str, path: Path, **bounds: Any) -> float:
    if key not in meta:
        raise MapFileError(f"{path}: missing key {key!r}")
    try:
        return check_real(meta[key], key, **bounds)
    except (TypeError, ValueError) as exc:
        raise MapFileError(f"{path}: {exc}") from exc


def load_ros_map(yaml_path: str | Path, *, allow_yaw: bool = False) -> FloorPlan:
    """Load a ROS ``map_server`` map (YAML + image) as a :class:`FloorPlan`.

    A non-zero origin yaw is refused unless ``allow_yaw`` (the env's worlds are axis-aligned;
    the map-merge tool, :mod:`fusion.mapmerge`, reads it into :attr:`FloorPlan.yaw`). In
    ``raw`` mode a pixel is the occupancy value itself (0–100) and anything above 100 is
    unknown (map_server writes such a value as −1)."""
    import yaml

    path = Path(yaml_path)
    if not path.is_file():
        raise MapFileError(f"{path}: map YAML file not found")
    try:
        meta = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        raise MapFileError(f"{path}: not valid YAML ({exc})") from exc
    if not isinstance(meta, dict):
        raise MapFileError(f"{path}: expected a YAML mapping, got {type(meta).__name__}")
    if "image" not in meta:
        raise MapFileError(f"{path}: missing key 'image' (the map image file name)")
    if not isinstance(meta["image"], str) or not meta["image"].strip():
        raise MapFileError(f"{path}: 'image' must be the map image file name, got "
                           f"{meta['image']!r}")
    resolution = _yaml_number(meta, "resolution", path, low=0.0)
    occ_t = _yaml_number(meta, "occupied_thresh", path, low=0.0, high=1.0)
    free_t = _yaml_number(meta, "free_thresh", path, low=0.0, low_inclusive=True, high=1.0)
    if free_t > occ_t:
        raise MapFileError(f"{path}: free_thresh ({free_t}) must be <= occupied_thresh "
                           f"({occ_t})")
    origin = meta.get("origin")
    if (not isinstance(origin, list) or len(origin) != 3
            or not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                       and math.isfinite(v) for v in origin)):
        raise MapFileError(f"{path}: 'origin' must be [x, y, yaw] of finite numbers, got "
                           f"{origin!r}")
    if origin[2] != 0 and not allow_yaw:
        raise MapFileError(f"{path}: origin yaw must be 0 (rotated map origins are not "
                           f"supported), got {origin[2]}")
    mode = meta.get("mode", "trinary")
    if mode not in ("trinary", "scale", "raw"):
        raise MapFileError(f"{path}: mode must be 'trinary', 'scale' or 'raw', got {mode!r}")
    negate = meta.get("negate", 0)
    if negate not in (0, 1, True, False):
        raise MapFileError(f"{path}: negate must be 0 or 1, got {negate!r}")

    image_path = Path(meta["image"])
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    if not image_path.is_file():
        raise MapFileError(f"{path}: names image {image_path}: map image file not found")
    grey = _read_image(image_path, "map image")[::-1]  # row 0 at the bottom
    if mode == "raw":
        p = np.where(grey <= 100.0, grey / 100.0, np.nan)  # NaN: unknown (neither mask)
    else:
        p = grey / 255.0 if negate else (255.0 - grey) / 255.0
    return _trinary(p, free_t, occ_t, resolution, (float(origin[0]), float(origin[1])),
                    path.stem, float(origin[2]))


def _trinary(p: np.ndarray, free_thresh: float, occupied_thresh: float, resolution: float,
             origin: tuple[float, float], name: str, yaw: float = 0.0) -> FloorPlan:
    """``map_server``'s trinary rule on occupancy probabilities ``p`` (rows bottom-up): free
    below ``free_thresh``, occupied above ``occupied_thresh``, unknown between (or NaN)."""
    return FloorPlan(free=np.ascontiguousarray(p < free_thresh),
                     occupied=np.ascontiguousarray(p > occupied_thresh), resolution=resolution,
                     origin=origin, name=name, yaw=yaw)


ROS_FREE_GREY, ROS_UNKNOWN_GREY, ROS_OCCUPIED_GREY = 254, 205, 0
"""Grey levels ``map_saver`` writes for free, unknown and occupied cells (trinary)."""


def save_ros_map(plan: FloorPlan, yaml_path: str | Path) -> Path:
    """Write ``plan`` as a ROS ``map_server`` map: a trinary PGM (free 254, unknown 205,
    occupied 0; image row 0 at the top) beside ``yaml_path``, named after it, and the YAML
    (``mode: trinary``, ``negate: 0``, ``occupied_thresh: 0.65``, ``free_thresh: 0.196``:
    ``map_saver``'s values, so :func:`load_ros_map` reads back the same masks). Both files are
    written atomically, the image first. Returns the YAML's path.

    Raises:
        ValueError: ``plan``'s masks overlap or differ in shape.
    """
    import io

    from PIL import Image

    from topo.fileio import atomic_write_bytes

    path = Path(yaml_path)
    if plan.free.shape != plan.occupied.shape or plan.free.ndim != 2:
        raise ValueError(f"plan.free {plan.free.shape} and plan.occupied "
                         f"{plan.occupied.shape} must be 2-D masks of one shape")
    if (plan.free & plan.occupied).any():
        raise ValueError("plan.free and plan.occupied overlap: a cell is one or the other")
    grey = np.full(plan.free.shape, ROS_UNKNOWN_GREY, dtype=np.uint8)
    grey[plan.free] = ROS_FREE_GREY
    grey[plan.occupied] = ROS_OCCUPIED_GREY
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(grey[::-1])).save(buf, format="PPM")
    image = path.with_suffix(".pgm")
    atomic_write_bytes(image, buf.getvalue())
    x0, y0 = plan.origin
    text = (f"image: {image.name}\nmode: trinary\nresolution: {float(plan.resolution)!r}\n"
            f"origin: [{float(x0)!r}, {float(y0)!r}, {float(plan.yaw)!r}]\nnegate: 0\n"
            "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
    atomic_write_bytes(path, text.encode())
    return path


def load_dungeon_png(png_path: str | Path, resolution: float = 0.1) -> FloorPlan:
    """Load a DungeonMaps PNG (grey > 150 free, darker obstacle) at ``resolution`` m/pixel;
    the origin is the image's lower-left corner at (0, 0)."""
    resolution = check_real(resolution, "resolution", low=0.0)
    path = Path(png_path)
    grey = _read_image(path, "DungeonMaps PNG")[::-1]
    free = grey > DUNGEON_FREE_ABOVE
    return FloorPlan(free=np.ascontiguousarray(free), occupied=np.ascontiguousarray(~free),
                     resolution=resolution, origin=(0.0, 0.0), name=path.stem)


def load_plain_image(path: str | Path, resolution: float, occupied_thresh: float = 0.65,
                     free_thresh: float = 0.196) -> FloorPlan:
    """Load an occupancy image without a YAML (a PGM ``map_saver`` wrote, say) at
    ``resolution`` m/pixel, by ``map_server``'s trinary rule with its default thresholds
    (``p = (255 − v) / 255``); the origin is the image's lower-left corner at (0, 0)."""
    resolution = check_real(resolution, "resolution", low=0.0)
    path = Path(path)
    p = (255.0 - _read_image(path, "map image")[::-1]) / 255.0
    return _trinary(p, free_thresh, occupied_thresh, resolution, (0.0, 0.0), path.stem)


def load_floor_plan(path: str | Path, resolution: float | None = None) -> FloorPlan:
    """Load a map file by its suffix: ``.yaml``/``.yml`` (ROS) or ``.png`` (DungeonMaps, at
    ``resolution`` m/pixel, default 0.1). ``resolution`` is refused for ROS maps (their YAML
    sets it)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        if resolution is not None:
            raise ValueError(f"resolution is set by the ROS map's YAML ({path.name}); "
                             f"got resolution={resolution}")
        return load_ros_map(path)
    if suffix == ".png":
        return load_dungeon_png(path, 0.1 if resolution is None else resolution)
    raise MapFileError(f"{path}: unknown map format {suffix!r}; expected .yaml/.yml (ROS "
                       "map_server) or .png (DungeonMaps)")
