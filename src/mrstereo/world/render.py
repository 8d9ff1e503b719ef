"""Stereo rendering of the synthetic corridor with exact ground truth.

:func:`default_stereo` is the *true* calibration of the simulated rig; :func:`render_stereo_frame`
renders the raw cameras (rays through the distortion model, paper eq. 1-3, then ``R``), the ideally
rectified pair and the ground truth of the rectified left camera: disparity ``d = b f / Z``
(eq. 14), depth and labels. User guide: docs/world.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..camera import Camera, CameraInfo, CameraMount, StereoCamera
from ..transforms import T_from_planar, rotation_from_rpy
from . import _kernels
from .scene import Scene

__all__ = ["StereoFrame", "SensorModel", "default_stereo", "render_stereo_frame", "camera_poses",
           "render_view", "sensor_noise_sigma"]

sensor_noise_sigma = 2.0
"""Standard deviation of the simulated sensor noise, grey levels."""

_EXPOSURE = 255.0 * 0.95   # radiance 1.0 -> grey level


@dataclass(frozen=True)
class SensorModel:
    """How one camera turns radiance into grey levels (gain relative, black level and noise in grey levels):
    ``grey = clip(round(gain * 242.25 * radiance + black_level + N(0, noise_sigma)), 0, 255)``.
    """

    gain: float = 1.0
    black_level: float = 0.0
    noise_sigma: float = sensor_noise_sigma

    def __post_init__(self) -> None:
        _checks.finite_number("gain", self.gain, positive=True)
        _checks.finite_number("black_level", self.black_level)
        _checks.finite_number("noise_sigma", self.noise_sigma, nonnegative=True)


@dataclass(frozen=True)
class StereoFrame:
    """One rendered stereo frame with its ground truth.

    ``raw_left, raw_right`` what the distorted, misaligned cameras see; ``left_rect, right_rect`` the
    ideally rectified pair (uint8); ``disparity_px`` (NaN where no surface), ``depth_m`` (``Z``) and
    ``labels`` (``LABEL_*``) of the rectified left camera; the robot ``pose`` ``(x_m, y_m, yaw_rad)``,
    the head's ``pan_rad`` and ``T_world_from_cam`` of the rectified left camera.
    """

    raw_left: np.ndarray
    raw_right: np.ndarray
    left_rect: np.ndarray
    right_rect: np.ndarray
    disparity_px: np.ndarray
    depth_m: np.ndarray
    labels: np.ndarray
    pose: tuple[float, float, float]
    pan_rad: float
    T_world_from_cam: np.ndarray


def default_stereo(width: int = 320, height: int = 240, *, height_m: float = 0.45,
                   tilt_rad: float = 0.15) -> StereoCamera:
    """The simulated stereo head: its exact calibration and mount (docs/world.md, "The stereo rig").

    Parameters
    ----------
    width, height : int
        320x240 (the paper's cameras, Sec. 3, Fig. 4): ``fx = 200 px``, baseline 0.12 m; 640x480:
        ``fx = 451 px``, baseline 0.075 m; other sizes scale 200 px with the width. The raw cameras
        are distorted and rotated slightly, so rectification is not the identity.
    height_m, tilt_rad : float
        The rig's mount (:meth:`mrstereo.camera.CameraMount.from_rig`).
    """
    width = _checks.positive_int("width", width, minimum=16)
    height = _checks.positive_int("height", height, minimum=16)
    if (width, height) == (640, 480):
        f, baseline = 451.0, 0.075
    else:
        f, baseline = 200.0 * width / 320.0, 0.12
    s = width / 320.0
    cx, cy = (width - 1) / 2.0 + 1.6 * s, (height - 1) / 2.0 - 1.1 * s
    rect = Camera(width=width, height=height, fx=f, fy=f, cx=cx, cy=cy)
    raw_left = Camera(width=width, height=height, fx=f * 1.0075, fy=f * 1.0040, cx=cx + 2.1 * s,
                      cy=cy + 1.4 * s, k1=-0.045, k2=0.006)
    raw_right = Camera(width=width, height=height, fx=f * 0.9960, fy=f * 0.9995, cx=cx - 2.7 * s,
                       cy=cy + 2.3 * s, k1=-0.040, k2=0.004)
    R_left = rotation_from_rpy(0.0040, -0.0060, 0.0030)     # raw left -> rectified
    R_right = rotation_from_rpy(-0.0035, 0.0120, -0.0050)   # raw right -> rectified
    P_left = np.hstack([rect.K, np.zeros((3, 1))])
    P_right = P_left.copy()
    P_right[0, 3] = -f * baseline
    mount = CameraMount.from_rig(height_m, tilt_rad, R_rect_from_cam=R_left)
    return StereoCamera(left=CameraInfo(raw_left, R=R_left, P=P_left, name="left"),
                        right=CameraInfo(raw_right, R=R_right, P=P_right, name="right"), mount=mount)


def camera_poses(stereo: StereoCamera, *, pose, pan_rad: float = 0.0,
                 mount: CameraMount | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``T_world_from_cam`` (4x4) of the rectified left and right cameras for a robot pose."""
    _checks.instance("stereo", stereo, StereoCamera)
    mount = stereo.mount if mount is None else mount
    if mount is None:
        raise ValueError("stereo has no camera mount; pass mount=CameraMount(...)")
    x, y, yaw = _pose(pose)
    T_left = T_from_planar(x, y, yaw) @ mount.T_base_from_rectified(stereo.left.R, pan_rad)
    T_right = T_left.copy()
    T_right[:3, 3] = T_left[:3, 3] + T_left[:3, 0] * stereo.baseline_m
    return T_left, T_right


def _pose(pose) -> tuple[float, float, float]:
    try:
        values = [float(v) for v in pose]
    except (TypeError, ValueError):
        raise ValueError(f"pose must be (x_m, y_m, yaw_rad) numbers, got {pose!r}") from None
    if len(values) != 3 or not np.all(np.isfinite(values)):
        raise ValueError(f"pose must be 3 finite numbers (x_m, y_m, yaw_rad), got {pose!r}")
    return values[0], values[1], values[2]


_RAY_CACHE: OrderedDict = OrderedDict()
_RAY_CACHE_BYTES = 256 * 2**20     # ray tables kept between frames (a 320x240 2x2 table is 7 MB)


def _sample_offsets(supersample: int) -> np.ndarray:
    g = (np.arange(supersample) + 0.5) / supersample - 0.5
    return np.stack(np.meshgrid(g, g, indexing="xy"), -1).reshape(-1, 2)   # (S, 2) as (du, dv)


def _ray_table(info: CameraInfo, *, raw: bool, supersample: int) -> np.ndarray:
    """Sample rays (H, W, S, 3) in the *rectified* frame of this camera (cached)."""
    cam = info.camera
    key = (cam, raw, info.R.tobytes(), info.P.tobytes(), supersample)
    table = _RAY_CACHE.get(key)
    if table is not None:
        _RAY_CACHE.move_to_end(key)
        return table
    v, u = np.mgrid[0:cam.height, 0:cam.width].astype(np.float64)
    off = _sample_offsets(supersample)
    uv = np.stack([u[..., None] + off[:, 0], v[..., None] + off[:, 1]], -1).reshape(-1, 2)
    if raw:
        dirs = cam.rays(uv) @ info.R.T                     # raw ray -> rectified frame: R @ d
    else:
        P = info.P
        dirs = np.stack([(uv[:, 0] - P[0, 2]) / P[0, 0], (uv[:, 1] - P[1, 2]) / P[1, 1],
                         np.ones(len(uv))], -1)
    table = np.ascontiguousarray(dirs.reshape(cam.height, cam.width, len(off), 3))
    table.setflags(write=False)
    _RAY_CACHE[key] = table
    while len(_RAY_CACHE) > 1 and sum(t.nbytes for t in _RAY_CACHE.values()) > _RAY_CACHE_BYTES:
        _RAY_CACHE.popitem(last=False)
    return table


def render_view(scene: Scene, dirs_cam: np.ndarray, T_world_from_cam: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Noise-free radiance (H, W) float32, depth ``z`` (H, W) float32 and labels (H, W) uint8.

    ``dirs_cam`` holds S sample rays per pixel, shape (H, W, S, 3), in the
    frame whose pose is ``T_world_from_cam``; the radiance is their mean, the
    depth and label belong to the first sample.
    """
    dirs = np.ascontiguousarray(dirs_cam, dtype=np.float64)
    if dirs.ndim != 4 or dirs.shape[3] != 3:
        raise ValueError(f"dirs_cam must have shape (H, W, S, 3), got {dirs.shape}")
    T = _checks.matrix("T_world_from_cam", T_world_from_cam, (4, 4))
    H, W = dirs.shape[:2]
    radiance = np.empty((H, W), np.float32)
    depth = np.empty((H, W), np.float32)
    labels = np.empty((H, W), np.uint8)
    p = scene.packed()
    _kernels.render_rays(dirs, np.ascontiguousarray(T[:3, :3]), np.ascontiguousarray(T[:3, 3]),
                         p["boxes"], p["box_material"], p["box_label"], p["cylinders"],
                         p["cylinder_material"], p["cylinder_label"], p["decals"], p["decal_material"],
                         p["decal_label"], p["materials"], p["lights"], float(scene.skirting_m),
                         int(scene.skirting_material), float(scene.ambient), int(scene.seed),
                         radiance, depth, labels)
    return radiance, depth, labels


def _to_uint8(radiance: np.ndarray, rng: np.random.Generator, sensor: SensorModel) -> np.ndarray:
    grey = radiance * (_EXPOSURE * sensor.gain) + rng.normal(0.0, sensor.noise_sigma, radiance.shape)
    if sensor.black_level:
        grey += sensor.black_level
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8)


def _check_free(scene: Scene, point: np.ndarray, what: str) -> None:
    """Raise if a camera centre lies inside a solid box or cylinder or outside the corridor."""
    p = scene.packed()
    b = p["boxes"]
    inside = np.all((point >= b[:, :3]) & (point <= b[:, 3:]), axis=1)
    c = p["cylinders"]
    in_cyl = (np.hypot(point[0] - c[:, 0], point[1] - c[:, 1]) <= c[:, 2]) & (point[2] <= c[:, 3])
    if inside.any() or in_cyl.any():
        raise ValueError(f"the {what} camera at ({point[0]:.2f}, {point[1]:.2f}, {point[2]:.2f}) m "
                         "is inside a solid object of the scene; choose another pose")


def render_stereo_frame(scene: Scene, stereo: StereoCamera, *, pose=(0.0, 0.0, 0.0), pan_rad: float = 0.0,
                        seed: int = 0, supersample: int = 2, mount: CameraMount | None = None,
                        sensors: tuple[SensorModel, SensorModel] = (SensorModel(), SensorModel())) -> StereoFrame:
    """Render raw and rectified stereo images of ``scene`` with ground truth.

    Parameters
    ----------
    scene : Scene
    stereo : StereoCamera
        True calibration of the rig; its ``mount`` places the head unless ``mount`` is given.
    pose : (x_m, y_m, yaw_rad)
        Robot pose in the world.
    pan_rad : float
        Head pan about the robot's z axis (positive to the left; the paper: 0 and +-45 degrees).
    seed : int
        Seed of the sensor noise.
    supersample : int
        Anti-aliasing: ``supersample x supersample`` rays per pixel.
    mount : CameraMount, optional
    sensors : (SensorModel, SensorModel)
        Left and right camera (default: equal cameras with :data:`sensor_noise_sigma`).

    Returns
    -------
    StereoFrame
        A raw pixel's ray is the raw camera's undistorted ray (inverse of eq. 3) rotated by ``R``;
        ground truth at the rectified left pixel centres, ``d = b f / Z - doffs`` (eq. 14).
    """
    _checks.instance("scene", scene, Scene)
    T_left, T_right = camera_poses(stereo, pose=pose, pan_rad=pan_rad, mount=mount)
    supersample = _checks.positive_int("supersample", supersample)
    if supersample > 8:
        raise ValueError(f"supersample must be <= 8, got {supersample}")
    seed = _checks.positive_int("seed", seed, minimum=0)
    if (not isinstance(sensors, (tuple, list)) or len(sensors) != 2
            or not all(isinstance(m, SensorModel) for m in sensors)):
        raise TypeError(f"sensors must be two SensorModel (left, right), got {sensors!r}")
    _check_free(scene, T_left[:3, 3], "left")
    _check_free(scene, T_right[:3, 3], "right")
    rngs = [np.random.default_rng(s) for s in np.random.SeedSequence([seed, 0x57E7E0]).spawn(4)]
    images = []
    for k, (info, T) in enumerate(((stereo.left, T_left), (stereo.right, T_right))):
        for raw in (True, False):
            rad, _, _ = render_view(scene, _ray_table(info, raw=raw, supersample=supersample), T)
            images.append(_to_uint8(rad, rngs[2 * k + int(raw)], sensors[k]))
    raw_left, left_rect, raw_right, right_rect = images
    _, depth, labels = render_view(scene, _ray_table(stereo.left, raw=False, supersample=1), T_left)
    with np.errstate(divide="ignore", invalid="ignore"):
        disparity = (stereo.focal_px * stereo.baseline_m / depth - stereo.doffs_px).astype(np.float32)
    disparity[~np.isfinite(depth)] = np.nan
    x, y, yaw = _pose(pose)
    return StereoFrame(raw_left=raw_left, raw_right=raw_right, left_rect=left_rect, right_rect=right_rect,
                       disparity_px=disparity, depth_m=depth, labels=labels, pose=(x, y, yaw),
                       pan_rad=float(pan_rad), T_world_from_cam=T_left)
