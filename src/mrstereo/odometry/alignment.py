"""Scan-to-map alignment: correct each frame's odometry pose against the map built so far.

A correlative scan matcher in the form of a Bayes filter (Olson 2009, the approach of Hector
mapping and Cartographer's real-time correlative matcher), per frame:

1. *Prior*: the previous corrected pose moved by the odometry step, with a covariance grown by
   the odometry's expected drift over that step (``drift_scale`` of the distance along and
   ``drift_lateral`` across the motion, ``drift_rad_per_m`` of heading per metre);
   ``P' = J P J^T + Q`` with ``J`` the Jacobian of the pose composition.
2. *Likelihood*: the map so far becomes a log-likelihood field
   ``log(p_out + (1 - p_out) exp(-d^2 / (2 sigma^2)))`` of the distance ``d`` to its nearest
   occupied cell (``cv2.distanceTransform``); the frame's obstacle points (robot frame, x-y,
   averaged per small cell) score the mean of the field at their positions, and
   ``effective_points`` times that mean is the scan's log-likelihood (stereo points are not
   independent: this is the number of independent measurements a scan is worth).
3. *Posterior*: log-likelihood plus the Gaussian log-prior, evaluated on a window of
   ``samples^3`` poses spanning ``window_sigmas`` prior standard deviations on each axis, then
   again on a window of three posterior standard deviations around the first estimate (coarse
   to fine). The pose used is the posterior *mean* and its covariance the posterior's
   (Olson's covariance estimate from the sampled distribution), not the best-scoring pose: a
   flat direction of the score (a corridor along its axis, a wall seen alone) leaves the prior
   there, and a noisy scan moves the pose only as far as its information outweighs the
   odometry's.

:func:`fuse_aligned` is the ordered reduction of the mapping pipeline with alignment: the
frames' points are computed in parallel with their given poses, then, in order, each frame is
aligned to the grid of the frames before it and fused at its corrected pose.
Conventions: docs/conventions.md; user guide: docs/odometry.md.

References
----------
E. Olson. Real-time correlative scan matching. ICRA 2009. S. Kohlbrecher et al. A flexible
and scalable SLAM system with full 3D motion estimation (Hector). SSRR 2011. W. Hess et al.
Real-time loop closure in 2D LIDAR SLAM (Cartographer). ICRA 2016. S. Thrun, W. Burgard,
D. Fox. Probabilistic Robotics, ch. 6.4 (likelihood fields) and 5.4 (odometry motion model).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from .. import _checks
from ..mapping import GridSpec
from ..mapping.grid import distance_cells
from ..mapping.occupancy import MappingConfig, OccupancyGrid
from ..transforms import compose_planar, relative_planar, wrap_angle
from ._kernels import score_poses

__all__ = ["AlignConfig", "Alignment", "likelihood_field", "align_points", "fuse_aligned",
           "observation_at"]


@dataclass(frozen=True)
class AlignConfig:
    """Scan-to-map alignment settings.

    Attributes
    ----------
    sigma_m : float
        Width of the likelihood field (about the stereo points' spread on a wall at a few metres).
    outlier_probability : float
        ``p_out``: the likelihood floor of a point far from every occupied cell (a new obstacle,
        a mismatch), so that such points do not dominate the score.
    effective_points : float
        Independent measurements a scan is worth: its log-likelihood is this times the mean of
        the field over its points. Larger trusts the scans more against the odometry.
    drift_scale, drift_lateral : float
        Expected odometry error (standard deviation) per metre travelled, along and across the
        direction of travel.
    drift_rad_per_m : float
        Expected heading drift (standard deviation) per metre travelled.
    initial_sigma_m, initial_sigma_rad : float
        Uncertainty of the first frame's pose (the map's origin: 0 keeps it where it is given).
    window_sigmas : float
        Half-width of the first search window, in prior standard deviations per axis.
    min_window_m, max_window_m, min_window_rad, max_window_rad : float
        Bounds of that half-width.
    samples : int
        Poses per axis of each window (odd; ``samples^3`` poses are scored per level).
    max_range_m : float
        Obstacle points farther from the robot are not scored (stereo depth error grows with
        the square of the range).
    cell_m, min_cell_points : float, int
        Points are averaged per ``cell_m`` cell holding at least ``min_cell_points`` of them
        (isolated mismatches are dropped).
    max_points : int
        Cells scored (an even subsample).
    min_points : int
        Fewer obstacle cells, or an empty map: the prior is kept.
    calibrate_odometry : bool
        Estimate the odometry's systematic errors (scale error, heading drift per metre) from the
        corrections over the last ``calibration_window_m`` of travel and take them out of each
        step before it becomes the prior (wheel radius and track-width errors are constant; the
        per-frame matches are noisier than a step's drift, so only their trend over metres can
        tell it).
    calibration_window_m : float
        Path length over which the odometry's errors are estimated.
    """

    sigma_m: float = 0.05
    outlier_probability: float = 0.1
    effective_points: float = 30.0
    drift_scale: float = 0.05
    drift_lateral: float = 0.02
    drift_rad_per_m: float = math.radians(5.0)
    initial_sigma_m: float = 0.0
    initial_sigma_rad: float = 0.0
    window_sigmas: float = 3.0
    min_window_m: float = 0.01
    max_window_m: float = 0.3
    min_window_rad: float = math.radians(0.2)
    max_window_rad: float = math.radians(5.0)
    samples: int = 9
    max_range_m: float = 4.0
    cell_m: float = 0.025
    min_cell_points: int = 3
    max_points: int = 300
    min_points: int = 30
    calibrate_odometry: bool = True
    calibration_window_m: float = 4.0

    def __post_init__(self) -> None:
        for name in ("sigma_m", "effective_points", "window_sigmas", "min_window_m", "max_window_m",
                     "min_window_rad", "max_window_rad", "max_range_m", "cell_m", "calibration_window_m"):
            _checks.finite_number(name, getattr(self, name), positive=True)
        for name in ("drift_scale", "drift_lateral", "drift_rad_per_m", "initial_sigma_m", "initial_sigma_rad"):
            _checks.finite_number(name, getattr(self, name), nonnegative=True)
        if not 0.0 < self.outlier_probability < 1.0:
            raise ValueError(f"outlier_probability must be in (0, 1), got {self.outlier_probability}")
        if self.min_window_m > self.max_window_m or self.min_window_rad > self.max_window_rad:
            raise ValueError("min_window_m/rad must not exceed max_window_m/rad")
        _checks.positive_int("samples", self.samples, minimum=3)
        if self.samples % 2 == 0:
            raise ValueError(f"samples must be odd (the window is centred on a sample), got {self.samples}")
        _checks.positive_int("max_points", self.max_points)
        _checks.positive_int("min_cell_points", self.min_cell_points)
        _checks.positive_int("min_points", self.min_points)

    def step_covariance(self, step) -> np.ndarray:
        """Odometry noise ``Q`` (3x3, robot frame of the step's start) of a planar step ``(dx, dy, dyaw)``."""
        dist = math.hypot(step[0], step[1])
        return np.diag([(self.drift_scale * dist) ** 2, (self.drift_lateral * dist) ** 2,
                        (self.drift_rad_per_m * dist) ** 2])


@dataclass(frozen=True)
class Alignment:
    """One frame's alignment.

    Attributes
    ----------
    pose, prior : (x_m, y_m, yaw_rad)
        The pose used (posterior mean) and the odometry prior.
    score, prior_score : float
        Mean log-likelihood of the scan's points at the pose and at the prior (NaN: not aligned).
    applied : bool
        False when there was nothing to align (too few points, an empty map): the prior is used.
    covariance, prior_covariance : ndarray (3, 3)
        Of ``(x, y, yaw)`` after and before the alignment (world frame).
    """

    pose: tuple[float, float, float]
    prior: tuple[float, float, float]
    score: float
    prior_score: float
    applied: bool
    covariance: np.ndarray | None = None
    prior_covariance: np.ndarray | None = None

    @property
    def correction_m(self) -> float:
        return math.hypot(self.pose[0] - self.prior[0], self.pose[1] - self.prior[1])

    @property
    def correction_rad(self) -> float:
        return abs(wrap_angle(self.pose[2] - self.prior[2]))


def likelihood_field(occupied: np.ndarray, grid: GridSpec, *, sigma_m: float,
                     outlier_probability: float = 0.1) -> np.ndarray:
    """Log-likelihood field (float64) of the map's occupied cells (Thrun et al., sec. 6.4).

    ``log(p_out + (1 - p_out) exp(-d^2 / (2 sigma^2)))`` of the distance ``d`` of each cell
    centre to the nearest occupied cell (``cv2.distanceTransform``); all ``log(p_out)`` when
    nothing is occupied.
    """
    occupied = np.asarray(occupied, dtype=bool)
    if occupied.shape != grid.shape:
        raise ValueError(f"occupied must have the grid's shape {grid.shape}, got {occupied.shape}")
    _checks.finite_number("sigma_m", sigma_m, positive=True)
    if not 0.0 < outlier_probability < 1.0:
        raise ValueError(f"outlier_probability must be in (0, 1), got {outlier_probability}")
    if not occupied.any():
        return np.full(occupied.shape, math.log(outlier_probability))
    d_m = distance_cells(occupied) * grid.resolution_m
    return np.log(outlier_probability + (1.0 - outlier_probability) * np.exp(-0.5 * (d_m / sigma_m) ** 2))


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
    return np.ascontiguousarray(pts)


def _posterior(field, grid, pts, prior, info, centre, half, samples, effective_points, outside):
    """Mean, covariance and best log-posterior of poses on a window ``centre +- half`` (3 axes)."""
    axes = [np.linspace(centre[a] - half[a], centre[a] + half[a], samples) for a in range(3)]
    dx, dy = np.meshgrid(axes[0], axes[1], indexing="ij")
    offsets = np.ascontiguousarray(np.column_stack([dx.ravel(), dy.ravel()]))
    yaws = np.ascontiguousarray(axes[2])
    mean_ll = np.empty((len(yaws), len(offsets)))
    score_poses(field, grid.origin_x_m, grid.origin_y_m, grid.resolution_m, outside, pts, yaws, offsets, mean_ll)
    poses = np.empty((len(yaws), len(offsets), 3))
    poses[..., :2] = offsets[None, :, :]
    poses[..., 2] = yaws[:, None]
    delta = poses - np.asarray(prior)
    log_post = effective_points * mean_ll - 0.5 * np.einsum("...i,ij,...j->...", delta, info, delta)
    w = np.exp(log_post - log_post.max())
    w /= w.sum()
    mean = np.einsum("ij,ijk->k", w, poses)
    d = poses - mean
    cov = np.einsum("ij,ijk,ijl->kl", w, d, d)
    # the samples' spacing bounds what the window resolves: a uniform cell of that size at least
    spacing = 2.0 * np.asarray(half) / (samples - 1)
    cov += np.diag(spacing ** 2 / 12.0)
    return mean, cov, mean_ll


def align_points(points_robot_xy, prior_pose, field: np.ndarray, grid: GridSpec, *,
                 prior_covariance=None, config: AlignConfig = AlignConfig()) -> Alignment:
    """Posterior pose of robot-frame points ``(N, 2)`` in a log-likelihood field, given a prior.

    Parameters
    ----------
    points_robot_xy : ndarray (N, 2) or (N, 3)
        Obstacle points in the robot frame (z ignored).
    prior_pose : (x_m, y_m, yaw_rad)
    field : ndarray
        :func:`likelihood_field` of the map (the grid's shape).
    prior_covariance : ndarray (3, 3), optional
        Of the prior; by default the drift of one metre of travel (``config.step_covariance``).

    Returns the prior (``applied=False``) when there are too few points or the map is empty.
    """
    c = config
    pts = np.asarray(points_robot_xy, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] < 2:
        raise ValueError(f"points_robot_xy must have shape (N, 2) or (N, 3), got {pts.shape}")
    field = np.asarray(field, dtype=np.float64)
    if field.shape != grid.shape:
        raise ValueError(f"field must have the grid's shape {grid.shape}, got {field.shape}")
    prior = tuple(float(v) for v in prior_pose)
    if len(prior) != 3 or not all(math.isfinite(v) for v in prior):
        raise ValueError(f"prior_pose must be three finite numbers (x_m, y_m, yaw_rad), got {prior_pose!r}")
    P = c.step_covariance((1.0, 0.0, 0.0)) if prior_covariance is None else np.array(prior_covariance, float)
    if P.shape != (3, 3) or not np.isfinite(P).all():
        raise ValueError(f"prior_covariance must be a finite (3, 3) matrix, got shape {P.shape}")
    pts = pts[np.isfinite(pts[:, :2]).all(axis=1), :2]
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) <= c.max_range_m]
    if len(pts):
        pts = _subsample(pts, c.cell_m, c.min_cell_points, c.max_points)
    outside = math.log(c.outlier_probability)
    if len(pts) < c.min_points or not (field > outside).any():
        return Alignment(pose=prior, prior=prior, score=math.nan, prior_score=math.nan, applied=False,
                         covariance=P, prior_covariance=P)
    # the window: window_sigmas prior standard deviations, bounded; the prior's information
    sd = np.sqrt(np.clip(np.diag(P), 0.0, None))
    lo = np.array([c.min_window_m, c.min_window_m, c.min_window_rad])
    hi = np.array([c.max_window_m, c.max_window_m, c.max_window_rad])
    half = np.clip(c.window_sigmas * sd, lo, hi)
    info = np.linalg.inv(P + np.diag((lo / c.window_sigmas) ** 2 * 1e-2))     # regularised: P may be 0
    prior_ll = np.empty((1, 1))
    score_poses(field, grid.origin_x_m, grid.origin_y_m, grid.resolution_m, outside, pts,
                np.array([prior[2]]), np.array([prior[:2]]), prior_ll)
    mean, cov, _ = _posterior(field, grid, pts, prior, info, prior, half, c.samples, c.effective_points, outside)
    # finer: three posterior standard deviations around the first estimate
    half_fine = np.minimum(np.maximum(3.0 * np.sqrt(np.diag(cov)), lo / 2), half)
    mean, cov, _ = _posterior(field, grid, pts, prior, info, mean, half_fine, c.samples, c.effective_points,
                              outside)
    score = np.empty((1, 1))
    score_poses(field, grid.origin_x_m, grid.origin_y_m, grid.resolution_m, outside, pts,
                np.array([mean[2]]), np.array([mean[:2]]), score)
    pose = (float(mean[0]), float(mean[1]), wrap_angle(float(mean[2])))
    return Alignment(pose=pose, prior=prior, score=float(score[0, 0]), prior_score=float(prior_ll[0, 0]),
                     applied=True, covariance=cov, prior_covariance=P)


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


