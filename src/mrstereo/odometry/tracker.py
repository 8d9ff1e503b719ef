"""Stereo visual odometry: KLT tracks against a keyframe, 3-D from stereo, PnP-RANSAC + LM.

Per frame (rectified pair):

1. *Keyframe* (first frame, after tracking thinned out, or after a loss): corners
   (Shi-Tomasi, spread over a grid of cells) of the left image are found in the right image
   (brought to the left one's gain and offset) with pyramidal Lucas-Kanade along the row (or
   read from a given disparity map), kept when the right-to-left track returns within ``max_fb_error_px``
   and ``|y_left - y_right| <= max_row_error_px``, and triangulated with eq. (14)-(16):
   ``Z = b f / (d + doffs)``, ``X = (u - cx) Z / f``, ``Y = (v - cy) Z / f_y``.
2. *Tracking*: the keyframe's corners are tracked into the current left image by
   Lucas-Kanade started at their projection under the motion prior (the previous step
   repeated: constant velocity), with the same forward-backward check. Tracking against
   the keyframe, not frame to frame, means a robot standing still gets the same pose for
   every frame (no random walk).
3. *Pose*: ``cv2.solvePnPRansac`` (reprojection threshold ``ransac_threshold_px``,
   started at the prior) gives ``T_cam_from_keycam``; ``cv2.solvePnPRefineLM`` polishes it
   on the inliers, the inliers are re-selected under the polished pose and polished again.
4. *Failure*: fewer than ``min_inliers`` inliers, or a step larger than ``max_step_m`` /
   ``max_step_rad`` from the previous frame, marks the frame ``lost``: its pose is the last
   good one (never a jump), and after ``max_lost_streak`` lost frames in a row a new
   keyframe starts at that pose.

Poses are of the robot base in the world (REP 103), ``T_world_from_base = T_world_from_cam @
inv(T_base_from_cam)`` with the camera mount of each frame; the first frame's pose is given
(identity by default). Conventions: docs/conventions.md; user guide: docs/odometry.md.

References
----------
D. Nister, O. Naroditsky, J. Bergen. Visual odometry. CVPR 2004 (stereo VO with 3-D
points and RANSAC). B. Kitt, A. Geiger, H. Lategahn. Visual odometry based on stereo image
sequences with RANSAC-based outlier rejection scheme. IV 2010. J.-Y. Bouguet. Pyramidal
implementation of the Lucas Kanade feature tracker. Intel, 2000. J. Shi, C. Tomasi. Good
features to track. CVPR 1994.
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
from ..transforms import T_from_rvec_t, rotation_angle_rad, rvec_t_from_T

__all__ = ["OdometryConfig", "FrameEstimate", "StereoOdometry", "TRACKED", "KEYFRAME", "LOST"]

TRACKED, KEYFRAME, LOST = "tracked", "keyframe", "lost"


@dataclass(frozen=True)
class OdometryConfig:
    """Visual odometry settings (defaults measured on the synthetic corridor, docs/odometry.md).

    Attributes
    ----------
    max_features : int
        Corners per keyframe (spread over ``grid_cells`` cells, rows x columns).
    corner_quality : float
        Weakest Shi-Tomasi corner kept, as a fraction of the strongest (``qualityLevel`` of
        ``cv2.goodFeaturesToTrack``).
    corner_block_px : int
        Window of the corners' gradient matrix.
    min_corner_distance_px : float
        At most one corner per square of this size.
    klt_window_px, klt_levels : int
        Lucas-Kanade window and pyramid levels of the tracking from the keyframe (a small window:
        approaching a surface magnifies it, which a translating window follows with a bias toward
        too little motion, so a larger window underestimates the distance travelled).
    stereo_window_px : int
        Lucas-Kanade window of the left-right search of keyframe corners (``klt_levels + 1``
        levels; the two views differ by the baseline only, and a larger window matches weak
        texture more reliably).
    max_fb_error_px : float
        Forward-backward track error above which a track is dropped.
    max_row_error_px : float
        Largest ``|y_left - y_right|`` of a stereo match (rectified images); with a given
        disparity map, the largest spread of the four disparities around a corner.
    min_disparity_px : float
        Closest to infinity a point may be (its depth is ``b f / d``).
    ransac_threshold_px : float
        Reprojection error of a PnP inlier.
    ransac_iterations : int
    min_inliers : int
        Fewer inliers: the frame is lost.
    keyframe_inlier_fraction : float
        A new keyframe when the inliers fall below this fraction of the keyframe's points.
    keyframe_distance_m, keyframe_angle_rad : float
        A new keyframe after this motion from the keyframe.
    max_step_m, max_step_rad : float
        A larger step from the previous frame is a failure, not a motion.
    max_lost_streak : int
        Lost frames in a row before tracking restarts from a new keyframe.
    """

    max_features: int = 300
    grid_cells: tuple[int, int] = (2, 3)
    corner_quality: float = 0.001
    corner_block_px: int = 5
    min_corner_distance_px: float = 8.0
    klt_window_px: int = 11
    stereo_window_px: int = 21
    klt_levels: int = 3
    max_fb_error_px: float = 0.5
    max_row_error_px: float = 1.0
    min_disparity_px: float = 1.0
    ransac_threshold_px: float = 1.0
    ransac_iterations: int = 100
    min_inliers: int = 12
    keyframe_inlier_fraction: float = 0.5
    keyframe_distance_m: float = 1.0
    keyframe_angle_rad: float = math.radians(20.0)
    max_step_m: float = 1.0
    max_step_rad: float = math.radians(30.0)
    max_lost_streak: int = 2

    def __post_init__(self) -> None:
        for name in ("max_features", "klt_window_px", "stereo_window_px", "klt_levels", "ransac_iterations", "min_inliers",
                     "corner_block_px", "max_lost_streak"):
            _checks.positive_int(name, getattr(self, name), minimum=4 if name == "min_inliers" else 1)
        for name in ("min_corner_distance_px", "max_fb_error_px", "max_row_error_px",
                     "min_disparity_px", "ransac_threshold_px", "keyframe_distance_m", "keyframe_angle_rad",
                     "max_step_m", "max_step_rad"):
            _checks.finite_number(name, getattr(self, name), positive=True)
        if not 0.0 < self.corner_quality < 1.0:
            raise ValueError(f"corner_quality must be in (0, 1), got {self.corner_quality}")
        if not 0.0 < self.keyframe_inlier_fraction < 1.0:
            raise ValueError(f"keyframe_inlier_fraction must be in (0, 1), got {self.keyframe_inlier_fraction}")
        if len(self.grid_cells) != 2 or min(self.grid_cells) < 1:
            raise ValueError(f"grid_cells must be (rows, cols) >= 1, got {self.grid_cells!r}")


@dataclass(frozen=True)
class FrameEstimate:
    """One frame's result: the base pose and how it was obtained."""

    T_world_from_base: np.ndarray
    status: str
    n_tracked: int
    n_inliers: int
    time_s: float


