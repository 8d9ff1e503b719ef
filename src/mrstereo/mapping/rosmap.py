"""ROS map_server / Nav2 maps: a PGM image (254 free, 0 occupied, 205 unknown; top row max y) and a
YAML description (image, resolution, origin of the lower-left pixel, thresholds, trinary mode).
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml

from .. import _checks
from ..io import atomic_write, read_image, read_yaml, write_image
from .grid import GridSpec

__all__ = ["RosMap", "read_ros_map", "write_ros_map", "write_map_yaml", "ros_map_files", "occupancy_values",
           "check_thresholds", "ros_map_on_grid", "array_on_grid", "FREE", "OCCUPIED", "UNKNOWN"]

FREE, OCCUPIED, UNKNOWN = 254, 0, 205


def check_thresholds(occupied_thresh, free_thresh, *, where: str = "") -> tuple[float, float]:
    """``(occupied_thresh, free_thresh)`` as floats: probabilities with ``free_thresh < occupied_thresh``.

    Thresholds outside [0, 1] or in the wrong order turn walls free (a planner drives through them):
    refused with a ``ValueError`` (prefixed by ``where``).
    """
    prefix = f"{where}: " if where else ""
    occupied = _checks.finite_number("occupied_thresh", occupied_thresh)
    free = _checks.finite_number("free_thresh", free_thresh)
    for name, value in (("occupied_thresh", occupied), ("free_thresh", free)):
        if not 0.0 <= value <= 1.0:
            raise ValueError(f"{prefix}{name} must be a probability in [0, 1], got {value:g}")
    if not free < occupied:
        raise ValueError(f"{prefix}free_thresh ({free:g}) must be below occupied_thresh ({occupied:g})")
    return occupied, free


@dataclass(frozen=True)
class RosMap:
    """A trinary map: ``occupancy`` is float (rows, cols) in [0, 1], NaN unknown, row 0 = min y.

    ``occupancy`` must have the shape of ``grid``; a cell is occupied above ``occupied_thresh`` and
    free below ``free_thresh``, two probabilities with ``0 <= free_thresh < occupied_thresh <= 1``.
    """

    occupancy: np.ndarray
    grid: GridSpec
    occupied_thresh: float = 0.65
    free_thresh: float = 0.196   # as ROS map_saver: 205 (p = 0.196) must read back as unknown

    def __post_init__(self) -> None:
        if not isinstance(self.grid, GridSpec):
            raise TypeError(f"grid must be a GridSpec, got {type(self.grid).__name__}")
        occupancy = np.asarray(self.occupancy)
        if occupancy.dtype.kind not in "fiub":
            raise TypeError(f"occupancy must hold numbers (probabilities), got dtype {occupancy.dtype}")
        if occupancy.shape != self.grid.shape:
            raise ValueError(f"occupancy has shape {occupancy.shape} but the grid is {self.grid.shape} "
                             "(rows, cols)")
        check_thresholds(self.occupied_thresh, self.free_thresh)

    @property
    def occupied(self) -> np.ndarray:
        return np.nan_to_num(self.occupancy, nan=0.0) > self.occupied_thresh

    @property
    def free(self) -> np.ndarray:
        return np.nan_to_num(self.occupancy, nan=1.0) < self.free_thresh

    @property
    def unknown(self) -> np.ndarray:
        return ~(self.occupied | self.free)


def occupancy_values(probability, *, trinary: bool = True, occupied_thresh: float = RosMap.occupied_thresh,
                     free_thresh: float = RosMap.free_thresh) -> np.ndarray:
    """``nav_msgs/OccupancyGrid`` data of occupancy probabilities (rows, cols), NaN unknown, rows in the same
    order (row 0 at the grid's origin, the lowest y): int8, -1 unknown.

    ``trinary`` (default): 100 above ``occupied_thresh``, 0 below ``free_thresh``, -1 between, the values
    map_server and slam_toolbox publish and the thresholds of map.yaml, so that Nav2's static layer with its
    defaults (trinary, lethal at 100) sees the obstacles of map.pgm. Otherwise the probability in percent
    (0 free .. 100 occupied).
    """
    p = np.asarray(probability, dtype=np.float64)
    if trinary:
        occupied, free = check_thresholds(occupied_thresh, free_thresh)
        known = np.nan_to_num(p, nan=0.5 * (occupied + free))
        return np.where(known > occupied, 100, np.where(known < free, 0, -1)).astype(np.int8)
    return np.where(np.isnan(p), -1, np.rint(np.clip(np.nan_to_num(p), 0.0, 1.0) * 100.0)).astype(np.int8)


def as_ros_map(name: str, value) -> RosMap:
    """``value`` as a RosMap (an OccupancyGrid converted), else TypeError naming ``name``."""
    if hasattr(value, "to_ros_map") and not isinstance(value, RosMap):
        value = value.to_ros_map()
    if not isinstance(value, RosMap):
        raise TypeError(f"{name} must be a RosMap or OccupancyGrid, got {type(value).__name__}")
    return value


def write_ros_map(yaml_path: str | os.PathLike, ros_map: RosMap) -> None:
    """Write ``NAME.yaml`` and ``NAME.pgm`` beside it (atomically)."""
    _checks.instance("ros_map", ros_map, RosMap)
    yaml_path = Path(yaml_path)
    pgm_path = yaml_path.with_suffix(".pgm")
    image = np.full(ros_map.occupancy.shape, UNKNOWN, np.uint8)
    image[ros_map.free] = FREE
    image[ros_map.occupied] = OCCUPIED
    write_image(pgm_path, np.flipud(image))
    write_map_yaml(yaml_path, pgm_path.name, ros_map.grid, ros_map.occupied_thresh, ros_map.free_thresh)


def write_map_yaml(yaml_path: str | os.PathLike, image_name: str, grid: GridSpec, occupied_thresh: float = 0.65,
                   free_thresh: float = 0.196) -> None:
    """Write the map_server YAML of a trinary map image ``image_name`` (beside it) on ``grid``, atomically."""
    meta = {"image": image_name, "resolution": float(grid.resolution_m),
            "origin": [float(grid.origin_x_m), float(grid.origin_y_m), 0.0], "negate": 0,
            "occupied_thresh": float(occupied_thresh), "free_thresh": float(free_thresh), "mode": "trinary"}
    with atomic_write(yaml_path) as tmp:
        tmp.write_text(yaml.safe_dump(meta, sort_keys=False, default_flow_style=None))


def ros_map_files(yaml_path: str | os.PathLike) -> list[Path]:
    """The files of a map: the YAML and the image it names (else ``NAME.pgm``) -- what a reader reads."""
    yaml_path = Path(yaml_path)
    files = [yaml_path, yaml_path.with_suffix(".pgm")]
    try:
        meta = read_yaml(yaml_path, "map file")
        files.append(yaml_path.parent / str(meta["image"]))
    except (OSError, ValueError, TypeError, KeyError):
        pass
    return files


def read_ros_map(yaml_path: str | os.PathLike) -> RosMap:
    """Read a map_server YAML + image (trinary or scale, negate 0/1)."""
    yaml_path = Path(yaml_path)
    if not yaml_path.is_file():
        raise FileNotFoundError(f"map file not found: {yaml_path}")
    meta = read_yaml(yaml_path, "map file")
    if not isinstance(meta, dict):
        raise ValueError(f"map file {yaml_path}: expected a mapping")
    for key in ("image", "resolution", "origin"):
        if key not in meta:
            raise ValueError(f"map file {yaml_path}: missing field '{key}'")
    try:
        resolution = float(meta["resolution"])
        ox, oy = float(meta["origin"][0]), float(meta["origin"][1])
        occ_t = float(meta.get("occupied_thresh", 0.65))
        free_t = float(meta.get("free_thresh", 0.196))
    except (TypeError, ValueError, IndexError):
        raise ValueError(f"map file {yaml_path}: resolution/origin/thresholds must be numbers") from None
    if not np.isfinite([resolution, ox, oy, occ_t, free_t]).all() or resolution <= 0:
        raise ValueError(f"map file {yaml_path}: resolution must be > 0 and all numbers finite")
    check_thresholds(occ_t, free_t, where=f"map file {yaml_path}")
    negate, mode = meta.get("negate", 0), meta.get("mode", "trinary")
    if negate not in (0, 1, False, True):
        raise ValueError(f"map file {yaml_path}: negate must be 0 or 1, got {negate!r}")
    if mode not in ("trinary", "scale", "raw"):
        raise ValueError(f"map file {yaml_path}: mode must be trinary, scale or raw, got {mode!r}")
    if not isinstance(meta["image"], str) or not meta["image"]:
        raise ValueError(f"map file {yaml_path}: image must be a file name, got {meta['image']!r}")
    image = read_image(yaml_path.parent / meta["image"], gray=True)
    if image.dtype != np.uint8:
        image = np.round(image / 257.0).astype(np.uint8)
    p = (255.0 - image.astype(np.float64)) / 255.0 if not negate else image / 255.0
    occupancy = np.flipud(p).copy()
    if mode == "trinary":
        occupancy[(image == UNKNOWN)[::-1]] = np.nan
    rows, cols = occupancy.shape
    grid = GridSpec(width_m=cols * resolution, height_m=rows * resolution, resolution_m=resolution,
                    origin_x_m=ox, origin_y_m=oy)
    return RosMap(occupancy=occupancy, grid=grid, occupied_thresh=occ_t, free_thresh=free_t)


def ros_map_on_grid(ros_map: RosMap, grid: GridSpec) -> RosMap | None:
    """``ros_map`` on another grid of the same resolution whose origin is a whole number of cells away
    (e.g. a map built with another ``--origin`` or ``--size``): its cells where the two overlap, unknown
    elsewhere. None when the resolutions differ or the origins are not whole cells apart."""
    out = array_on_grid(ros_map.occupancy, ros_map.grid, grid)
    if out is None:
        return None
    return RosMap(occupancy=out, grid=grid, occupied_thresh=ros_map.occupied_thresh, free_thresh=ros_map.free_thresh)


def array_on_grid(values: np.ndarray, src: GridSpec, grid: GridSpec) -> np.ndarray | None:
    """The cell values (rows, cols) of grid ``src`` on ``grid`` (float, NaN where ``src`` has no cell), or None
    when the resolutions differ or the origins are not a whole number of cells apart."""
    res = src.resolution_m
    if not isinstance(grid, GridSpec):
        raise TypeError(f"grid must be a GridSpec, got {type(grid).__name__}")
    if abs(grid.resolution_m - res) > 1e-9 * res:
        return None
    shift = np.array([(grid.origin_y_m - src.origin_y_m) / res, (grid.origin_x_m - src.origin_x_m) / res])
    if np.abs(shift - np.round(shift)).max() > 1e-6:
        return None
    dr, dc = (int(v) for v in np.round(shift))
    out = np.full(grid.shape, np.nan)
    rows, cols = grid.shape
    src_rows, src_cols = src.shape
    r0, r1 = max(0, -dr), min(rows, src_rows - dr)
    c0, c1 = max(0, -dc), min(cols, src_cols - dc)
    if r0 < r1 and c0 < c1:
        out[r0:r1, c0:c1] = values[r0 + dr:r1 + dr, c0 + dc:c1 + dc]
    return out
