"""Compile before the first frame: every numba kernel of the per-frame chain, loaded or compiled once.

:func:`warm_up` runs the chain (match -> reject -> 3-D -> free space -> scan -> grid) on the matcher's
tiny synthetic pair (:func:`mrstereo.matching.warmup.warm_pair`), so that the kernels are in memory
(loaded from numba's cache, or compiled into it the first time) before a source is opened: a robot's
first frame then runs at full speed. ``mrstereo warm-up`` is its command. docs/speed.md ("First run").
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable

import numpy as np

__all__ = ["warm_up", "COLD_MESSAGE", "chain_kernel_modules"]

COLD_MESSAGE = "compiling the kernels once, about 3 minutes"
"""Said once, before the compile, when numba's cache does not hold the chain's kernels (2 cores)."""


def chain_kernel_modules() -> tuple:
    """The kernel modules of the per-frame chain (matching, rejection, geometry, mapping)."""
    from .geometry import _freespace_kernels
    from .geometry import _kernels as geometry_kernels
    from .mapping import _kernels as mapping_kernels
    from .matching.warmup import KERNEL_MODULES
    from .rejection import _kernels as rejection_kernels

    return (*KERNEL_MODULES, rejection_kernels, geometry_kernels, _freespace_kernels, mapping_kernels)


def warm_up(*, say: Callable[[str], None] | None = None) -> float:
    """Load, or the first time compile, every kernel of the per-frame chain; returns the seconds it took.

    Parameters
    ----------
    say : callable, optional
        Called once with :data:`COLD_MESSAGE` before compiling when the cache is cold (a fresh
        install, an upgrade); not called when the kernels only load.
    """
    from .camera import Camera, CameraMount, StereoCamera
    from .geometry import detect_obstacles, ground_for_frame
    from .geometry.freespace import free_space_boundary
    from .geometry.scan import laser_scan_from_points
    from .mapping import OccupancyGrid
    from .mapping.occupancy import view_cells
    from .matching.warmup import WARM_MAX_DISPARITY_PX, cache_is_cold, warm_pair
    from .matching.warmup import warm_up as warm_matching
    from .rejection import reject_uniform

    t0 = time.perf_counter()
    if say is not None and cache_is_cold(chain_kernel_modules()):
        say(COLD_MESSAGE)
    mapping = warm_matching()[-1]                       # robust and mapping presets
    left, _ = warm_pair()
    h, w = left.shape
    baseline_m = 0.075
    focal_px = WARM_MAX_DISPARITY_PX * 0.5 / baseline_m        # the near limit at 0.5 m
    mount = CameraMount.from_xyz_rpy((0.0, 0.0, 0.4), (0.0, math.radians(10.0), 0.0))
    stereo = StereoCamera.ideal(Camera(fx=focal_px, fy=focal_px, cx=w / 2, cy=h / 2, width=w, height=h), baseline_m,
                                mount=mount)
    disparity = reject_uniform(mapping.disparity_px, left).disparity_px
    ground = ground_for_frame(mapping.disparity_px, stereo, mount=mount)
    obstacles = detect_obstacles(disparity, stereo, ground=ground, too_near=mapping.too_near,
                                 near_limit_px=mapping.near_limit_px)
    free_space_boundary(left, obstacles, disparity, stereo)
    laser_scan_from_points(obstacles.obstacle_points_robot, min_points=3,
                           observed_points_robot=obstacles.points_robot)
    grid = OccupancyGrid()
    floor = obstacles.floor_points_robot.astype(np.float32)
    hits = obstacles.obstacle_points_robot.astype(np.float32)
    grid.update(hits, floor, (0.0, 0.0, 0.4), baseline_focal_m_px=baseline_m * focal_px)
    grid.apply(view_cells(hits, floor, (0.0, 0.0, 0.4), grid=grid.grid, config=grid.config,
                          baseline_focal_m_px=baseline_m * focal_px))
    return time.perf_counter() - t0
