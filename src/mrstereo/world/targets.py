"""Rendered calibration targets with exact correspondences (paper Sec. 2, Fig. 2).

A planar target (``z = 0`` of its frame) placed at ``points_cam = R p + t`` in the raw left
camera, rendered with the true lens distortion (eq. 1-3), anti-aliasing and noise; ``points_px``
are the exact control points the calibration (eq. 4-8) fits. User guide: docs/world.md.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..calibration import planar_grid
from ..camera import Camera, CameraInfo, StereoCamera
from ..transforms import rotation_from_rpy
from .render import _ray_table, sensor_noise_sigma

__all__ = ["RenderedTarget", "render_calibration_views", "render_paper_dot_target", "target_points"]

_WHITE, _BLACK = 0.88, 0.07


@dataclass(frozen=True)
class RenderedTarget:
    """One rendered view of a planar target with its exact correspondences (docs/world.md).

    ``image`` (and ``image_right`` for a stereo pair, else None); ``points_target`` (N, 3) row-major
    ``(i * spacing, j * spacing, 0)``; ``points_px`` (and ``points_px_right``) their exact distorted
    pixels; ``R, t`` the pose in the left raw camera; ``target``, ``board``, ``spacing_m``.
    """

    image: np.ndarray
    image_right: np.ndarray | None
    points_target: np.ndarray
    points_px: np.ndarray
    points_px_right: np.ndarray | None
    R: np.ndarray
    t: np.ndarray
    target: str
    board: tuple[int, int]
    spacing_m: float


def target_points(board: tuple[int, int], spacing_m: float) -> np.ndarray:
    """Target-frame points (N, 3): ``(i * s, j * s, 0)`` for j rows, i columns, row-major
    (:func:`mrstereo.calibration.planar_grid`)."""
    try:
        nx, ny = board
    except (TypeError, ValueError):
        raise TypeError(f"board must be (columns, rows), got {board!r}") from None
    return planar_grid(nx, ny, spacing_m)


def _board_extent(target: str, board: tuple[int, int], s: float) -> tuple[float, float, float, float]:
    """Target-frame rectangle of the white paper (the pattern plus a white margin)."""
    nx, ny = board
    m = 2.0 * s if target == "chessboard" else 1.0 * s
    return -m, (nx - 1) * s + m, -m, (ny - 1) * s + m


def _pattern(target: str, board: tuple[int, int], s: float, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Reflectance at target-frame (x, y); background outside the paper."""
    x0, x1, y0, y1 = _board_extent(target, board, s)
    on_paper = (x >= x0) & (x <= x1) & (y >= y0) & (y <= y1)
    nx, ny = board
    if target == "chessboard":
        ix = np.floor(x / s)
        iy = np.floor(y / s)
        in_squares = (x >= -s) & (x <= nx * s) & (y >= -s) & (y <= ny * s)
        black = in_squares & ((ix + iy) % 2 == 0)
    else:
        r = 0.22 * s
        gx = np.clip(np.rint(x / s), 0, nx - 1) * s
        gy = np.clip(np.rint(y / s), 0, ny - 1) * s
        black = (x - gx) ** 2 + (y - gy) ** 2 <= r * r
    value = np.where(black, _BLACK, _WHITE)
    background = 0.35 + 0.1 * np.tanh(x) - 0.05 * np.tanh(y)
    return np.where(on_paper, value, background)