def observation_at(obs, pose):
    """A :class:`~mrstereo.mapping.fusion.FrameObservation` moved to another planar ``pose``.

    Its points keep their place in the robot frame; it carries no cells (the map traces them,
    :func:`mrstereo.mapping.fusion.add_observation`).
    """
    pose = tuple(float(v) for v in pose)
    obstacles = _world_points(_robot_points(obs.obstacle_points_world, obs.pose), pose)
    floor = _world_points(_robot_points(obs.floor_points_world, obs.pose), pose)
    return replace(obs, pose=pose, obstacle_points_world=obstacles, floor_points_world=floor, cells=None)


def _propagate(P: np.ndarray, pose, step, Q_robot: np.ndarray) -> np.ndarray:
    """Covariance of ``compose(pose, step)``: ``J P J^T + R Q R^T`` (Thrun et al., sec. 5.4)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    J = np.array([[1.0, 0.0, -s * step[0] - c * step[1]], [0.0, 1.0, c * step[0] - s * step[1]], [0.0, 0.0, 1.0]])
    R = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    return J @ P @ J.T + R @ Q_robot @ R.T


def _odometry_errors(given: np.ndarray, corrected: np.ndarray, path_m: np.ndarray, align: AlignConfig,
                     variance_m2: float, variance_rad2: float) -> tuple[float, float]:
    """Scale error and heading drift [rad/m] of the odometry over the last ``calibration_window_m``.

    Between the window's first frame ``j`` and the last ``k``, the given odometry turned
    ``dtheta_g``; the corrected poses turned ``dtheta_c`` and moved ``L_c`` (chord). Heading
    drift ``b``: ``dtheta_g - dtheta_c = b s`` over the path length ``s``; scale error
    ``L_g = (1 + e) L_c`` with ``L_g`` the chord of the given steps integrated again without
    the drift. Each is a one-parameter Gaussian estimate with a zero-mean prior of the
    configured drift (``drift_rad_per_m``, ``drift_scale``) and the matches' variance as noise,
    so that a short or poorly constrained window leaves them near zero.
    """
    k = len(given) - 1
    j = int(np.searchsorted(path_m, path_m[k] - align.calibration_window_m))
    s = path_m[k] - path_m[j]
    if k - j < 2 or s <= 0:
        return 0.0, 0.0
    turn_g = wrap_angle(given[k, 2] - given[j, 2])
    turn_c = wrap_angle(corrected[k, 2] - corrected[j, 2])
    prior_b = max(align.drift_rad_per_m, 1e-9) ** 2
    drift = (turn_g - turn_c) * s / (s * s + 2.0 * variance_rad2 / prior_b)
    # the given path of the window again with the drift taken out: its chord against the corrected one's
    x = y = 0.0
    yaw = given[j, 2]
    for i in range(j + 1, k + 1):
        dx, dy, dyaw = relative_planar(given[i - 1], given[i])
        c, sn = math.cos(yaw), math.sin(yaw)
        x, y = x + c * dx - sn * dy, y + sn * dx + c * dy
        yaw += dyaw - drift * (path_m[i] - path_m[i - 1])
    length_g = math.hypot(x, y)
    length_c = float(np.hypot(*(corrected[k, :2] - corrected[j, :2])))
    prior_e = max(align.drift_scale, 1e-9) ** 2
    scale = (length_g - length_c) * length_c / (length_c ** 2 + 2.0 * variance_m2 / prior_e) if length_c > 0 else 0.0
    return scale, drift


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
    from ..mapping.fusion import add_observation
    from ..profiling import stage

    occupancy = OccupancyGrid(grid, config=config)
    corrected, alignments = [], []
    previous_given = previous_pose = None
    P = np.diag([align.initial_sigma_m ** 2, align.initial_sigma_m ** 2, align.initial_sigma_rad ** 2])
    given_poses, corrected_poses, path_m = [], [], [0.0]
    scale_error = drift_rad_per_m = 0.0
    for obs in observations:
        given = tuple(float(v) for v in obs.pose)
        with stage("align"):
            if previous_given is None:
                prior = given
            else:
                step = relative_planar(previous_given, given)
                path_m.append(path_m[-1] + math.hypot(step[0], step[1]))
                if align.calibrate_odometry:          # the odometry's estimated systematic errors out
                    dist = math.hypot(step[0], step[1])
                    step = (step[0] / (1.0 + scale_error), step[1] / (1.0 + scale_error),
                            step[2] - drift_rad_per_m * dist)
                prior = compose_planar(previous_pose, step)
                P = _propagate(P, previous_pose, step, align.step_covariance(step))
            obstacles = _robot_points(obs.obstacle_points_world, given)
            field = likelihood_field(occupancy.occupied, grid, sigma_m=align.sigma_m,
                                     outlier_probability=align.outlier_probability)
            result = align_points(obstacles, prior, field, grid, prior_covariance=P, config=align)
            P = result.covariance
        moved = observation_at(obs, result.pose)
        add_observation(occupancy, moved)
        corrected.append(moved)
        alignments.append(result)
        previous_given, previous_pose = given, result.pose
        given_poses.append(given)
        corrected_poses.append(result.pose)
        if align.calibrate_odometry and result.applied:
            scale_error, drift_rad_per_m = _odometry_errors(
                np.array(given_poses), np.array(corrected_poses), np.array(path_m), align,
                variance_m2=float(P[0, 0] + P[1, 1]) / 2.0, variance_rad2=float(P[2, 2]))
    return occupancy, corrected, alignments
