"""Fusion: each frame's observation added to the occupancy grid, in order (paper section 5.2).

A :class:`FrameObservation` is what one frame contributes to the map: its obstacle and floor
points in the world frame, where it saw them from, and (when they do not depend on the map so
far) the grid cells they hit and clear. :func:`fuse` is the ordered reduction over a sequence's
observations. Conventions: docs/conventions.md.
"""
from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..profiling import stage
from .grid import GridSpec
from .occupancy import MappingConfig, OccupancyGrid, ViewCells

__all__ = ["FrameObservation", "fuse", "add_observation"]


@dataclass(frozen=True)
class FrameObservation:
    """What one frame contributes to the map (world frame)."""

    index: int
    pose: tuple[float, float, float]
    pan_rad: float
    obstacle_points_world: np.ndarray
    floor_points_world: np.ndarray
    n_valid_disparity: int
    ground_message: str
    cells: ViewCells | None = None
    """Cells hit and cleared in the grid of the run's config (None: :func:`fuse` computes them)."""
    baseline_focal_m_px: float | None = None
    """``b f`` of the rig, for the mapping's range uncertainty (None: rays clear up to each point)."""
    sensor_height_m: float | None = None
    """Height of the camera above the floor, for the mapping's height-aware occlusion test."""
    boundary_points: int = 0
    """The last ``boundary_points`` rows of ``obstacle_points_world`` are free-space boundary points
    (:mod:`mrstereo.geometry.freespace`: a floor's end seen in the image, not a stereo measurement)."""

    @property
    def sensor_origin_world(self) -> tuple[float, ...]:
        if self.sensor_height_m is None:
            return (self.pose[0], self.pose[1])
        return (self.pose[0], self.pose[1], self.sensor_height_m)


def fuse(observations: Iterable[FrameObservation], *, grid: GridSpec = GridSpec(),
         config: MappingConfig = MappingConfig()) -> OccupancyGrid:
    """Ordered reduction: add each frame's cells to one occupancy grid (paper section 5.2).

    A frame's precomputed ``cells`` are used when they fit ``grid`` and ``config``; otherwise
    they are computed from its points (the result is the same). With ``config.map_occlusion_p``
    the cells depend on the map so far and are always computed here, in order.
    """
    if isinstance(observations, (str, bytes)):
        raise TypeError("observations must be FrameObservations, got a string")
    occupancy = OccupancyGrid(grid, config=config)
    for obs in observations:
        add_observation(occupancy, obs)
    return occupancy


def add_observation(occupancy: OccupancyGrid, obs: FrameObservation) -> None:
    """One frame into the map, in order: its precomputed cells when they fit the map's grid and
    config and the map does not occlude (``map_occlusion_p`` None), else its cells traced
    against the map so far."""
    _checks.instance("occupancy", occupancy, OccupancyGrid)
    _checks.instance("obs", obs, FrameObservation)
    grid, config = occupancy.grid, occupancy.config
    with stage("grid"):
        if obs.cells is not None and obs.cells.fits(grid, config) and config.map_occlusion_p is None:
            occupancy.apply(obs.cells)
        else:
            occupancy.update(obs.obstacle_points_world, obs.floor_points_world, obs.sensor_origin_world,
                             baseline_focal_m_px=obs.baseline_focal_m_px)
