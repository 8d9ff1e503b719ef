"""Visual odometry over a sequence of rectified pairs.

Conventions: docs/conventions.md; user guide: docs/odometry.md.
"""
from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..camera import StereoCamera
from ..profiling import stage
from ..transforms import planar_from_T
from .tracker import LOST, OdometryConfig, StereoOdometry

__all__ = ["OdometryResult", "visual_odometry"]


@dataclass(frozen=True)
class OdometryResult:
    """Poses of a sequence from visual odometry.

    ``T_world_from_base`` (N, 4, 4) after the windowed refinement (a lost frame: the motion model's
    prediction) and ``T_world_from_base_online`` as known at each frame (or None); ``status``
    ``"keyframe"``, ``"tracked"`` or ``"lost"``; ``n_tracked`` and ``n_inliers`` (PnP) per frame;
    ``time_s`` of the stage alone per frame; the input's ``stamps_s`` or None.
    """

    T_world_from_base: np.ndarray
    status: tuple[str, ...]
    n_tracked: np.ndarray
    n_inliers: np.ndarray
    time_s: np.ndarray
    stamps_s: np.ndarray | None = None
    T_world_from_base_online: np.ndarray | None = None

    @property
    def poses(self) -> np.ndarray:
        """Planar poses ``(N, 3)``: ``(x_m, y_m, yaw_rad)``."""
        return planar_from_T(self.T_world_from_base)

    @property
    def tracked(self) -> np.ndarray:
        """True for the frames whose pose was measured (not lost)."""
        return np.array([s != LOST for s in self.status], bool)

    @property
    def n_lost(self) -> int:
        return int((~self.tracked).sum())

    @property
    def success(self) -> bool:
        return self.n_lost == 0

    @property
    def message(self) -> str:
        lost = np.flatnonzero(~self.tracked)
        if not len(lost):
            return f"tracked all {len(self.status)} frames"
        shown = ", ".join(str(k) for k in lost[:10]) + (", ..." if len(lost) > 10 else "")
        return (f"lost tracking on {len(lost)} of {len(self.status)} frames ({shown}); their poses are the motion "
                f"model's prediction")


def visual_odometry(pairs: Iterable, stereo: StereoCamera, *, T_base_from_cam,
                    T_world_from_base0=None, config: OdometryConfig | None = None,
                    disparities: Iterable | None = None, stamps_s: Sequence[float] | None = None,
                    progress=None) -> OdometryResult:
    """Run :class:`~mrstereo.odometry.tracker.StereoOdometry` over rectified pairs.

    Parameters
    ----------
    pairs : iterable of (left_rect, right_rect)
    stereo : StereoCamera
    T_base_from_cam : ndarray (4, 4) or sequence of them
        The camera mount, one for all frames or one per frame.
    T_world_from_base0 : ndarray (4, 4), optional
        First pose (identity).
    disparities : iterable of ndarray, optional
        Each frame's disparity (keyframe depth from it instead of a stereo search).
    stamps_s : sequence of float, optional
        Increasing time stamps (without: ``config.frame_interval_s`` apart).
    progress : callable, optional
        Wraps the iteration (e.g. ``tqdm``).
    """
    tracker = StereoOdometry(stereo, T_world_from_base0, config or OdometryConfig())
    mounts = np.asarray(T_base_from_cam, dtype=np.float64)
    per_frame = mounts.ndim == 3
    if mounts.shape[-2:] != (4, 4) or mounts.ndim not in (2, 3):
        raise ValueError(f"T_base_from_cam must be (4, 4) or (N, 4, 4), got {mounts.shape}")
    disp_iter = iter(disparities) if disparities is not None else None
    stamps = None if stamps_s is None else np.asarray(stamps_s, dtype=np.float64).ravel()
    if stamps is not None and (not np.isfinite(stamps).all() or (np.diff(stamps) <= 0).any()):
        raise ValueError("stamps_s must be finite and increasing")
    items = progress(pairs) if progress is not None else pairs
    estimates = []
    for k, pair in enumerate(items):
        if per_frame and k >= len(mounts):
            raise ValueError(f"T_base_from_cam has {len(mounts)} mounts but there are more frames")
        if stamps is not None and k >= len(stamps):
            raise ValueError(f"stamps_s has {len(stamps)} stamps but there are more frames")
        left, right = pair
        disparity = next(disp_iter) if disp_iter is not None else None
        with stage("odometry"):
            estimates.append(tracker.step(left, right, T_base_from_cam=mounts[k] if per_frame else mounts,
                                          disparity_px=disparity, stamp_s=None if stamps is None else stamps[k]))
    if not estimates:
        raise ValueError("pairs is empty: visual odometry needs at least one frame")
    if stamps is not None and stamps.shape != (len(estimates),):
        raise ValueError(f"stamps_s must have one stamp per frame ({len(estimates)}), got {stamps.shape}")
    online = np.stack([e.T_world_from_base for e in estimates])
    T = tracker.trajectory()
    for a in (T, online):
        a.setflags(write=False)
    return OdometryResult(T_world_from_base=T, status=tuple(e.status for e in estimates),
                          n_tracked=np.array([e.n_tracked for e in estimates]),
                          n_inliers=np.array([e.n_inliers for e in estimates]),
                          time_s=np.array([e.time_s for e in estimates]), stamps_s=stamps,
                          T_world_from_base_online=online)