def _render_target(cam: Camera, target: str, board, s: float, R: np.ndarray, t: np.ndarray,
                   supersample: int, rng: np.random.Generator, noise_sigma: float) -> np.ndarray:
    """Ray-cast the target plane through the distorted camera (its own raw frame)."""
    dirs = _ray_table(CameraInfo(cam), raw=True, supersample=supersample)     # (H, W, S, 3), R = I
    n = R[:, 2]
    denom = dirs @ n
    with np.errstate(divide="ignore", invalid="ignore"):
        lam = (n @ t) / denom
        pts = lam[..., None] * dirs - t                # R p = lam d - t
    p = pts @ R                                        # p = R^T (lam d - t)
    hit = np.isfinite(lam) & (lam > 0)
    value = np.where(hit, _pattern(target, board, s, p[..., 0], p[..., 1]), 0.3)
    # Gentle illumination gradient across the image, then anti-aliasing.
    H, W = dirs.shape[:2]
    shade = 0.9 + 0.1 * np.linspace(-1, 1, W)[None, :] * np.linspace(1, 0.6, H)[:, None]
    grey = value.mean(axis=2) * shade * 255.0 + rng.normal(0.0, noise_sigma, (H, W))
    return np.clip(np.rint(grey), 0, 255).astype(np.uint8)


def _cameras(camera_or_stereo) -> tuple[Camera, Camera | None, np.ndarray | None, np.ndarray | None]:
    """(left raw camera, right raw camera, R_rr_from_lr, t_rr_from_lr)."""
    if isinstance(camera_or_stereo, Camera):
        return camera_or_stereo, None, None, None
    if isinstance(camera_or_stereo, CameraInfo):
        return camera_or_stereo.camera, None, None, None
    if isinstance(camera_or_stereo, StereoCamera):
        st = camera_or_stereo
        # p_rect_left = R_L p_lr; p_rect_right = p_rect_left - (b, 0, 0); p_rr = R_R^T p_rect_right.
        R = st.right.R.T @ st.left.R
        t = -st.right.R.T @ np.array([st.baseline_m, 0.0, 0.0])
        return st.left.camera, st.right.camera, R, t
    raise TypeError(f"camera_or_stereo must be a Camera, CameraInfo or StereoCamera, "
                    f"got {type(camera_or_stereo).__name__}")


def _right_offset_m(cams) -> float:
    """x of the right camera centre in the left raw frame (0 for a single camera)."""
    if cams[1] is None:
        return 0.0
    return float(-(cams[2].T @ cams[3])[0])


def _inside(cam: Camera, uv: np.ndarray, margin: float) -> bool:
    return bool(np.all(np.isfinite(uv)) and np.all(uv >= margin)
                and np.all(uv[:, 0] <= cam.width - 1 - margin) and np.all(uv[:, 1] <= cam.height - 1 - margin))


def _view(cams, target, board, s, R, t, supersample, rng, noise_sigma) -> RenderedTarget:
    left, right, R_rl, t_rl = cams
    pts = target_points(board, s)
    px = left.project(pts @ R.T + t)
    image = _render_target(left, target, board, s, R, t, supersample, rng, noise_sigma)
    image_r = px_r = None
    if right is not None:
        Rr, tr = R_rl @ R, R_rl @ t + t_rl
        px_r = right.project(pts @ Rr.T + tr)
        image_r = _render_target(right, target, board, s, Rr, tr, supersample, rng, noise_sigma)
    return RenderedTarget(image=image, image_right=image_r, points_target=pts, points_px=px,
                           points_px_right=px_r, R=R, t=t, target=target, board=tuple(board), spacing_m=s)


def _check_common(target, board, spacing_m, seed, supersample):
    if target not in ("chessboard", "dots"):
        raise ValueError(f"target must be 'chessboard' or 'dots', got {target!r}")
    try:
        nx, ny = (int(v) for v in board)
    except (TypeError, ValueError):
        raise ValueError(f"board must be (columns, rows) integers, got {board!r}") from None
    if nx < 2 or ny < 2:
        raise ValueError(f"board needs at least 2 x 2 points, got {board!r}")
    s = _checks.finite_number("spacing_m", spacing_m, positive=True)
    seed = _checks.positive_int("seed", seed, minimum=0)
    supersample = _checks.positive_int("supersample", supersample)
    return (nx, ny), s, seed, supersample


