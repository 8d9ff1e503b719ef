"""Scan-to-map alignment: correct each frame's odometry pose against the map built so far.

A correlative scan matcher (Olson 2009; the approach of Hector mapping and Cartographer's
real-time correlative matcher): the map so far becomes a likelihood field
``L = exp(-dist^2 / (2 sigma^2))`` of the distance to its nearest occupied cell; the frame's
obstacle points (robot frame, x-y) are scored as the mean of ``L`` at their positions under
every pose of a window of rotations and translations around the prior, first coarse, then at a
fifth of the step around the best. The prior is the frame's odometry pose carried by the
correction of the previous frame (odometry drift accumulates, so does the correction); the
best pose replaces it when it scores better.

:func:`fuse_aligned` is the ordered reduction of the mapping pipeline with alignment: the
frames' points are computed in parallel with their given poses, then, in order, each frame is
aligned to the grid of the frames before it and fused at its corrected pose.
Conventions: docs/conventions.md; user guide: docs/odometry.md.

References
----------
E. Olson. Real-time correlative scan matching. ICRA 2009. S. Kohlbrecher et al. A flexible
and scalable SLAM system with full 3D motion estimation (Hector). SSRR 2011. W. Hess et al.
Real-time loop closure in 2D LIDAR SLAM (Cartographer). ICRA 2016.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .. import _checks
from ..mapping import GridSpec
from ..mapping.grid import distance_cells
from ..mapping.occupancy import MappingConfig, OccupancyGrid, view_cells

__all__ = ["AlignConfig", "Alignment", "likelihood_field", "align_points", "fuse_aligned", "compose_planar",
           "relative_planar"]


@dataclass(frozen=True)
class AlignConfig:
    """Correlative search settings.

    Attributes
    ----------
    search_m, search_rad : float
        Half-width of the translation and rotation window around the prior.
    step_m, step_rad : float
        Coarse search step (the fine search uses a fifth of it).
    sigma_m : float
        Width of the likelihood field.
    prior_sigma_m, prior_sigma_rad : float
        Odometry prior: a pose ``dt`` and ``dtheta`` from the prior has its score multiplied by
        ``exp(-dt^2 / (2 prior_sigma_m^2) - dtheta^2 / (2 prior_sigma_rad^2))`` (Olson's
        posterior). The defaults make it almost flat over the search window: on the corridor
        sequences a tighter prior (5 cm, 1 degree) kept most of the heading drift.
    max_range_m : float
        Obstacle points farther from the robot are not scored (stereo depth error grows with
        the square of the range).
    min_cell_points : int
        Points are scored per ``step_m / 2`` cell holding at least this many of them (isolated
        mismatches are dropped).
    max_points : int
        Cells scored (an even subsample).
    min_points : int
        Fewer obstacle points, or fewer occupied cells in the map: the prior is kept.
    gain : float
        Fraction of the found correction applied to the frame (in (0, 1]); the rest of the drift
        is left to the next frames, so matching noise averages out over several frames.
    min_gain : float
        The best pose must beat the prior's score by this much to be used (0: any better pose;
        the per-frame drift is small, so a threshold lets it accumulate).
    """

    search_m: float = 0.1
    search_rad: float = math.radians(2.0)
    step_m: float = 0.02
    step_rad: float = math.radians(0.4)
    sigma_m: float = 0.05
    prior_sigma_m: float = 1.0
    prior_sigma_rad: float = 1.0
    max_range_m: float = 4.0
    min_cell_points: int = 3
    max_points: int = 400
    min_points: int = 30
    min_gain: float = 0.0
    gain: float = 1.0

    def __post_init__(self) -> None:
        for name in ("search_m", "search_rad", "step_m", "step_rad", "sigma_m", "prior_sigma_m", "prior_sigma_rad",
                     "max_range_m"):
            _checks.finite_number(name, getattr(self, name), positive=True)
        _checks.positive_int("max_points", self.max_points)
        _checks.positive_int("min_cell_points", self.min_cell_points)
        _checks.positive_int("min_points", self.min_points)
        _checks.finite_number("min_gain", self.min_gain, nonnegative=True)
        if not 0.0 < self.gain <= 1.0:
            raise ValueError(f"gain must be in (0, 1], got {self.gain}")


@dataclass(frozen=True)
class Alignment:
    """One frame's alignment: the pose used, the prior, their scores."""

    pose: tuple[float, float, float]
    prior: tuple[float, float, float]
    score: float
    prior_score: float
    applied: bool

    @property
    def correction_m(self) -> float:
        return math.hypot(self.pose[0] - self.prior[0], self.pose[1] - self.prior[1])

    @property
    def correction_rad(self) -> float:
        return abs(math.remainder(self.pose[2] - self.prior[2], math.tau))


