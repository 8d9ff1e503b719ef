"""Fusion: each frame's observation added to the occupancy grid, in order (paper section 5.2).

A :class:`FrameObservation` is what one frame contributes to the map: its obstacle and floor
points in the world frame, where it saw them from, and (when they do not depend on the map so
far) the grid cells they hit and clear. :func:`fuse` is the ordered reduction over a sequence's
observations. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np

from .. import _checks
from ..camera import StereoCamera
from ..geometry.drops import transform_candidates
from ..profiling import stage
from ..transforms import T_from_planar, transform_points
from .grid import GridSpec
from .occupancy import MappingConfig, OccupancyGrid, ViewCells
from .tiles import TiledOccupancyGrid

__all__ = ["FrameObservation", "world_observation", "fuse", "fuse_step", "add_observation", "sweep_footprint",
           "MAX_SWEEP_M", "SAME_VIEW_TURN_RAD"]

MAX_SWEEP_M = 2.0
"""Consecutive frames at most this far apart are joined by a straight sweep of the robot's footprint."""

SAME_VIEW_TURN_RAD = math.radians(1.0)
"""A frame whose robot lies within a cell of the last frame whose weak drop points the map counted, its camera
turned less than this from that frame's, is the same view again (a robot standing still): its weak points do
not vote (:func:`fuse_step`), as the map's weak votes must come from several views."""


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
    drop_points_world: np.ndarray | None = None
    """The drop test's points (:mod:`mrstereo.geometry.drops`) at their measured height, for the map's drop and
    height layers (their floor-level copies are among ``obstacle_points_world``); None: no drop test."""
    drop_candidates_world: np.ndarray | None = None
    """The drop test's candidates (K, 11) the map confirms with the floor it measured before
    (:data:`mrstereo.geometry.drops.CANDIDATE_COLUMNS`); None: none."""
    drop_weak_points_world: np.ndarray | None = None
    """The drop test's weak points (:attr:`mrstereo.geometry.drops.DropResult.weak_points_robot`), for the map's
    weak votes; None: none."""

    @property
    def layers(self) -> tuple:
        """The arguments of :meth:`OccupancyGrid.add_layers`: the measured obstacle points (without the
        boundary's), the floor points, the drop points, candidates and weak points."""
        n = len(self.obstacle_points_world) - self.boundary_points
        return self.obstacle_points_world[:n], self.floor_points_world, self.drop_points_world, \
            self.drop_candidates_world, self.drop_weak_points_world

    @property
    def sensor_origin_world(self) -> tuple[float, ...]:
        if self.sensor_height_m is None:
            return (self.pose[0], self.pose[1])
        return (self.pose[0], self.pose[1], self.sensor_height_m)


def fuse(observations: Iterable[FrameObservation], *, grid: GridSpec | None = GridSpec(),
         config: MappingConfig = MappingConfig(), resolution_m: float = GridSpec.resolution_m,
         view_reach_m: float = 20.0) -> OccupancyGrid | TiledOccupancyGrid:
    """Ordered reduction: add each frame's cells to one occupancy grid (paper section 5.2).

    A frame's precomputed ``cells`` are used when they fit ``grid`` and ``config``; otherwise
    they are computed from its points (the result is the same). With ``config.map_occlusion_p``
    the cells depend on the map so far and are always computed here, in order. Before each frame,
    the robot's footprint along the path from the previous frame is cleared
    (``config.footprint_radius_m``, :func:`sweep_footprint`; frames more than :data:`MAX_SWEEP_M`
    apart clear only their own footprint: the robot need not have driven straight between them).

    ``grid`` None: a map that grows (:class:`~mrstereo.mapping.tiles.TiledOccupancyGrid` of cells of
    ``resolution_m``; each view fused within ``view_reach_m`` of its sensor).
    """
    if isinstance(observations, (str, bytes)):
        raise TypeError("observations must be FrameObservations, got a string")
    if grid is None:
        occupancy = TiledOccupancyGrid(resolution_m, config=config, view_reach_m=view_reach_m)
    else:
        occupancy = OccupancyGrid(grid, config=config)
    previous = weak_view = None
    for obs in observations:
        weak_view = fuse_step(occupancy, obs, previous, weak_view)
        previous = obs.pose
    return occupancy


