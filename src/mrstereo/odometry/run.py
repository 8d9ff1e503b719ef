"""Visual odometry over a sequence: a dataset manifest or any iterable of rectified pairs.

Conventions: docs/conventions.md; user guide: docs/odometry.md.
"""
from __future__ import annotations

import os
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

from ..camera import StereoCamera
from ..geometry.frames import T_robot_from_cam
from ..profiling import stage
from .se3 import T_from_planar, planar_from_T
from .tracker import LOST, OdometryConfig, StereoOdometry

__all__ = ["OdometryResult", "visual_odometry", "odometry_from_manifest", "T_base_from_cam_of"]


@dataclass(frozen=True)
class OdometryResult:
    """Poses of a sequence from visual odometry.

    Attributes
    ----------
    T_world_from_base : ndarray (N, 4, 4)
        Base pose of every frame (REP 103); a lost frame holds the last tracked pose.
    status : tuple of str
        ``"keyframe"``, ``"tracked"`` or ``"lost"`` per frame.
    n_tracked, n_inliers : ndarray (N,) int
        Keyframe corners tracked into the frame, and PnP inliers among them.
    time_s : ndarray (N,)
        Time the odometry took per frame (the stage alone, no image reading).
    stamps_s : ndarray (N,) or None
        Frame stamps when the input had them.
    """

    T_world_from_base: np.ndarray
    status: tuple[str, ...]
    n_tracked: np.ndarray
    n_inliers: np.ndarray
    time_s: np.ndarray
    stamps_s: np.ndarray | None = None

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
        return f"lost tracking on {len(lost)} of {len(self.status)} frames ({shown}); their poses hold the last one"


def T_base_from_cam_of(rig, pan_rad: float = 0.0, *, stereo: StereoCamera | None = None) -> np.ndarray:
    """The left *rectified* camera's mount on the base, with the head's pan.

    ``rig``: the paper's ``RigMount`` (height, tilt: the rectified frame, as the mapping chain
    uses it), a 6-DoF ``CameraMount`` of the raw camera (turned into the rectified frame with
    ``stereo.left.R``), or None (a level camera on the floor: the base is the camera's REP 103
    body frame).
    """
    from ..geometry.frames import CameraMount

    if rig is None:
        rig = CameraMount.from_xyz_rpy((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    if isinstance(rig, CameraMount):
        T = rig.T_base_from_cam_panned(pan_rad)
        if stereo is not None:
            T_cam_from_rect = np.eye(4)
            T_cam_from_rect[:3, :3] = np.asarray(stereo.left.R, dtype=np.float64).T
            T = T @ T_cam_from_rect
        return T
    return T_robot_from_cam(height_m=rig.height_m, tilt_rad=rig.tilt_rad, pan_rad=pan_rad)


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
    progress : callable, optional
        Wraps the iteration (e.g. ``tqdm``).
    """
    tracker = StereoOdometry(stereo, T_world_from_base0, config or OdometryConfig())
    mounts = np.asarray(T_base_from_cam, dtype=np.float64)
    per_frame = mounts.ndim == 3
    if mounts.shape[-2:] != (4, 4) or mounts.ndim not in (2, 3):
        raise ValueError(f"T_base_from_cam must be (4, 4) or (N, 4, 4), got {mounts.shape}")
    disp_iter = iter(disparities) if disparities is not None else None
    items = progress(pairs) if progress is not None else pairs
    estimates = []
    for k, pair in enumerate(items):
        if per_frame and k >= len(mounts):
            raise ValueError(f"T_base_from_cam has {len(mounts)} mounts but there are more frames")
        left, right = pair
        disparity = next(disp_iter) if disp_iter is not None else None
        with stage("odometry"):
            estimates.append(tracker.step(left, right, T_base_from_cam=mounts[k] if per_frame else mounts,
                                          disparity_px=disparity))
    if not estimates:
        raise ValueError("pairs is empty: visual odometry needs at least one frame")
    stamps = None if stamps_s is None else np.asarray(stamps_s, dtype=np.float64)
    if stamps is not None and stamps.shape != (len(estimates),):
        raise ValueError(f"stamps_s must have one stamp per frame ({len(estimates)}), got {stamps.shape}")
    T = np.stack([e.T_world_from_base for e in estimates])
    T.setflags(write=False)
    return OdometryResult(T_world_from_base=T, status=tuple(e.status for e in estimates),
                          n_tracked=np.array([e.n_tracked for e in estimates]),
                          n_inliers=np.array([e.n_inliers for e in estimates]),
                          time_s=np.array([e.time_s for e in estimates]), stamps_s=stamps)


def odometry_from_manifest(manifest, *, config: OdometryConfig | None = None, calibration: StereoCamera | None = None,
                           initial_pose: str = "given", progress: bool = False) -> OdometryResult:
    """Visual odometry of a dataset (docs/dataset.md): rectified pairs, or raw ones rectified.

    Parameters
    ----------
    manifest : Manifest or path
    calibration : StereoCamera, optional
        Overrides the manifest's (the raw images are then rectified with it).
    initial_pose : {"given", "identity"}
        Start at the first frame's pose in the manifest, or at the origin.
    """
    from ..pipeline import frame_pair
    from ..recording import Manifest, read_manifest

    if not isinstance(manifest, Manifest):
        if not isinstance(manifest, (str, os.PathLike)):
            raise TypeError(f"manifest must be a Manifest or a path, got {type(manifest).__name__}")
        manifest = read_manifest(manifest)
    if initial_pose not in ("given", "identity"):
        raise ValueError(f"initial_pose must be 'given' or 'identity', got {initial_pose!r}")
    stereo = manifest.calibration if calibration is None else calibration
    prefer_raw = calibration is not None

    def pairs():
        for record in manifest.frames:
            left, right, rectified = frame_pair(record, prefer_raw=prefer_raw)
            if not rectified and not stereo.is_rectified:
                left, right = stereo.rectify(left, right)
            yield left, right

    mounts = np.stack([T_base_from_cam_of(manifest.rig, r.pan_rad, stereo=stereo) for r in manifest.frames])
    T0 = T_from_planar(*manifest.frames[0].pose) if initial_pose == "given" else np.eye(4)
    wrap = None
    if progress:
        from tqdm import tqdm

        def wrap(it):
            return tqdm(it, total=len(manifest.frames), desc="odometry", unit="frame")
    stamps = [getattr(r, "stamp_s", None) for r in manifest.frames]
    stamps = None if any(s is None for s in stamps) else stamps
    return visual_odometry(pairs(), stereo, T_base_from_cam=mounts, T_world_from_base0=T0, config=config,
                           stamps_s=stamps, progress=wrap)
