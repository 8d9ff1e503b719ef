"""Stereo visual odometry: KLT tracks against a keyframe, PnP-RANSAC, a window of keyframes refined.

Per rectified pair: predict the pose by the last measured motion scaled to the time since the last
measured frame; track the reference keyframe's features into the left image by pyramidal
Lucas-Kanade (forward-backward checked; against the keyframe, so that a robot standing still gets
the same pose every frame); ``cv2.solvePnPRansac`` then ``cv2.solvePnPRefineLM`` on the landmarks;
refuse a step beyond the speed, turn-rate and acceleration limits over that time (the latter plus
three times the motion model's RMS deviation); a refused frame is tried against the window's other
keyframes, then from fresh features PnP'd into the reference keyframe, and only then *lost* (its
pose is the prediction; tracking restarts after ``max_lost_streak`` lost frames); learn the
disparity offset of the rig from the motion at each keyframe; make a new keyframe when
too few inliers remain or the camera moved or turned far enough, with new Shi-Tomasi corners
matched into the right image along the row and triangulated by eq. (14)-(16); bundle-adjust the
last ``window_keyframes`` keyframes (:mod:`mrstereo.odometry.window`). Each step and why:
docs/odometry.md.

Poses are of the robot base in the world, ``T_world_from_base = T_world_from_cam @
inv(T_base_from_cam)`` with each frame's camera mount; a frame's pose is kept relative to its
keyframe, so :meth:`StereoOdometry.trajectory` follows the refined keyframes, while
:meth:`StereoOdometry.step` returns the pose as known at that frame. Conventions: docs/conventions.md.

References
----------
D. Nister, O. Naroditsky, J. Bergen. Visual odometry. CVPR 2004 (stereo VO with 3-D
points and RANSAC). B. Kitt, A. Geiger, H. Lategahn. Visual odometry based on stereo image
sequences with RANSAC-based outlier rejection scheme. IV 2010. J.-Y. Bouguet. Pyramidal
implementation of the Lucas Kanade feature tracker. Intel, 2000. J. Shi, C. Tomasi. Good
features to track. CVPR 1994. R. Mur-Artal, J. D. Tardos. ORB-SLAM2. IEEE T-RO 33(5), 2017
(keyframes and local bundle adjustment of a stereo odometry).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import cv2
import numpy as np

from .. import _checks
from ..camera import StereoCamera
from ..geometry.triangulation import depth_m_from_disparity_px
from ..transforms import T_from_rvec_t, rotation_angle_rad, rvec_t_from_T, scale_motion, transform_points
from .window import Keyframe, LocalMap

__all__ = ["OdometryConfig", "FrameEstimate", "StereoOdometry", "TRACKED", "KEYFRAME", "LOST"]

TRACKED, KEYFRAME, LOST = "tracked", "keyframe", "lost"


@dataclass(frozen=True)
class OdometryConfig:
    """Visual odometry settings (what each step does: docs/odometry.md).

    Attributes
    ----------
    max_features, grid_cells : int, (int, int)
        Features per keyframe; new corners are spread over ``grid_cells`` (rows, columns).
    corner_quality, corner_block_px, min_corner_distance_px : float, int, float
        ``cv2.goodFeaturesToTrack``'s ``qualityLevel``, gradient window and minimum distance.
    klt_window_px, klt_levels : int
        Lucas-Kanade window and pyramid levels of the tracking from the keyframe (small: a larger
        window underestimates the motion toward a surface, which magnifies it).
    stereo_window_px, stereo_levels : int
        The same for the left-right search of keyframe features.
    max_fb_error_px, max_row_error_px : float
        Largest forward-backward track error, and ``|y_left - y_right|`` of a stereo match (with a
        given disparity map: the spread of the four disparities around a corner).
    min_disparity_px : float
        Closest to infinity a new landmark may be (its depth is ``b f / d``).
    ransac_threshold_px, ransac_iterations, min_inliers : float, int, int
        PnP-RANSAC; with fewer inliers the frame is lost.
    keyframe_inlier_fraction, keyframe_depth_fraction, keyframe_angle_rad : float
        A new keyframe when the inliers fall below this fraction of its features, or after moving
        this fraction of its median landmark depth, or turning this far.
    max_speed_mps, max_turn_rate_radps, max_acceleration_mps2, max_angular_acceleration_radps2 : float
        A step beyond these over the frame's time step (the accelerations: away from the motion
        model's prediction) is a failure, not a motion.
    frame_interval_s : float
        Time step assumed between frames without stamps.
    max_lost_streak : int
        Lost frames in a row before tracking restarts from a new keyframe.
    window_keyframes, window_fixed : int
        Keyframes in the refined window (1: none) and the oldest of them held fixed (the gauge).
    archive_keyframes : int
        Keyframes kept (with their image and landmarks) after they leave the window, for the
        relocalization of a lost frame near one of them (0: none).
    huber_px, refine_iterations, outlier_px : float, int, float
        The refinement's Huber threshold and steps, and the distance from its landmark's projection
        beyond which an observation is dropped after it.
    calibrate_disparity_offset : bool
        Learn the rig's disparity correction from the motion: an offset (a rectified principal point
        off) and a term growing down the image (a right camera rolled), ``a + b (v - cy) / 100`` px.
    offset_prior_weight, min_disparity_offset_px, max_disparity_offset_px : float
        The weight of the correction's 0 start (in the units of a keyframe pair's cost curvature,
        px^2 per px^2); the smallest correction a term makes at the image's edge for it to be used
        (below it, 0: within the learner's own bias, about +0.07 px on synthetic rigs with none) and
        each term's largest size either way.
    """

    max_features: int = 300
    grid_cells: tuple[int, int] = (2, 3)
    corner_quality: float = 0.001
    corner_block_px: int = 5
    min_corner_distance_px: float = 8.0
    klt_window_px: int = 11
    stereo_window_px: int = 21
    klt_levels: int = 3
    stereo_levels: int = 5
    max_fb_error_px: float = 0.5
    max_row_error_px: float = 1.0
    min_disparity_px: float = 1.0
    ransac_threshold_px: float = 1.0
    ransac_iterations: int = 100
    min_inliers: int = 12
    keyframe_inlier_fraction: float = 0.5
    keyframe_depth_fraction: float = 0.1
    keyframe_angle_rad: float = math.radians(10.0)
    max_speed_mps: float = 40.0
    max_turn_rate_radps: float = 3.0
    max_acceleration_mps2: float = 30.0
    max_angular_acceleration_radps2: float = 30.0
    frame_interval_s: float = 0.1
    max_lost_streak: int = 2
    window_keyframes: int = 7
    window_fixed: int = 1
    archive_keyframes: int = 50
    huber_px: float = 1.0
    refine_iterations: int = 10
    outlier_px: float = 3.0
    calibrate_disparity_offset: bool = True
    offset_prior_weight: float = 20.0
    min_disparity_offset_px: float = 0.15
    max_disparity_offset_px: float = 3.0

    def __post_init__(self) -> None:
        for name in ("max_features", "klt_window_px", "stereo_window_px", "klt_levels", "stereo_levels",
                     "ransac_iterations", "min_inliers", "corner_block_px", "max_lost_streak", "window_keyframes",
                     "window_fixed", "refine_iterations"):
            _checks.positive_int(name, getattr(self, name), minimum=4 if name == "min_inliers" else 1)
        for name in ("min_corner_distance_px", "max_fb_error_px", "max_row_error_px",
                     "min_disparity_px", "ransac_threshold_px", "keyframe_depth_fraction", "keyframe_angle_rad",
                     "max_speed_mps", "max_turn_rate_radps", "max_acceleration_mps2",
                     "max_angular_acceleration_radps2", "frame_interval_s", "huber_px", "outlier_px",
                     "offset_prior_weight", "max_disparity_offset_px"):
            _checks.finite_number(name, getattr(self, name), positive=True)
        if not (isinstance(self.archive_keyframes, int) and not isinstance(self.archive_keyframes, bool)
                and self.archive_keyframes >= 0):
            raise ValueError(f"archive_keyframes must be an integer >= 0, got {self.archive_keyframes!r}")
        if not (isinstance(self.min_disparity_offset_px, (int, float)) and 0.0 <= self.min_disparity_offset_px
                <= self.max_disparity_offset_px):
            raise ValueError(f"min_disparity_offset_px must be in [0, max_disparity_offset_px], got "
                             f"{self.min_disparity_offset_px!r}")
        if not 0.0 < self.corner_quality < 1.0:
            raise ValueError(f"corner_quality must be in (0, 1), got {self.corner_quality}")
        if not 0.0 < self.keyframe_inlier_fraction < 1.0:
            raise ValueError(f"keyframe_inlier_fraction must be in (0, 1), got {self.keyframe_inlier_fraction}")
        if len(self.grid_cells) != 2 or min(self.grid_cells) < 1:
            raise ValueError(f"grid_cells must be (rows, cols) >= 1, got {self.grid_cells!r}")


@dataclass(frozen=True)
class FrameEstimate:
    """One frame's result: the base pose as known at that frame and how it was obtained."""

    T_world_from_base: np.ndarray
    status: str
    n_tracked: int
    n_inliers: int
    time_s: float


@dataclass
class _FrameLink:
    keyframe: Keyframe             # reference keyframe (its pose is refined later)
    T_key_from_cam: np.ndarray
    T_base_from_cam: np.ndarray


@dataclass
class StereoOdometry:
    """The tracker; feed it rectified pairs in order with :meth:`step`.

    Parameters
    ----------
    stereo : StereoCamera
        The rectified rig (``P`` of both cameras).
    T_world_from_base0 : ndarray (4, 4), optional
        Pose of the first frame (identity).
    config : OdometryConfig
    keep_history : bool
        Keep every frame's link to its keyframe for :meth:`trajectory` (the refined poses of the
        whole run). A live run that only needs each frame's pose as :meth:`step` returns it turns
        this off: its memory then stays flat over any number of frames.
    """

    stereo: StereoCamera
    T_world_from_base0: np.ndarray | None = None
    config: OdometryConfig = field(default_factory=OdometryConfig)
    keep_history: bool = True

    def __post_init__(self) -> None:
        _checks.instance("stereo", self.stereo, StereoCamera)
        _checks.instance("config", self.config, OdometryConfig)
        T0 = np.eye(4) if self.T_world_from_base0 is None else self.T_world_from_base0
        self.T_world_from_base0 = _checks.matrix("T_world_from_base0", T0, (4, 4)).copy()
        P = self.stereo.left.P
        self._K = np.array([[P[0, 0], 0.0, P[0, 2]], [0.0, P[1, 1], P[1, 2]], [0.0, 0.0, 1.0]])
        c = self.config
        self._map = LocalMap(self._K, self.stereo.baseline_m, float(self.stereo.right.P[0, 2]),
                             size=c.window_keyframes, fixed=c.window_fixed, huber_px=c.huber_px,
                             iterations=c.refine_iterations, outlier_px=c.outlier_px)
        self._keyframe: Keyframe | None = None
        # the motion model rests on measured frames only (a lost frame's pose is a guess): the last
        # measured camera pose, the time since it, and the motion between the last two measured frames
        self._T_measured: np.ndarray | None = None
        self._since_measured_s = 0.0
        self._velocity = np.eye(4)                             # T_prevcam_from_cam between measured frames
        self._velocity_dt = c.frame_interval_s
        self._velocity_known = False
        # the disparity correction learnt from the motion, e(u, v) = offset + row and column slopes (px, px
        # per 100 px; the offset is added to the rig's doffs, the slopes to the matches), its mean, the
        # sum of the keyframe pairs' information times their estimate and the information (prior included)
        self._offset_px, self._slopes_px = 0.0, np.zeros(2)
        self._correction_mean = np.zeros(2)
        self._correction_sum, self._correction_info = np.zeros(2), c.offset_prior_weight * np.eye(2)
        self._deviation = np.zeros(2)                          # mean squared model deviation (m^2, rad^2)
        self._n_deviation = 0
        self._stamp: float | None = None
        self._lost_streak = 0
        # the last measured pose and the time since it, kept through restarts from a guess (the gate of a
        # relocalization against an archived keyframe), and the keyframes that left the window
        self._T_anchor: np.ndarray | None = None
        self._anchor_elapsed_s = 0.0
        self._archive: list[Keyframe] = []
        self._remeasured = False
        self._links: list[_FrameLink] = []
        self._n_frames = 0
        self._criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.003)

    # -- public -----------------------------------------------------------------------------
    def step(self, left_rect, right_rect, *, T_base_from_cam, disparity_px=None, stamp_s: float | None = None
             ) -> FrameEstimate:
        """Estimate the pose of the next frame.

        Parameters
        ----------
        left_rect, right_rect : ndarray (H, W) or (H, W, 3)
            The rectified pair (uint8 or float).
        T_base_from_cam : ndarray (4, 4)
            The left camera's mount on the base for this frame.
        disparity_px : ndarray (H, W), optional
            This frame's disparity: keyframe features take their depth from it instead of a stereo search.
        stamp_s : float, optional
            The frame's time stamp; without, frames are ``config.frame_interval_s`` apart.
        """
        start = time.thread_time()
        T_base_from_cam = _checks.matrix("T_base_from_cam", T_base_from_cam, (4, 4))
        left = _gray_u8("left_rect", left_rect)
        right = _gray_u8("right_rect", right_rect)
        _checks.same_shape("left_rect", left, "right_rect", right)
        if (left.shape[1], left.shape[0]) != tuple(self.stereo.size):
            raise ValueError(f"images are {left.shape[1]}x{left.shape[0]} but the calibration is "
                             f"{self.stereo.size[0]}x{self.stereo.size[1]}")
        if disparity_px is not None and np.shape(disparity_px) != left.shape:
            raise ValueError(f"disparity_px must have shape {left.shape}, got {np.shape(disparity_px)}")
        dt = self._time_step(stamp_s)
        if self._keyframe is None:
            T_world_from_cam = self.T_world_from_base0 @ T_base_from_cam
            self._new_keyframe(left, right, disparity_px, T_world_from_cam, None)
            self._T_measured, self._since_measured_s = T_world_from_cam, 0.0
            self._T_anchor, self._anchor_elapsed_s = T_world_from_cam, 0.0
            n = int(self._keyframe.valid.sum())
            return self._finish(start, T_world_from_cam, T_base_from_cam, KEYFRAME, n, n, dt)
        # the motion model: the last measured motion again, scaled to the time since the last measured frame
        dt_pred = self._since_measured_s + dt
        T_pred = self._predict(dt_pred)
        status, T_world_from_cam, n_tracked, n_inliers, tracked = self._track(left, T_pred, dt_pred)
        if status == LOST:     # the window's keyframes, earlier ones near the prediction, then fresh features
            status, T_world_from_cam, n_tracked, n_inliers, tracked = self._relocalize(
                left, right, disparity_px, T_pred, dt_pred, (status, T_world_from_cam, n_tracked, n_inliers, tracked))
        if status == LOST:
            self._lost_streak += 1
            self._since_measured_s += dt
            self._anchor_elapsed_s += dt
            if self._lost_streak >= self.config.max_lost_streak:
                self._archive_keyframes(self._map.clear())     # restart at the predicted pose, the motion kept
                self._new_keyframe(left, right, disparity_px, T_pred, None)
                self._T_measured, self._since_measured_s = T_pred, 0.0
                self._lost_streak = 0
            return self._finish(start, T_pred, T_base_from_cam, LOST, n_tracked, n_inliers, dt)
        self._lost_streak = 0
        if not self._remeasured:                 # (a relocalization against an archived keyframe measured it)
            self._measure(T_world_from_cam, dt_pred, T_pred)
        self._remeasured = False
        if status == KEYFRAME:                   # re-found from fresh features: already a keyframe
            return self._finish(start, T_world_from_cam, T_base_from_cam, status, n_tracked, n_inliers, dt)
        kf, c = self._keyframe, self.config
        T_key_from_cam = np.linalg.inv(kf.T_world_from_cam) @ T_world_from_cam
        depth = self._median_depth(kf)
        if (n_inliers < c.keyframe_inlier_fraction * int(kf.valid.sum())
                or np.linalg.norm(T_key_from_cam[:3, 3]) > c.keyframe_depth_fraction * depth
                or rotation_angle_rad(T_key_from_cam[:3, :3]) > c.keyframe_angle_rad):
            if c.calibrate_disparity_offset:
                self._learn_offset(kf, tracked, T_world_from_cam)
            T_world_from_cam = self._new_keyframe(left, right, disparity_px, T_world_from_cam, tracked)
            self._T_measured = T_world_from_cam
            status = KEYFRAME
        return self._finish(start, T_world_from_cam, T_base_from_cam, status, n_tracked, n_inliers, dt)

    def trajectory(self) -> np.ndarray:
        """``T_world_from_base`` (N, 4, 4) of every frame so far, on its keyframe's refined pose."""
        if not self.keep_history and self._n_frames:
            raise ValueError("this tracker keeps no history (keep_history=False): use the poses step() returns")
        return np.stack([link.keyframe.T_world_from_cam @ link.T_key_from_cam @ np.linalg.inv(link.T_base_from_cam)
                         for link in self._links]) if self._links else np.empty((0, 4, 4))

    # -- internals --------------------------------------------------------------------------
    def _time_step(self, stamp_s) -> float:
        if stamp_s is None:
            self._stamp = None
            return self.config.frame_interval_s
        stamp = _checks.finite_number("stamp_s", stamp_s)
        previous, self._stamp = self._stamp, stamp
        if previous is None:
            return self.config.frame_interval_s
        if stamp <= previous:
            raise ValueError(f"stamp_s must increase from frame to frame, got {stamp!r} after {previous!r}")
        return stamp - previous

    def _finish(self, start, T_world_from_cam, T_base_from_cam, status, n_tracked, n_inliers, dt) -> FrameEstimate:
        kf = self._keyframe
        self._n_frames += 1
        if self.keep_history:
            self._links.append(_FrameLink(kf, np.linalg.inv(kf.T_world_from_cam) @ T_world_from_cam,
                                          T_base_from_cam))
        T_world_from_base = T_world_from_cam @ np.linalg.inv(T_base_from_cam)
        return FrameEstimate(T_world_from_base=_readonly(T_world_from_base), status=status,
                             n_tracked=int(n_tracked), n_inliers=int(n_inliers), time_s=time.thread_time() - start)

    def _median_depth(self, kf: Keyframe) -> float:
        ids = kf.landmark[kf.valid]
        if not len(ids):
            return math.inf
        points = transform_points(np.linalg.inv(kf.T_world_from_cam), self._map.points(ids))
        return float(np.median(points[:, 2]))

    def _klt(self, image_a, image_b, pts: np.ndarray, guess: np.ndarray, levels: int,
             window_px: int) -> tuple[np.ndarray, np.ndarray]:
        """Track ``pts`` from a to b (started at ``guess``) and back; (tracked, ok).

        The way back starts at the original points, where a good track must end, so it needs
        no pyramid (one level of refinement).
        """
        flags = cv2.OPTFLOW_USE_INITIAL_FLOW
        p0 = pts.reshape(-1, 1, 2).astype(np.float32)
        win = (window_px, window_px)
        p1, st1, _ = cv2.calcOpticalFlowPyrLK(image_a, image_b, p0, guess.reshape(-1, 1, 2).astype(np.float32).copy(),
                                              winSize=win, maxLevel=levels, criteria=self._criteria, flags=flags)
        back, st2, _ = cv2.calcOpticalFlowPyrLK(image_b, image_a, p1, p0.copy(), winSize=win,
                                                maxLevel=min(1, levels), criteria=self._criteria, flags=flags)
        p1 = p1.reshape(-1, 2)
        fb = np.linalg.norm(back.reshape(-1, 2) - pts, axis=1)
        h, w = image_b.shape[:2]
        inside = (p1[:, 0] >= 0) & (p1[:, 0] <= w - 1) & (p1[:, 1] >= 0) & (p1[:, 1] <= h - 1)
        ok = (st1.ravel() == 1) & (st2.ravel() == 1) & (fb < self.config.max_fb_error_px) & inside
        return p1, ok

    def _corners(self, left: np.ndarray, wanted: int, taken: np.ndarray) -> np.ndarray:
        """Shi-Tomasi corners (``cv2.goodFeaturesToTrack``), ``wanted`` in all, (N, 2) float32, at least
        ``min_corner_distance_px`` from the features ``taken`` (N, 2) and from each other.

        Each of the ``grid_cells`` keeps its strongest corners first and the strongest of the rest
        fill the places left: corners cover the textured image, and a plain wall still gives its
        best ones.
        """
        c = self.config
        h, w = left.shape
        rows, cols = c.grid_cells
        margin = c.klt_window_px // 2 + 1
        if h <= 2 * margin or w <= 2 * margin or wanted <= 0:
            return np.empty((0, 2), np.float32)
        mask = None
        if len(taken):
            mask = np.full((h - 2 * margin, w - 2 * margin), 255, np.uint8)
            radius = max(1, int(round(c.min_corner_distance_px)))
            for u, v in np.rint(taken - margin).astype(int):
                cv2.circle(mask, (int(u), int(v)), radius, 0, -1)
        inner = left[margin:h - margin, margin:w - margin]
        found = cv2.goodFeaturesToTrack(inner, 2 * wanted, c.corner_quality, c.min_corner_distance_px,
                                        blockSize=c.corner_block_px, mask=mask)
        if found is None:
            return np.empty((0, 2), np.float32)
        uv = found.reshape(-1, 2) + margin                       # strongest first
        cell = (uv[:, 1] * rows // h).astype(np.int64) * cols + (uv[:, 0] * cols // w).astype(np.int64)
        order = np.argsort(cell, kind="stable")                  # strongest first within each cell
        sorted_cells = cell[order]
        rank = np.empty(len(uv), np.int64)
        rank[order] = np.arange(len(order)) - np.searchsorted(sorted_cells, sorted_cells, side="left")
        per_cell = max(1, wanted // (rows * cols))
        first = np.flatnonzero(rank < per_cell)
        rest = np.flatnonzero(rank >= per_cell)[:max(0, wanted - len(first))]
        keep = np.sort(np.concatenate([first, rest]))[:wanted]
        return np.ascontiguousarray(uv[keep], dtype=np.float32)

    def _right_columns(self, left, right, disparity_px, uv, guess_d) -> np.ndarray:
        """Right image column of each feature ``uv`` (NaN: no reliable match).

        Lucas-Kanade finds the match in 2-D; in a rectified pair it lies on the feature's row, so
        the result is moved back onto the row along the patch's gradients: the 1-D Lucas-Kanade
        solution ``x_1d = x_2d + (sum Ix Iy / sum Ix^2) dy`` (from ``G d = b`` with ``dy = 0``). On an
        oblique edge the 2-D solution slides along the edge with the noise; on the row it cannot.
        """
        c = self.config
        if not len(uv):
            return np.empty(0)
        if disparity_px is not None:
            d = _sample_smooth(np.asarray(disparity_px, dtype=np.float64), uv, max_spread=c.max_row_error_px)
        else:
            guess = uv.astype(np.float64).copy()
            guess[:, 0] -= np.nan_to_num(guess_d, nan=0.0)
            uv_right, ok = self._klt(left, _photometry_like(right, left), uv, guess, c.stereo_levels - 1,
                                     c.stereo_window_px)
            dy = uv_right[:, 1] - uv[:, 1]
            ok &= np.abs(dy) <= c.max_row_error_px
            d = np.where(ok, uv[:, 0] - uv_right[:, 0] - _row_slope(left, uv, c.stereo_window_px) * dy, np.nan)
        d = np.where(np.isfinite(d) & (d >= c.min_disparity_px), d, np.nan)
        return uv[:, 0] - d - self._disparity_slopes(uv, self._slopes_px)

    def _new_keyframe(self, left, right, disparity_px, T_world_from_cam, tracked) -> np.ndarray:
        """Make the frame a keyframe: tracked features keep their landmarks, new corners get new ones;
        the window is refined. Returns the frame's (refined) camera pose."""
        c, s = self.config, self.stereo
        if tracked is None:
            ids, uv = np.empty(0, np.int64), np.empty((0, 2), np.float32)
        else:
            ids, uv = tracked
        T_cam_from_world = np.linalg.inv(T_world_from_cam)
        guess_d = np.full(len(uv), np.nan)
        if len(ids):
            z = transform_points(T_cam_from_world, self._map.points(ids))[:, 2]
            guess_d = (s.focal_px * s.baseline_m / np.maximum(z, 1e-3) - s.doffs_px - self._offset_px
                       - self._disparity_slopes(uv, self._slopes_px))
        new_uv = self._corners(left, c.max_features - len(uv), uv)
        all_uv = np.concatenate([uv, new_uv]).astype(np.float32)
        u_right = self._right_columns(left, right, disparity_px, all_uv,
                                      np.concatenate([guess_d, np.full(len(new_uv), np.nan)]))
        # new landmarks: the new corners with a stereo match (eq. 14-16)
        fresh = np.isfinite(u_right[len(uv):])
        nuv = new_uv[fresh]
        points_cam = self._backproject(nuv, nuv[:, 0] - u_right[len(uv):][fresh])
        new_ids = self._map.add_landmarks(transform_points(T_world_from_cam, points_cam))
        kf = Keyframe(frame=self._n_frames, T_world_from_cam=np.array(T_world_from_cam, dtype=np.float64),
                      image=left, landmark=np.concatenate([ids, new_ids]),
                      uv=np.concatenate([uv, nuv]).astype(np.float32),
                      u_right=np.concatenate([u_right[:len(uv)], u_right[len(uv):][fresh]]),
                      disparity_slopes_px=self._slopes_px.copy())
        self._archive_keyframes(self._map.add_keyframe(kf))
        self._keyframe = kf
        self._map.refine()
        return kf.T_world_from_cam

    def _predict(self, elapsed) -> np.ndarray:
        """The motion model's pose ``elapsed`` seconds after the last measured frame."""
        if not self._velocity_known:
            return self._T_measured
        return self._T_measured @ scale_motion(self._velocity, elapsed / self._velocity_dt)

    def _measure(self, T_world_from_cam, elapsed, T_pred) -> None:
        """A measured pose: it updates the velocity and the statistics of the model's deviation."""
        if self._velocity_known:
            off = np.linalg.inv(T_pred) @ T_world_from_cam
            sample = np.array([float(off[:3, 3] @ off[:3, 3]), rotation_angle_rad(off[:3, :3]) ** 2])
            self._n_deviation = min(self._n_deviation + 1, 20)
            self._deviation += (sample - self._deviation) / self._n_deviation
        self._velocity = np.linalg.inv(self._T_measured) @ T_world_from_cam
        self._velocity_dt, self._velocity_known = elapsed, True
        self._T_measured, self._since_measured_s = T_world_from_cam, 0.0
        self._T_anchor, self._anchor_elapsed_s = T_world_from_cam, 0.0

    def _track(self, left, T_pred, dt, kf: Keyframe | None = None, *, T_retry=None, gate=None):
        """Track keyframe ``kf`` (the reference) into ``left`` from the motion model's prediction; when
        that loses most features (a sudden stop, a wrong prediction), again from the last measured pose;
        with ``T_retry``, from that pose too in any case (the better of the two).
        ``gate(T_world_from_cam)``: the plausibility test (default :meth:`_plausible`)."""
        c = self.config
        kf = self._keyframe if kf is None else kf
        valid = np.flatnonzero(kf.valid)
        if len(valid) < c.min_inliers or kf.image is None:
            return LOST, None, 0, 0, None
        points_key = kf.points_cam if kf.points_cam is not None else \
            transform_points(np.linalg.inv(kf.T_world_from_cam), self._map.points(kf.landmark[valid]))
        gate = gate or (lambda T: self._plausible(T, self._predict(dt), dt))
        result = self._track_from(left, T_pred, valid, points_key, kf, gate)
        if T_retry is not None or result[3] < c.keyframe_inlier_fraction * len(valid):
            retry = self._track_from(left, self._T_measured if T_retry is None else T_retry, valid, points_key, kf,
                                     gate)
            if retry[0] != LOST and (result[0] == LOST or retry[3] > result[3]):
                result = retry              # (a pose the gate rejected is no better for its inliers)
        return result

    def _relocalize(self, left, right, disparity_px, T_pred, dt, lost):
        """A frame the reference keyframe could not place: the other keyframes of the window (newest
        first), the archived keyframes near the prediction (:meth:`_relocalize_archived`) and, failing
        those, fresh features of this frame found in the reference keyframe."""
        for kf in reversed(self._map.keyframes):
            if kf is self._keyframe:
                continue
            result = self._track(left, T_pred, dt, kf)
            if result[0] != LOST:
                self._keyframe = kf
                return result
        result = self._relocalize_archived(left, right, disparity_px, T_pred, dt)
        if result is not None:
            return result
        return self._track_fresh(left, right, disparity_px, T_pred, dt, lost)

    def _archive_keyframes(self, keyframes: list[Keyframe]) -> None:
        """Keep the keyframes that left the window, the last ``archive_keyframes`` of them (the older
        ones' images dropped: a live run's memory stays bounded)."""
        self._archive.extend(kf for kf in keyframes if kf.image is not None)
        cut = max(0, len(self._archive) - self.config.archive_keyframes)
        for kf in self._archive[:cut]:
            kf.image = None
        self._archive = self._archive[cut:]

    def _relocalize_archived(self, left, right, disparity_px, T_pred, dt):
        """The frame placed against an archived keyframe near the predicted pose (as ORB-SLAM relocalizes
        against its keyframe database, here by place: after a blackout or a restart from a guess, the
        prediction is off by what the motion did meanwhile, a place seen before is not). The candidates:
        the archived keyframes whose camera is within their median landmark depth of the predicted one
        and looks within 45 degrees of its direction, nearest first, three at most; each is tracked from
        its own pose (no motion since it) and from the prediction, then again from the pose found while
        that adds inliers (from a guess metres off only the far points track: a weak hold on the
        distance moved). The gate is the speed and
        turn-rate limits over the time since the last measured frame (a motion model is no guide after a
        gap). A frame placed so starts a new window there (no jump: the archived keyframe's pose)."""
        c = self.config
        if not self._archive or self._T_anchor is None:
            return None
        centre, axis = T_pred[:3, 3], T_pred[:3, 2]
        near = [(float(np.linalg.norm(kf.T_world_from_cam[:3, 3] - centre)), k) for k, kf in enumerate(self._archive)
                if np.linalg.norm(kf.T_world_from_cam[:3, 3] - centre) <= kf.median_depth_m
                and float(kf.T_world_from_cam[:3, 2] @ axis) >= math.cos(math.radians(45.0))]
        elapsed = self._anchor_elapsed_s + dt

        def gate(T_world_from_cam):
            step = np.linalg.inv(self._T_anchor) @ T_world_from_cam
            return (np.linalg.norm(step[:3, 3]) <= c.max_speed_mps * elapsed
                    and rotation_angle_rad(step[:3, :3]) <= c.max_turn_rate_radps * elapsed)

        found = []
        for _, k in sorted(near)[:3]:
            kf = self._archive[k]
            result = self._track(left, kf.T_world_from_cam, dt, kf, T_retry=T_pred, gate=gate)
            if result[0] == LOST:
                continue
            for _ in range(3):      # again from the pose found: from a far guess only the far points track
                again = self._track(left, result[1], dt, kf, T_retry=result[1], gate=gate)
                if again[0] == LOST or again[3] <= result[3]:
                    break
                result = again
            found.append((float(np.linalg.norm(result[1][:3, 3] - kf.T_world_from_cam[:3, 3])), len(found), result))
        if found:
            # the keyframe nearest the place found saw it best (a periodic facade aliases long tracks)
            result = min(found)[2]
            T_world_from_cam = result[1]
            self._velocity = np.linalg.inv(self._T_anchor) @ T_world_from_cam      # the mean motion over the gap
            self._velocity_dt, self._velocity_known = elapsed, True
            self._T_measured, self._since_measured_s = T_world_from_cam, 0.0
            self._T_anchor, self._anchor_elapsed_s = T_world_from_cam, 0.0
            self._remeasured = True
            self._archive_keyframes(self._map.clear())
            T_world_from_cam = self._new_keyframe(left, right, disparity_px, T_world_from_cam, None)
            return KEYFRAME, T_world_from_cam, result[2], result[3], None
        return None

    def _track_fresh(self, left, right, disparity_px, T_guess, dt, lost):
        """The frame from scratch: new corners with their depth from this frame's pair, found in the
        reference keyframe's image, PnP (the keyframe's view of this frame's points). The reference's
        landmarks are then tracked again from that pose; if they still fail, the frame starts a new
        window (a keyframe at the measured pose: no jump)."""
        c, kf = self.config, self._keyframe
        uv = self._corners(left, c.max_features, np.empty((0, 2), np.float32))
        u_right = self._right_columns(left, right, disparity_px, uv, np.full(len(uv), np.nan))
        stereo = np.isfinite(u_right)
        if stereo.sum() < c.min_inliers or kf.image is None:
            return lost
        uv = uv[stereo]
        points_cam = self._backproject(uv, uv[:, 0] - u_right[stereo])
        T_key_from_guess = np.linalg.inv(kf.T_world_from_cam) @ T_guess
        uv_key, ok = self._klt(left, kf.image, uv, self._project(T_key_from_guess, points_cam, uv), c.klt_levels,
                               c.klt_window_px)
        solved = self._solve_pnp(points_cam[ok], uv_key[ok].astype(np.float64), T_key_from_guess)
        if solved is None:
            return lost
        T_world_from_cam = kf.T_world_from_cam @ solved[0]
        if not self._plausible(T_world_from_cam, T_guess, dt):
            return lost
        result = self._track(left, T_world_from_cam, dt)
        if result[0] != LOST:
            return result
        self._archive_keyframes(self._map.clear())
        T_world_from_cam = self._new_keyframe(left, right, disparity_px, T_world_from_cam, None)
        return KEYFRAME, T_world_from_cam, int(ok.sum()), len(solved[1]), None

    def _project(self, T_b_from_a, points_a, fallback_uv) -> np.ndarray:
        """Pixels (N, 2) of points ``points_a`` seen from b; ``fallback_uv`` where behind the camera."""
        X = transform_points(T_b_from_a, points_a)
        guess = np.asarray(fallback_uv, dtype=np.float64).copy()
        front = X[:, 2] > 0.05
        guess[front] = (X[front, :2] / X[front, 2:3]) * [self._K[0, 0], self._K[1, 1]] + self._K[:2, 2]
        return guess

    def _backproject(self, uv, disparity_px, offset_px: float | None = None) -> np.ndarray:
        """Camera-frame points of pixels ``uv`` (N, 2) with their disparities, eq. (14)-(16), the rig's
        ``doffs`` plus the learnt disparity offset (or ``offset_px``)."""
        s, K = self.stereo, self._K
        offset = self._offset_px if offset_px is None else offset_px
        z = depth_m_from_disparity_px(disparity_px, focal_px=s.focal_px, baseline_m=s.baseline_m,
                                      doffs_px=s.doffs_px + offset)
        return np.column_stack([(uv[:, 0] - K[0, 2]) * z / K[0, 0], (uv[:, 1] - K[1, 2]) * z / K[1, 1], z])

    def _disparity_slopes(self, uv, slopes_px) -> np.ndarray:
        """The row and column terms of the disparity correction at pixels ``uv`` (N, 2): ``b (v - cy) / 100
        + c (u - cx) / 100`` px for ``slopes_px = (b, c)``."""
        K = self._K
        uv = np.asarray(uv, dtype=np.float64).reshape(-1, 2)
        return (slopes_px[0] * (uv[:, 1] - K[1, 2]) + slopes_px[1] * (uv[:, 0] - K[0, 2])) / 100.0

    def _learn_offset(self, kf: Keyframe, tracked, T_world_from_cam) -> None:
        """Learn the disparity correction from the motion between keyframe ``kf`` and this frame.

        A rig whose rectified principal points are off by ``e`` px gives depths ``b f / (d + doffs)``
        wrong by the factor ``d / (d + e)``: far points much more than near ones, which no rigid
        motion reconciles; a right camera rolled against the left adds a disparity error growing down
        the image. The correction is ``e(u, v) = a + b (v - cy) / 100``: the keyframe's stereo points
        are re-made with the correction moved by ``h`` along ``a``, ``b`` and both (6 corrections), the
        pose refined (``cv2.solvePnPRefineLM``) on this frame's tracks each time; the quadratic through
        the (truncated) reprojection costs gives a Newton step, repeated from its vertex (at most 3) to
        the pair's own minimum: its estimate, with the last Hessian its information, summed over the
        run from the prior ``offset_prior_weight`` at 0. The offset alone, with the pose free, takes
        part of a row term into the pose and stops short (a synthetic rig with +1 px and a 5 mrad
        roll: +0.63 px), and one step from a lagging mean stops short again.
        """
        c = self.config
        ids, uv_now = tracked
        order = np.argsort(kf.landmark)
        j = order[np.searchsorted(kf.landmark[order], ids)]
        use = np.isfinite(kf.u_right[j])
        if use.sum() < c.min_inliers:
            return
        uv_key, img = kf.uv[j][use].astype(np.float64), uv_now[use].astype(np.float64)
        d_raw = uv_key[:, 0] - kf.u_right[j][use] - self._disparity_slopes(uv_key, kf.disparity_slopes_px)
        rvec0, tvec0 = rvec_t_from_T(np.linalg.inv(T_world_from_cam) @ kf.T_world_from_cam)
        h, vertex = 0.5, self._correction_mean
        for _ in range(3):                         # Newton steps of the pair's own cost, from the run's mean
            m, costs = vertex, []
            for step in (np.zeros(2), (h, 0.0), (-h, 0.0), (0.0, h), (0.0, -h), (h, h)):
                p = m + step
                obj = self._backproject(uv_key, d_raw + p[1] * (uv_key[:, 1] - self._K[1, 2]) / 100.0, p[0])
                if not (obj[:, 2] > 0).all():
                    return
                rvec, tvec = cv2.solvePnPRefineLM(obj, img, self._K, None, rvec0.copy(), tvec0.copy())
                proj, _ = cv2.projectPoints(obj, rvec, tvec, self._K, None)
                err2 = np.sum((proj.reshape(-1, 2) - img) ** 2, axis=1)
                costs.append(float(np.minimum(err2, c.ransac_threshold_px ** 2).sum()))
            f0, f = costs[0], np.array(costs[1:5]).reshape(2, 2)
            grad = (f[:, 0] - f[:, 1]) / (2.0 * h)
            H = np.diag((f[:, 0] - 2.0 * f0 + f[:, 1]) / (h * h))
            H[0, 1] = H[1, 0] = (costs[5] - f[0, 0] - f[1, 0] + f0) / (h * h)
            if not np.all(np.linalg.eigvalsh(H) > 0.0):
                return
            vertex = np.clip(m - np.linalg.solve(H, grad), -c.max_disparity_offset_px, c.max_disparity_offset_px)
            if np.abs(vertex - m).max() < 0.05:
                break
        self._correction_sum += H @ vertex
        self._correction_info += H
        self._correction_mean = np.linalg.solve(self._correction_info, self._correction_sum)
        # a term is used once the correction it makes reaches min_disparity_offset_px at the image's edge
        # (the principal point's distance from it: about half the image)
        used = np.where(np.abs(self._correction_mean) * [1.0, self._K[1, 2] / 100.0] >= c.min_disparity_offset_px,
                        self._correction_mean, 0.0)
        self._offset_px, self._slopes_px = float(used[0]), np.array([used[1], 0.0])
        self._map.cx_right_px = float(self.stereo.right.P[0, 2]) + self._offset_px

    def _solve_pnp(self, obj, img, T_guess):
        """PnP-RANSAC from ``T_guess`` (camera from object), then LM on the inliers re-selected twice;
        ``(T_cam_from_obj, inliers)`` or None with fewer than ``min_inliers``."""
        c = self.config
        if len(obj) < c.min_inliers:
            return None
        rvec, tvec = rvec_t_from_T(T_guess)
        found, rvec, tvec, inliers = cv2.solvePnPRansac(
            obj, img, self._K, None, rvec.copy(), tvec.copy(), useExtrinsicGuess=True,
            iterationsCount=c.ransac_iterations, reprojectionError=c.ransac_threshold_px, confidence=0.999,
            flags=cv2.SOLVEPNP_ITERATIVE)
        if not found or inliers is None or len(inliers) < c.min_inliers:
            return None
        inl = inliers.ravel()
        for _ in range(2):             # LM on the inliers, re-select under the polished pose
            rvec, tvec = cv2.solvePnPRefineLM(obj[inl], img[inl], self._K, None, rvec, tvec)
            proj, _ = cv2.projectPoints(obj, rvec, tvec, self._K, None)
            err = np.linalg.norm(proj.reshape(-1, 2) - img, axis=1)
            inl = np.flatnonzero(err < c.ransac_threshold_px)
            if len(inl) < c.min_inliers:
                return None
        T = T_from_rvec_t(rvec, tvec)
        return (T, inl) if np.isfinite(T).all() else None

    def _track_from(self, left, T_guess, valid, points_key, kf, gate):
        c = self.config
        T_guess_from_key = np.linalg.inv(T_guess) @ kf.T_world_from_cam
        guess = self._project(T_guess_from_key, points_key, kf.uv[valid])
        uv, ok = self._klt(kf.image, left, kf.uv[valid], guess, c.klt_levels, c.klt_window_px)
        n_tracked = int(ok.sum())
        if n_tracked < c.min_inliers:
            return LOST, None, n_tracked, 0, None
        img = uv[ok].astype(np.float64)
        solved = self._solve_pnp(points_key[ok], img, T_guess_from_key)
        if solved is None:
            return LOST, None, n_tracked, 0, None
        T_cam_from_key, inl = solved
        T_world_from_cam = kf.T_world_from_cam @ np.linalg.inv(T_cam_from_key)
        if not gate(T_world_from_cam):
            # the consensus is implausible: a periodic structure (a facade's windows, a crash barrier's posts)
            # tracked one period off agrees with a wrong motion. The pyramid's coarse levels, where a period is a
            # few pixels, are where the tracks jumped it: when the gate rests on the motion up to the last frame
            # (after a lost frame the gate is wide and the motion model no guide), the tracks are made again from
            # the guess on the full-resolution image alone, and their consensus is judged by the gate too
            if self._anchor_elapsed_s > 0.0 or not self._velocity_known:
                return LOST, None, n_tracked, len(inl), None
            uv, ok = self._klt(kf.image, left, kf.uv[valid], guess, 0, c.klt_window_px)
            img = uv[ok].astype(np.float64)
            fine = self._solve_pnp(points_key[ok], img, T_guess_from_key)
            if fine is None:
                return LOST, None, n_tracked, len(inl), None
            n_tracked, inl = int(ok.sum()), fine[1]
            T_world_from_cam = kf.T_world_from_cam @ np.linalg.inv(fine[0])
            if not gate(T_world_from_cam):
                return LOST, None, n_tracked, len(inl), None
        tracked = (kf.landmark[valid][ok][inl], img[inl].astype(np.float32))
        return TRACKED, T_world_from_cam, n_tracked, len(inl), tracked

    def _plausible(self, T_world_from_cam, T_pred, dt) -> bool:
        """The step from the last measured frame (``dt`` ago) within the speed and turn-rate limits and,
        once the motion is known, its deviation from the motion model's prediction within what the
        acceleration limits allow plus three times the model's usual deviation (its RMS over the last
        measured frames, as kiss-icp's adaptive threshold): a gross failure, never a real motion."""
        c = self.config
        step = np.linalg.inv(self._T_measured) @ T_world_from_cam
        if (np.linalg.norm(step[:3, 3]) > c.max_speed_mps * dt
                or rotation_angle_rad(step[:3, :3]) > c.max_turn_rate_radps * dt):
            return False
        if not self._velocity_known:
            return True
        off = np.linalg.inv(T_pred) @ T_world_from_cam
        sigma = np.sqrt(self._deviation) if self._n_deviation >= 5 else np.zeros(2)
        return (np.linalg.norm(off[:3, 3]) <= c.max_acceleration_mps2 * dt * dt + 3.0 * sigma[0]
                and rotation_angle_rad(off[:3, :3]) <= c.max_angular_acceleration_radps2 * dt * dt + 3.0 * sigma[1])


def _row_slope(image: np.ndarray, uv: np.ndarray, window_px: int) -> np.ndarray:
    """``sum Ix Iy / sum Ix^2`` over the ``window_px`` square around each point ``uv`` (N, 2): how far a
    patch's best match moves along x per pixel it is moved along y."""
    f = image.astype(np.float32)
    ix = cv2.Sobel(f, cv2.CV_32F, 1, 0, ksize=3)
    iy = cv2.Sobel(f, cv2.CV_32F, 0, 1, ksize=3)
    xx = cv2.boxFilter(ix * ix, -1, (window_px, window_px), normalize=False)
    xy = cv2.boxFilter(ix * iy, -1, (window_px, window_px), normalize=False)
    h, w = image.shape
    r = np.clip(np.rint(uv[:, 1]).astype(np.int64), 0, h - 1)
    col = np.clip(np.rint(uv[:, 0]).astype(np.int64), 0, w - 1)
    return xy[r, col] / np.maximum(xx[r, col], 1e-6)


def _sample_smooth(image: np.ndarray, uv: np.ndarray, *, max_spread: float) -> np.ndarray:
    """Bilinear samples at ``uv``; NaN where a neighbour is invalid or the four differ by more
    than ``max_spread`` (a corner on a depth edge takes neither side's depth)."""
    h, w = image.shape
    u0 = np.clip(np.floor(uv[:, 0]).astype(int), 0, w - 2)
    v0 = np.clip(np.floor(uv[:, 1]).astype(int), 0, h - 2)
    a, b = uv[:, 0] - u0, uv[:, 1] - v0
    q = np.stack([image[v0, u0], image[v0, u0 + 1], image[v0 + 1, u0], image[v0 + 1, u0 + 1]])
    value = (q[0] * (1 - a) + q[1] * a) * (1 - b) + (q[2] * (1 - a) + q[3] * a) * b
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(q).all(axis=0) | (np.ptp(q, axis=0) > max_spread)
    value[bad] = np.nan
    return value


def _photometry_like(image: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """``image`` mapped linearly to the mean and spread of ``reference`` (uint8).

    Lucas-Kanade assumes equal brightness; a gain difference between the cameras would shift
    the stereo match on an intensity ramp (a scale error of the odometry).
    """
    mean_i, sd_i = cv2.meanStdDev(image)
    mean_r, sd_r = cv2.meanStdDev(reference)
    sd_i, sd_r = float(sd_i.ravel()[0]), float(sd_r.ravel()[0])
    if sd_i < 1e-6 or sd_r < 1e-6:
        return image
    gain = sd_r / sd_i
    offset = float(mean_r.ravel()[0]) - gain * float(mean_i.ravel()[0])
    if abs(gain - 1.0) < 1e-3 and abs(offset) < 0.05:
        return image
    return cv2.addWeighted(image, gain, image, 0.0, offset, dtype=cv2.CV_8U)


def _gray_u8(name: str, image) -> np.ndarray:
    img = _checks.image(name, image)
    if img.ndim == 3 and img.shape[2] == 1:
        img = img[:, :, 0]
    if img.ndim == 3:
        img = cv2.cvtColor(img if img.dtype == np.uint8 else np.clip(img, 0, 255).astype(np.uint8),
                           cv2.COLOR_BGR2GRAY)
    if img.dtype != np.uint8:
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
    return np.ascontiguousarray(img)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, dtype=np.float64)
    a.setflags(write=False)
    return a