def fuse_step(occupancy: OccupancyGrid | TiledOccupancyGrid, obs: FrameObservation, previous_pose=None,
              weak_view=None) -> tuple[float, float, float] | None:
    """One step of :func:`fuse`: the robot's footprint swept from ``previous_pose`` (the frame before's, None
    for the first) to the frame's pose, then the frame added (:func:`add_observation`), without its weak drop
    points when it is the same view (:data:`SAME_VIEW_TURN_RAD`) as ``weak_view``. Returns the view ``(x, y,
    heading + pan)`` of the last frame whose weak points were added (``weak_view`` when not this one's): the
    next step's ``weak_view``."""
    radius = occupancy.config.footprint_radius_m
    if radius:
        near = previous_pose is not None and math.dist(previous_pose[:2], obs.pose[:2]) <= MAX_SWEEP_M
        sweep_footprint(occupancy, previous_pose if near else obs.pose, obs.pose, radius)
    if obs.drop_weak_points_world is not None:
        view = (float(obs.pose[0]), float(obs.pose[1]), float(obs.pose[2]) + float(obs.pan_rad))
        if weak_view is not None and math.dist(view[:2], weak_view[:2]) < _resolution(occupancy) and \
                abs(math.remainder(view[2] - weak_view[2], math.tau)) < SAME_VIEW_TURN_RAD:
            obs = replace(obs, drop_weak_points_world=None)
        else:
            weak_view = view
    add_observation(occupancy, obs)
    return weak_view


def _resolution(occupancy) -> float:
    return occupancy.grid.resolution_m if isinstance(occupancy, OccupancyGrid) else occupancy.resolution_m


def sweep_footprint(occupancy, start_xy, end_xy, radius_m: float) -> None:
    """Clear the cells a disc of ``radius_m`` touches on its way from ``start_xy`` to ``end_xy`` (discs at
    most a cell apart along the segment, :meth:`OccupancyGrid.clear_disc`)."""
    a, b = np.asarray(start_xy[:2], dtype=np.float64), np.asarray(end_xy[:2], dtype=np.float64)
    steps = max(1, int(np.ceil(np.linalg.norm(b - a) / _resolution(occupancy))))
    for t in (np.linspace(0.0, 1.0, steps + 1) if np.any(a != b) else (1.0,)):
        occupancy.clear_disc(a + t * (b - a), radius_m)


def add_observation(occupancy: OccupancyGrid | TiledOccupancyGrid, obs: FrameObservation) -> None:
    """One frame into the map, in order: its precomputed cells when they fit the map's grid and
    config and the map does not occlude (``map_occlusion_p`` None), else its cells traced
    against the map so far; then its height and drop layers (:meth:`OccupancyGrid.add_layers`)."""
    _checks.instance("occupancy", occupancy, (OccupancyGrid, TiledOccupancyGrid))
    _checks.instance("obs", obs, FrameObservation)
    config = occupancy.config
    with stage("grid"):
        if (isinstance(occupancy, OccupancyGrid) and obs.cells is not None and obs.cells.fits(occupancy.grid, config)
                and config.map_occlusion_p is None):
            occupancy.apply(obs.cells)
            occupancy.add_layers(*obs.layers)
        else:
            occupancy.update(obs.obstacle_points_world, obs.floor_points_world, obs.sensor_origin_world,
                             baseline_focal_m_px=obs.baseline_focal_m_px, layers=obs.layers)


def world_observation(observed, pose: tuple[float, float, float], stereo: StereoCamera) -> FrameObservation:
    """An observed frame's points (:class:`~mrstereo.geometry.pair.Observed`) in the world frame at the planar
    ``pose`` (the map is of the floor): what it adds to the map."""
    with stage("grid"):
        T = T_from_planar(*pose)
        obstacles = transform_points(T, observed.obstacle_points_robot).astype(np.float32)
        floor = transform_points(T, observed.floor_points_robot).astype(np.float32)
        drops, weak = (None if p is None else transform_points(T, p).astype(np.float32)
                       for p in (observed.drop_points_robot, observed.drop_weak_points_robot))
        candidates = None if observed.drop_candidates_robot is None else \
            transform_candidates(T, observed.drop_candidates_robot)
        ground = observed.ground
        height = float(ground.height_m) if ground.success else None
    return FrameObservation(index=observed.index, pose=pose, pan_rad=observed.pan_rad,
                            obstacle_points_world=obstacles, floor_points_world=floor,
                            n_valid_disparity=observed.n_valid_disparity, ground_message=ground.message,
                            baseline_focal_m_px=float(stereo.baseline_m * stereo.focal_px),
                            sensor_height_m=height, boundary_points=observed.n_boundary, drop_points_world=drops,
                            drop_candidates_world=candidates, drop_weak_points_world=weak)