_COVERAGES = ("random", "grid")
# "grid" coverage: aim regions (x, y) in {-1, 0, 1}, corners first, then edges, then the centre, so
# that every 9 consecutive views cover the image. The corner distortion is extrapolated from the
# points nearest to it, so corner views push a small, tilted board as deep into the corner as a
# detector allows; large, strongly tilted boards elsewhere pin down the focal length.
_GRID_AIMS = ((-1, -1), (1, 1), (1, -1), (-1, 1), (0, -1), (0, 1), (-1, 0), (1, 0), (0, 0))
_GRID_CORNER_FILLS = (0.3, 0.25)      # quiet-zone outline width / image width, per pass over the regions
_GRID_MIN_SQUARE_PX = 8.0             # smallest projected square side (or dot pitch) anywhere on the board
_GRID_CORNER_TILT_RAD = 0.45
_GRID_FILLS = (0.95, 0.85)            # edges and centre
_GRID_TILTS_RAD = (0.7, 0.45)         # edges and centre: receding by 0.7 rad, then approaching by 0.45
_GRID_ROLL_RAD = 0.1
_GRID_QUIET_ZONE = 0.25
_GRID_BORDER_PX = 3.0


def _rect_outline(x0: float, x1: float, y0: float, y1: float) -> np.ndarray:
    """Corners and edge midpoints (8, 3) of a target-frame rectangle."""
    xm, ym = (x0 + x1) / 2, (y0 + y1) / 2
    return np.array([[x0, y0, 0], [x1, y0, 0], [x1, y1, 0], [x0, y1, 0], [xm, y0, 0], [xm, y1, 0], [x0, ym, 0],
                     [x1, ym, 0]])


def _outline(target, board, s) -> tuple[np.ndarray, np.ndarray]:
    """Paper outline points and the paper centre, target frame."""
    x0, x1, y0, y1 = _board_extent(target, board, s)
    return _rect_outline(x0, x1, y0, y1), np.array([(x0 + x1) / 2, (y0 + y1) / 2, 0.0])


def _grid_outline(target, board, s) -> np.ndarray:
    """What must stay inside the image for "grid": the pattern plus its quiet zone (chessboard), the paper (dots)."""
    if target != "chessboard":
        return _outline(target, board, s)[0]
    m = (1.0 + _GRID_QUIET_ZONE) * s
    return _rect_outline(-m, (board[0] - 1) * s + m, -m, (board[1] - 1) * s + m)


def _projections(cams, pts: np.ndarray) -> list[np.ndarray]:
    """Pixels of the left-raw-frame points ``pts`` in the left (and right) image."""
    if cams[1] is None:
        return [cams[0].project(pts)]
    return [cams[0].project(pts), cams[1].project(pts @ cams[2].T + cams[3])]


def _fits(cams, pts: np.ndarray, margin: float) -> bool:
    """Whether the left-raw-frame points ``pts`` project inside the left (and right) image."""
    return all(_inside(cam, uv, margin) for cam, uv in zip(cams, _projections(cams, pts)))


def _random_pose(cams, outline, centre, rng) -> tuple[np.ndarray, np.ndarray] | None:
    """A random pose: tilt up to about 35 degrees, 35-65 % of the image width, anywhere inside."""
    left = cams[0]
    width_m = outline[1, 0] - outline[0, 0]
    aim_x_m = _right_offset_m(cams) / 2    # aim between the cameras of a stereo pair
    for _attempt in range(500):
        angles = rng.uniform([-0.6, -0.6, -0.3], [0.6, 0.6, 0.3])
        R = rotation_from_rpy(*angles)
        fill = rng.uniform(0.35, 0.65)
        z = left.fx * width_m / (fill * left.width)
        off = rng.uniform(-0.5, 0.5, 2) * (1.0 - fill) * np.array([left.width / left.fx,
                                                                    left.height / left.fy])
        t = np.array([aim_x_m + off[0] * z, off[1] * z, z]) - R @ centre
        if _fits(cams, outline @ R.T + t, 6.0):
            return R, t
    return None