def compose_planar(a, b) -> tuple[float, float, float]:
    """``a * b`` of planar poses ``(x, y, yaw)``."""
    c, s = math.cos(a[2]), math.sin(a[2])
    return (a[0] + c * b[0] - s * b[1], a[1] + s * b[0] + c * b[1], math.remainder(a[2] + b[2], math.tau))


def relative_planar(a, b) -> tuple[float, float, float]:
    """``inv(a) * b`` of planar poses."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[0] - a[0], b[1] - a[1]
    return (c * dx + s * dy, -s * dx + c * dy, math.remainder(b[2] - a[2], math.tau))


def likelihood_field(occupied: np.ndarray, grid: GridSpec, *, sigma_m: float) -> np.ndarray:
    """``exp(-d^2 / (2 sigma^2))`` of the distance ``d`` to the nearest occupied cell (float32)."""
    if not occupied.any():
        return np.zeros(occupied.shape, np.float32)
    d_m = distance_cells(occupied) * grid.resolution_m
    return np.exp(-0.5 * (d_m / sigma_m) ** 2).astype(np.float32)


def _score(field: np.ndarray, grid: GridSpec, xy_world: np.ndarray) -> np.ndarray:
    """Mean bilinear likelihood of point sets (..., N, 2); points outside the grid score 0."""
    u = (xy_world[..., 0] - grid.origin_x_m) / grid.resolution_m - 0.5     # cell-centre coordinates
    v = (xy_world[..., 1] - grid.origin_y_m) / grid.resolution_m - 0.5
    rows, cols = field.shape
    c0, r0 = np.floor(u).astype(np.int64), np.floor(v).astype(np.int64)
    a, b = u - c0, v - r0
    ok = (c0 >= 0) & (c0 < cols - 1) & (r0 >= 0) & (r0 < rows - 1)
    c0, r0 = np.where(ok, c0, 0), np.where(ok, r0, 0)
    val = ((field[r0, c0] * (1 - a) + field[r0, c0 + 1] * a) * (1 - b)
           + (field[r0 + 1, c0] * (1 - a) + field[r0 + 1, c0 + 1] * a) * b)
    return np.where(ok, val, 0.0).mean(axis=-1)


def _subsample(points_xy: np.ndarray, cell_m: float, min_count: int, max_points: int) -> np.ndarray:
    """Mean point of every ``cell_m`` cell holding ``min_count`` points or more; at most ``max_points``."""
    key = np.floor(points_xy / cell_m).astype(np.int64)
    _, inverse, counts = np.unique(key[:, 0] * 1_000_003 + key[:, 1], return_inverse=True, return_counts=True)
    inverse = inverse.ravel()
    sums = np.zeros((len(counts), 2))
    np.add.at(sums, inverse, points_xy)
    pts = (sums / counts[:, None])[counts >= min_count]
    if len(pts) > max_points:
        pts = pts[np.linspace(0, len(pts) - 1, max_points).astype(np.int64)]
    return pts


def align_points(points_robot_xy, prior_pose, field: np.ndarray, grid: GridSpec, *,
                 config: AlignConfig = AlignConfig()) -> Alignment:
    """Best planar pose of robot-frame points ``(N, 2)`` in a likelihood field, near ``prior_pose``.

    Returns the prior (``applied=False``) when there are too few points, the field is empty, or
    no pose beats the prior by ``config.min_gain``.
    """
    pts = np.asarray(points_robot_xy, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 2:
        raise ValueError(f"points_robot_xy must have shape (N, 2) or (N, 3), got {pts.shape}")
    pts = pts[np.isfinite(pts[:, :2]).all(axis=1), :2]
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= config.max_range_m]
    prior = tuple(float(v) for v in prior_pose)
    if len(pts):
        pts = _subsample(pts, config.step_m / 2, config.min_cell_points, config.max_points)
    if len(pts) < config.min_points or not field.any():
        return Alignment(pose=prior, prior=prior, score=math.nan, prior_score=math.nan, applied=False)

    def scores(yaws, offsets):
        """Posterior scores (len(yaws), len(offsets)) of the points rotated by each yaw and shifted."""
        c, s = np.cos(yaws), np.sin(yaws)
        rotated = np.stack([c[:, None] * pts[:, 0] - s[:, None] * pts[:, 1],
                            s[:, None] * pts[:, 0] + c[:, None] * pts[:, 1]], axis=-1)      # (Y, N, 2)
        match = _score(field, grid, rotated[:, None, :, :] + offsets[None, :, None, :])
        dt2 = np.sum((offsets - prior[:2]) ** 2, axis=1) / config.prior_sigma_m ** 2
        dr2 = (yaws - prior[2]) ** 2 / config.prior_sigma_rad ** 2
        return match * np.exp(-0.5 * (dr2[:, None] + dt2[None, :]))

    def window(centre, half_m, step_m, half_rad, step_rad):
        t = np.arange(-half_m, half_m + 1e-9, step_m)
        dx, dy = np.meshgrid(t, t, indexing="ij")
        offsets = np.column_stack([centre[0] + dx.ravel(), centre[1] + dy.ravel()])
        yaws = centre[2] + np.arange(-half_rad, half_rad + 1e-12, step_rad)
        sc = scores(yaws, offsets)
        i, j = np.unravel_index(int(np.argmax(sc)), sc.shape)
        return (float(offsets[j, 0]), float(offsets[j, 1]), float(yaws[i])), float(sc[i, j])

    c = config
    prior_score = float(scores(np.array([prior[2]]), np.array([prior[:2]]))[0, 0])
    best, _ = window(prior, c.search_m, c.step_m, c.search_rad, c.step_rad)
    best, score = window(best, c.step_m, c.step_m / 5, c.step_rad, c.step_rad / 5)
    if score < prior_score + c.min_gain:
        return Alignment(pose=prior, prior=prior, score=prior_score, prior_score=prior_score, applied=False)
    pose = (best[0], best[1], math.remainder(best[2], math.tau))
    return Alignment(pose=pose, prior=prior, score=score, prior_score=prior_score, applied=True)


def _robot_points(points_world: np.ndarray, pose) -> np.ndarray:
    """World points back into the robot frame of planar ``pose`` (x, y; z kept)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    p = np.asarray(points_world, dtype=np.float64)
    dx, dy = p[:, 0] - pose[0], p[:, 1] - pose[1]
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, p[:, 2]])