@dataclass
class _Keyframe:
    image: np.ndarray              # left image (uint8)
    uv: np.ndarray                 # (N, 2) float32, left image
    points_cam: np.ndarray         # (N, 3) float64, keyframe camera
    T_world_from_cam: np.ndarray


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
    """

    stereo: StereoCamera
    T_world_from_base0: np.ndarray | None = None
    config: OdometryConfig = field(default_factory=OdometryConfig)

    def __post_init__(self) -> None:
        if not isinstance(self.stereo, StereoCamera):
            raise TypeError(f"stereo must be a StereoCamera, got {type(self.stereo).__name__}")
        if not isinstance(self.config, OdometryConfig):
            raise TypeError(f"config must be an OdometryConfig, got {type(self.config).__name__}")
        T0 = np.eye(4) if self.T_world_from_base0 is None else self.T_world_from_base0
        self.T_world_from_base0 = _checks.matrix("T_world_from_base0", T0, (4, 4)).copy()
        P = self.stereo.left.P
        self._K = np.array([[P[0, 0], 0.0, P[0, 2]], [0.0, P[1, 1], P[1, 2]], [0.0, 0.0, 1.0]])
        self._keyframe: _Keyframe | None = None
        self._T_world_from_cam: np.ndarray | None = None      # last good camera pose
        self._velocity = np.eye(4)                             # T_prevcam_from_cam of the last step
        self._lost_streak = 0
        c = self.config
        self._criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.03)

    # -- public -----------------------------------------------------------------------------
    def step(self, left_rect, right_rect, *, T_base_from_cam, disparity_px=None) -> FrameEstimate:
        """Estimate the pose of the next frame.

        Parameters
        ----------
        left_rect, right_rect : ndarray (H, W) or (H, W, 3)
            The rectified pair (uint8 or float).
        T_base_from_cam : ndarray (4, 4)
            The left camera's mount on the base for this frame (e.g. with the head's pan).
        disparity_px : ndarray (H, W), optional
            This frame's disparity (NaN invalid); when given, keyframe points take their
            depth from it instead of a stereo Lucas-Kanade search.
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
        if self._keyframe is None:
            T_world_from_cam = self.T_world_from_base0 @ T_base_from_cam
            return self._finish(start, T_world_from_cam, T_base_from_cam, KEYFRAME,
                                *self._new_keyframe(left, right, disparity_px, T_world_from_cam))
        status, T_world_from_cam, n_tracked, n_inliers = self._track(left)
        if status == LOST:
            self._lost_streak += 1
            T_world_from_cam = self._T_world_from_cam
            if self._lost_streak >= self.config.max_lost_streak:
                self._keyframe = None          # restart at the held pose (the base keeps its pose)
                held = T_world_from_cam @ np.linalg.inv(self._last_T_base_from_cam) @ T_base_from_cam
                self._new_keyframe(left, right, disparity_px, held)
                self._velocity = np.eye(4)
                self._lost_streak = 0
                self._T_world_from_cam = held
            held_base = T_world_from_cam @ np.linalg.inv(self._last_T_base_from_cam)
            return FrameEstimate(T_world_from_base=_readonly(held_base), status=LOST, n_tracked=n_tracked,
                                 n_inliers=n_inliers, time_s=time.thread_time() - start)
        self._lost_streak = 0
        kf = self._keyframe
        T_key_from_cam = np.linalg.inv(kf.T_world_from_cam) @ T_world_from_cam
        if (n_inliers < self.config.keyframe_inlier_fraction * len(kf.uv)
                or np.linalg.norm(T_key_from_cam[:3, 3]) > self.config.keyframe_distance_m
                or rotation_angle_rad(T_key_from_cam[:3, :3]) > self.config.keyframe_angle_rad):
            n_points, _ = self._new_keyframe(left, right, disparity_px, T_world_from_cam)
            if n_points >= self.config.min_inliers:
                status = KEYFRAME
        return self._finish(start, T_world_from_cam, T_base_from_cam, status, n_tracked, n_inliers)

    # -- internals --------------------------------------------------------------------------
    def _finish(self, start, T_world_from_cam, T_base_from_cam, status, n_tracked, n_inliers) -> FrameEstimate:
        if self._T_world_from_cam is not None:
            self._velocity = np.linalg.inv(self._T_world_from_cam) @ T_world_from_cam
        self._T_world_from_cam = T_world_from_cam
        self._last_T_base_from_cam = T_base_from_cam
        T_world_from_base = T_world_from_cam @ np.linalg.inv(T_base_from_cam)
        return FrameEstimate(T_world_from_base=_readonly(T_world_from_base), status=status,
                             n_tracked=int(n_tracked), n_inliers=int(n_inliers), time_s=time.thread_time() - start)

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

    def _corners(self, left: np.ndarray) -> np.ndarray:
        """Shi-Tomasi corners spread over a grid of cells (``max_features`` in all), (N, 2) float32.

        ``cv2.goodFeaturesToTrack`` (the minimum eigenvalue of the gradient matrix, the corner
        that Lucas-Kanade tracks well; Shi and Tomasi 1994) keeps corners at least
        ``min_corner_distance_px`` apart whose strength is ``corner_quality`` of the strongest or
        more; each of the ``grid_cells`` keeps its strongest ones first, and the places left are
        filled with the strongest of the rest, so corners cover the image where it has texture
        and weakly textured images (plain walls) still give their best corners.
        """
        c = self.config
        h, w = left.shape
        rows, cols = c.grid_cells
        margin = c.klt_window_px // 2 + 1
        if h <= 2 * margin or w <= 2 * margin:
            return np.empty((0, 2), np.float32)
        inner = left[margin:h - margin, margin:w - margin]
        found = cv2.goodFeaturesToTrack(inner, 2 * c.max_features, c.corner_quality, c.min_corner_distance_px,
                                        blockSize=c.corner_block_px)
        if found is None:
            return np.empty((0, 2), np.float32)
        uv = found.reshape(-1, 2) + margin                       # strongest first
        cell = (uv[:, 1] * rows // h).astype(np.int64) * cols + (uv[:, 0] * cols // w).astype(np.int64)
        order = np.argsort(cell, kind="stable")                  # strongest first within each cell
        sorted_cells = cell[order]
        rank = np.empty(len(uv), np.int64)
        rank[order] = np.arange(len(order)) - np.searchsorted(sorted_cells, sorted_cells, side="left")
        per_cell = max(1, c.max_features // (rows * cols))
        first = np.flatnonzero(rank < per_cell)
        rest = np.flatnonzero(rank >= per_cell)[:max(0, c.max_features - len(first))]
        keep = np.sort(np.concatenate([first, rest]))[:c.max_features]
        return np.ascontiguousarray(uv[keep], dtype=np.float32)

    def _new_keyframe(self, left, right, disparity_px, T_world_from_cam) -> tuple[int, int]:
        """Corners of ``left`` with their 3-D points; becomes the keyframe. Returns (points, points)."""
        c, s = self.config, self.stereo
        uv = self._corners(left)
        d = np.full(len(uv), np.nan)
        if len(uv):
            if disparity_px is not None:
                d = _sample_smooth(np.asarray(disparity_px, dtype=np.float64), uv, max_spread=c.max_row_error_px)
            else:
                uv_right, ok = self._klt(left, _photometry_like(right, left), uv, uv, c.klt_levels + 1,
                                         c.stereo_window_px)
                ok &= np.abs(uv_right[:, 1] - uv[:, 1]) <= c.max_row_error_px
                d = np.where(ok, uv[:, 0] - uv_right[:, 0], np.nan)
        keep = np.isfinite(d) & (d >= c.min_disparity_px)
        uv, d = uv[keep], d[keep]
        z = depth_m_from_disparity_px(d, focal_px=s.focal_px, baseline_m=s.baseline_m, doffs_px=s.doffs_px)
        K = self._K
        points = np.column_stack([(uv[:, 0] - K[0, 2]) * z / K[0, 0], (uv[:, 1] - K[1, 2]) * z / K[1, 1], z])
        self._keyframe = _Keyframe(image=left, uv=uv, points_cam=points,
                                   T_world_from_cam=np.array(T_world_from_cam, dtype=np.float64))
        return len(uv), len(uv)

    def _track(self, left) -> tuple[str, np.ndarray | None, int, int]:
        c, kf = self.config, self._keyframe
        if len(kf.uv) < c.min_inliers:
            return LOST, None, 0, 0
        # motion prior: the last step again (constant velocity); predicted projections start KLT
        T_world_from_pred = self._T_world_from_cam @ self._velocity
        T_pred_from_key = np.linalg.inv(T_world_from_pred) @ kf.T_world_from_cam
        X = kf.points_cam @ T_pred_from_key[:3, :3].T + T_pred_from_key[:3, 3]
        guess = kf.uv.astype(np.float64).copy()
        front = X[:, 2] > 0.05
        proj = (X[front, :2] / X[front, 2:3]) * [self._K[0, 0], self._K[1, 1]] + self._K[:2, 2]
        guess[front] = proj
        uv, ok = self._klt(kf.image, left, kf.uv, guess, c.klt_levels, c.klt_window_px)
        n_tracked = int(ok.sum())
        if n_tracked < c.min_inliers:
            return LOST, None, n_tracked, 0
        obj = kf.points_cam[ok]
        img = uv[ok].astype(np.float64)
        rvec, tvec = rvec_t_from_T(T_pred_from_key)
        found, rvec, tvec, inliers = cv2.solvePnPRansac(
            obj, img, self._K, None, rvec.copy(), tvec.copy(), useExtrinsicGuess=True,
            iterationsCount=c.ransac_iterations, reprojectionError=c.ransac_threshold_px, confidence=0.999,
            flags=cv2.SOLVEPNP_ITERATIVE)
        if not found or inliers is None or len(inliers) < c.min_inliers:
            return LOST, None, n_tracked, 0 if inliers is None else len(inliers)
        inl = inliers.ravel()
        for _ in range(2):             # LM on the inliers, re-select under the polished pose
            rvec, tvec = cv2.solvePnPRefineLM(obj[inl], img[inl], self._K, None, rvec, tvec)
            proj, _ = cv2.projectPoints(obj, rvec, tvec, self._K, None)
            err = np.linalg.norm(proj.reshape(-1, 2) - img, axis=1)
            inl = np.flatnonzero(err < c.ransac_threshold_px)
            if len(inl) < c.min_inliers:
                return LOST, None, n_tracked, len(inl)
        T_cam_from_key = T_from_rvec_t(rvec, tvec)
        T_world_from_cam = kf.T_world_from_cam @ np.linalg.inv(T_cam_from_key)
        step = np.linalg.inv(self._T_world_from_cam) @ T_world_from_cam
        if (not np.isfinite(T_world_from_cam).all() or np.linalg.norm(step[:3, 3]) > c.max_step_m
                or rotation_angle_rad(step[:3, :3]) > c.max_step_rad):
            return LOST, None, n_tracked, len(inl)
        return TRACKED, T_world_from_cam, n_tracked, len(inl)


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

    The two cameras of a rig differ in gain and black level; Lucas-Kanade assumes equal
    brightness, and on an intensity ramp a gain difference shifts the match (a disparity bias,
    hence a scale error of the odometry). The cameras' differences are global, so one gain and
    one offset from the images' means and standard deviations remove them.
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