def _min_square_px(cams, points: np.ndarray, board) -> float:
    """Smallest projected distance between neighbouring pattern points, left (and right) image."""
    nx, ny = board
    smallest = np.inf
    for uv in _projections(cams, points):
        grid = uv.reshape(ny, nx, 2)
        smallest = min(smallest, np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
                       np.linalg.norm(np.diff(grid, axis=1), axis=-1).min())
    return float(smallest)


def _grid_pose(cams, outline, centre, pattern, board, k, rng) -> tuple[np.ndarray, np.ndarray] | None:
    """Pose ``k`` of the "grid" coverage: the board pushed into aim region ``k mod 9``.

    Corner regions tilt the board so its corner approaches the camera (``_GRID_CORNER_TILT_RAD``,
    ``_GRID_CORNER_FILLS``); edges and centre tilt by ``_GRID_TILTS_RAD`` (``_GRID_FILLS``); then the
    board is shifted until its ``outline`` touches the region's image border(s), moved away while it
    does not fit, and brought closer or tilted less while a square is under ``_GRID_MIN_SQUARE_PX``.
    """
    left = cams[0]
    width_m = outline[1, 0] - outline[0, 0]
    ax, ay = _GRID_AIMS[k % len(_GRID_AIMS)]
    npass = k // len(_GRID_AIMS)
    corner = ax != 0 and ay != 0
    if corner:
        sign, tilt_rad, fill = -1.0, _GRID_CORNER_TILT_RAD, _GRID_CORNER_FILLS[npass % len(_GRID_CORNER_FILLS)]
    else:
        sign = 1.0 if npass % 2 == 0 else -1.0
        tilt_rad = _GRID_TILTS_RAD[npass % len(_GRID_TILTS_RAD)]
        fill = _GRID_FILLS[npass % len(_GRID_FILLS)]
    border = _GRID_BORDER_PX
    for _attempt in range(200):
        jitter = rng.uniform(-0.1, 0.1, 2)
        if ax == 0 and ay == 0:          # centre: tilt in a random direction
            direction = rng.uniform(-1.0, 1.0, 2)
            tilt = tilt_rad * direction / max(float(np.linalg.norm(direction)), 1e-9)
        else:
            tilt = sign * tilt_rad * np.array([ax, ay], dtype=float)
        # Rx(alpha > 0) turns the board's +y (lower) edge away from the camera, Ry(beta < 0) its +x edge.
        R = rotation_from_rpy(tilt[1] + jitter[0], -tilt[0] + jitter[1], rng.uniform(-1, 1) * _GRID_ROLL_RAD)
        z = left.fx * width_m / (fill * left.width)
        t = np.array([_right_offset_m(cams) / 2, 0.0, z]) - R @ centre
        for _ in range(30):              # shift the board (Newton-like, in pixels) against the border(s)
            pts = outline @ R.T + t
            uv = np.concatenate(_projections(cams, pts))
            if not np.all(np.isfinite(uv)):
                break
            shift = np.zeros(2)
            for axis, aim, size in ((0, ax, left.width), (1, ay, left.height)):
                lo, hi = uv[:, axis].min(), uv[:, axis].max()
                shift[axis] = (border - lo if aim < 0 else size - 1 - border - hi if aim > 0
                               else (size - 1) / 2 - (lo + hi) / 2)
            depth_m = float((R @ centre + t)[2])
            t[:2] += shift * depth_m / np.array([left.fx, left.fy])
            if np.all(np.abs(shift) < 0.05):
                break
        if not _fits(cams, outline @ R.T + t, border - 1.0):
            fill *= 0.97
        elif _min_square_px(cams, pattern @ R.T + t, board) < _GRID_MIN_SQUARE_PX:
            if corner:
                fill *= 1.03
            else:
                tilt_rad *= 0.95
        else:
            return R, t
    return None