def _world_points(points_robot: np.ndarray, pose) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return np.column_stack([pose[0] + c * points_robot[:, 0] - s * points_robot[:, 1],
                            pose[1] + s * points_robot[:, 0] + c * points_robot[:, 1],
                            points_robot[:, 2]]).astype(np.float32)


def fuse_aligned(observations, *, grid: GridSpec = GridSpec(), config: MappingConfig = MappingConfig(),
                 align: AlignConfig = AlignConfig()) -> tuple[OccupancyGrid, list, list[Alignment]]:
    """Ordered reduction with scan-to-map alignment (the ``map --align`` fusion).

    Parameters
    ----------
    observations : iterable of FrameObservation
        Frames in order, points in the world frame of their given (odometry) pose.

    Returns
    -------
    (OccupancyGrid, list of FrameObservation at the corrected poses, list of Alignment)
    """
    occupancy = OccupancyGrid(grid, config=config)
    corrected, alignments = [], []
    correction = (0.0, 0.0, 0.0)           # world correction carried from frame to frame
    for obs in observations:
        given = tuple(float(v) for v in obs.pose)
        prior = compose_planar(correction, given)
        obstacles = _robot_points(obs.obstacle_points_world, given)
        floor = _robot_points(obs.floor_points_world, given)
        field = likelihood_field(occupancy.occupied, grid, sigma_m=align.sigma_m)
        result = align_points(obstacles, prior, field, grid, config=align)
        if result.applied and align.gain < 1.0:        # move part of the way: per-frame noise averages out
            step = relative_planar(prior, result.pose)
            result = replace(result, pose=compose_planar(prior, tuple(align.gain * v for v in step)))
        pose = result.pose
        correction = compose_planar(pose, relative_planar(given, (0.0, 0.0, 0.0)))
        obstacles_w, floor_w = _world_points(obstacles, pose), _world_points(floor, pose)
        cells = view_cells(obstacles_w, floor_w, pose[:2], grid=grid, config=config)
        occupancy.apply(cells)
        corrected.append(replace(obs, pose=pose, obstacle_points_world=obstacles_w, floor_points_world=floor_w,
                                 cells=cells))
        alignments.append(result)
    return occupancy, corrected, alignments
