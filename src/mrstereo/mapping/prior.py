"""A saved map to continue mapping on (``mrstereo map --resume-from map.yaml``, ``StereoMapper(prior=...)``).

A map_server map (PGM + YAML, trinary or scale) becomes log-odds: a cell the map holds occupied or free
(by the thresholds of its YAML, as map_server reads it) gets ``clip(logit(p), l_min, l_max)`` of its
probability ``p = (255 - value) / 255`` (a trinary map's occupied cell ``l_max``, its free cell ``l_min``:
as certain as the sensor model lets a cell be, :class:`~mrstereo.mapping.MappingConfig`), an unknown one
stays unknown (NaN). The origin and resolution come from the YAML; a map of another resolution is
refused (not resampled). An :class:`~mrstereo.mapping.OccupancyGrid` (a run's own map in memory) is taken
with its log-odds as they are. User guide: docs/mapping.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .grid import GridSpec
from .occupancy import MappingConfig, OccupancyGrid, log_odds_from_probability
from .rosmap import RosMap, array_on_grid, read_ros_map
from .tiles import TiledOccupancyGrid

__all__ = ["seeded", "prior_log_odds", "prior_grid"]


def prior_log_odds(ros_map: RosMap, config: MappingConfig) -> np.ndarray:
    """The log-odds (rows, cols; NaN unknown) of a map_server map's cells (see the module docstring)."""
    if not isinstance(ros_map, RosMap):
        raise TypeError(f"ros_map must be a RosMap, got {type(ros_map).__name__}")
    p = np.clip(np.nan_to_num(ros_map.occupancy, nan=0.5), 1e-9, 1.0 - 1e-9)
    log_odds = np.clip(log_odds_from_probability(p), config.l_min, config.l_max)
    return np.where(ros_map.unknown, np.nan, log_odds)


def prior_grid(prior, *, config: MappingConfig, resolution_m: float, grid: GridSpec | None = None) -> OccupancyGrid:
    """The saved map ``prior`` as an :class:`OccupancyGrid` to map on: on ``grid`` when the map has a fixed
    window (cells outside the prior unknown), else on the prior's own window.

    Parameters
    ----------
    prior : path, RosMap or OccupancyGrid
        A map_server YAML (``map.yaml`` of an earlier run), a map read, or a grid in memory.
    config : MappingConfig
        The sensor model (its clamping bounds).
    resolution_m : float
        The cell size of the map to be made: the prior's must be the same.
    grid : GridSpec, optional
        The fixed window of the map to be made; its origin must be whole cells from the prior's.

    Raises
    ------
    FileNotFoundError
        No such map file.
    ValueError
        An unreadable map, another resolution, a window whose cells do not line up with the prior's.
    TypeError
        ``prior`` of another type.
    """
    where = "prior"
    if isinstance(prior, (str, os.PathLike)):
        where = f"prior map {Path(prior)}"
        prior = read_ros_map(prior)
    if isinstance(prior, RosMap):
        spec, log_odds = prior.grid, prior_log_odds(prior, config)
    elif isinstance(prior, OccupancyGrid):
        spec, log_odds = prior.grid, np.array(prior.log_odds)
    else:
        raise TypeError(f"prior must be a map YAML path, a RosMap or an OccupancyGrid, got {type(prior).__name__}")
    if abs(spec.resolution_m - resolution_m) > 1e-9 * resolution_m:
        raise ValueError(f"{where} has cells of {spec.resolution_m:g} m, the map is made of {resolution_m:g} m cells: "
                         f"map with --resolution {spec.resolution_m:g} to continue it (it is not resampled)")
    if grid is None:
        return OccupancyGrid(spec, config=config, log_odds=log_odds)
    placed = array_on_grid(log_odds, spec, grid)
    if placed is None:
        raise ValueError(f"{where}: its origin ({spec.origin_x_m:g}, {spec.origin_y_m:g}) m is not a whole number "
                         f"of {resolution_m:g} m cells from the map's ({grid.origin_x_m:g}, {grid.origin_y_m:g}) m")
    return OccupancyGrid(grid, config=config, log_odds=placed)


def seeded(grid, prior, *, config: MappingConfig, resolution_m: float, window: GridSpec | None = None):
    """``grid`` (an :class:`OccupancyGrid` on ``window`` or a :class:`TiledOccupancyGrid`) started from the saved
    map ``prior`` (:func:`prior_grid`): the tiles written with it, or the window's grid replaced by it."""
    seed = prior_grid(prior, config=config, resolution_m=resolution_m, grid=window)
    if not isinstance(grid, TiledOccupancyGrid):
        return seed
    try:
        grid.seed(seed)
    except ValueError as exc:
        raise ValueError(f"prior {prior}: {exc} (give the map a window: --size/--origin)") from None
    return grid