def render_calibration_views(camera_or_stereo, *, target: str = "chessboard", board=(9, 6),
                             spacing_m: float = 0.03, n_views: int = 10, seed: int = 0,
                             supersample: int = 4, noise_sigma: float = sensor_noise_sigma,
                             coverage: str = "random") -> list[RenderedTarget]:
    """Render ``n_views`` poses of a planar target with exact correspondences.

    Parameters
    ----------
    camera_or_stereo : Camera, CameraInfo or StereoCamera
        True raw camera(s); a stereo pair renders left and right images of each pose.
    target : {"chessboard", "dots"}
    board : (int, int)
        Inner corners (chessboard) or dots per row and column, e.g. (9, 6).
    spacing_m : float
        Square size or dot pitch in metres.
    n_views : int
    seed : int
        Seed of the poses and the sensor noise.
    supersample : int
        Anti-aliasing rays per pixel along each axis.
    noise_sigma : float
        Sensor noise, grey levels.
    coverage : {"random", "grid"}
        ``"random"``: tilts up to about 35 degrees, the paper filling 35-65 % of the image width,
        anywhere. ``"grid"``: what calibration guides ask of a user, view ``k`` pushing the board into
        one of nine regions (corners, edges, centre) until it touches the border there, squares of
        8 px at least; take 18 views or more (docs/calibration.md, Measured).

    Returns
    -------
    list of RenderedTarget
        Deterministic for a seed; the paper (``"random"``, 6 px margin) or the pattern and its quiet
        zone (``"grid"``, 3 px) inside every image. RuntimeError when the board cannot be placed.
    """
    board, s, seed, supersample = _check_common(target, board, spacing_m, seed, supersample)
    n_views = _checks.positive_int("n_views", n_views)
    noise_sigma = _checks.finite_number("noise_sigma", noise_sigma, nonnegative=True)
    if coverage not in _COVERAGES:
        raise ValueError(f"coverage must be 'random' or 'grid', got {coverage!r}")
    cams = _cameras(camera_or_stereo)
    rng = np.random.default_rng(seed)
    outline, centre = _outline(target, board, s)
    views = []
    for k in range(n_views):
        if coverage == "random":
            pose = _random_pose(cams, outline, centre, rng)
        else:
            pose = _grid_pose(cams, _grid_outline(target, board, s), centre, target_points(board, s), board, k, rng)
        if pose is None:
            raise RuntimeError(f"could not place view {k} of the target inside the image(s); "
                               "use a smaller board or spacing_m")
        views.append(_view(cams, target, board, s, *pose, supersample, rng, noise_sigma))
    return views


def render_paper_dot_target(camera_or_stereo, *, grid=(15, 11), distance_m: float = 1.0, seed: int = 0,
                            supersample: int = 4, noise_sigma: float = sensor_noise_sigma) -> RenderedTarget:
    """One fronto-parallel view of a dot grid filling most of the image (paper Fig. 2), whose
    corners show the radial distortion (eq. 3) most.

    Parameters
    ----------
    camera_or_stereo : Camera, CameraInfo or StereoCamera
    grid : (int, int)
        Dots per row and column.
    distance_m : float
        Distance of the target plane from the left camera.
    seed, supersample, noise_sigma
        As in :func:`render_calibration_views`.
    """
    board, _, seed, supersample = _check_common("dots", grid, 1.0, seed, supersample)
    z = _checks.finite_number("distance_m", distance_m, positive=True)
    noise_sigma = _checks.finite_number("noise_sigma", noise_sigma, nonnegative=True)
    cams = _cameras(camera_or_stereo)
    left = cams[0]
    nx, ny = board
    span = 0.94 if cams[1] is None else 0.86
    s = min(span * (left.width / left.fx) * z / (nx - 1), span * (left.height / left.fy) * z / (ny - 1))
    R = np.eye(3)
    centre = np.array([(nx - 1) * s / 2, (ny - 1) * s / 2, 0.0])
    t = np.array([((left.width - 1) / 2 - left.cx) / left.fx * z + _right_offset_m(cams) / 2,
                  ((left.height - 1) / 2 - left.cy) / left.fy * z, z]) - centre
    rng = np.random.default_rng(seed)
    return _view(cams, "dots", board, s, R, t, supersample, rng, noise_sigma)
