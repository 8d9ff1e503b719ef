"""Calibration targets: planar grids, chessboard detection, control-point files.

A :class:`CalibrationView` holds the known 3D target points (metres, target
frame) and their detected pixel positions in one image -- the control points of
paper section 2.1. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import csv
import glob as _glob
import io as _io
import os
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from .. import _checks
from ..io import read_image, read_text
from ..transforms import T_from_R_t, rotation_from_rpy

__all__ = ["CalibrationView", "planar_grid", "parse_board", "detect_chessboard", "chessboard_views",
           "read_control_points", "expand_glob", "synthetic_view", "pose_looking_at", "ChessboardPairs",
           "chessboard_pairs", "agree_with_left"]

_UNITS_M = {"m": 1.0, "mm": 1e-3}


@dataclass(frozen=True)
class CalibrationView:
    """Control points of one image: target points and their pixels.

    Attributes
    ----------
    points_target : ndarray of shape (N, 3)
        Known target points in metres (a planar target has Z = 0).
    uv : ndarray of shape (N, 2)
        Measured pixel positions (distorted, raw image).
    name : str
        Where the view came from (file name).
    """

    points_target: np.ndarray
    uv: np.ndarray
    name: str = "view"

    def __post_init__(self) -> None:
        p = _checks.points3("points_target", self.points_target)
        uv = np.asarray(self.uv, dtype=np.float64)
        if uv.ndim != 2 or uv.shape[1] != 2 or len(uv) != len(p):
            raise ValueError(f"uv must have shape ({len(p)}, 2) to match points_target, got {uv.shape}")
        if len(p) < 6:
            raise ValueError(f"a calibration view needs at least 6 control points, got {len(p)}")
        if not (np.isfinite(p).all() and np.isfinite(uv).all()):
            raise ValueError(f"view {self.name}: control points contain NaN or inf")
        object.__setattr__(self, "points_target", p)
        object.__setattr__(self, "uv", uv)

    @property
    def is_planar(self) -> bool:
        """True when every target point has Z = 0 (what Zhang's method needs)."""
        return bool(np.all(self.points_target[:, 2] == 0.0))


def planar_grid(cols: int, rows: int, spacing_m: float) -> np.ndarray:
    """Target points of a ``cols x rows`` grid on Z = 0, row-major (x fastest), metres.

    This is the order ``cv2.findChessboardCorners`` returns for ``(cols, rows)``.
    """
    cols = _checks.positive_int("cols", cols, minimum=2)
    rows = _checks.positive_int("rows", rows, minimum=2)
    spacing_m = _checks.finite_number("spacing_m", spacing_m, positive=True)
    _checks.fits_in_memory("cols and rows", 72.0 * cols * rows, f"a grid of {cols} x {rows} points")
    x, y = np.meshgrid(np.arange(cols, dtype=np.float64), np.arange(rows, dtype=np.float64))
    return np.stack([x.ravel() * spacing_m, y.ravel() * spacing_m, np.zeros(x.size)], axis=1)


MAX_BOARD_CORNERS = 200
"""The most inner corners per side of a chessboard (the largest printed targets have a few dozen)."""


def parse_board(text: str) -> tuple[int, int]:
    """Parse ``"9x6"`` (inner corners, columns x rows)."""
    parts = str(text).lower().replace(" ", "").split("x")
    try:
        cols, rows = (int(p) for p in parts)
    except ValueError:
        raise ValueError(f"board must look like 9x6 (inner corners), got {text!r}") from None
    if not (2 <= cols <= MAX_BOARD_CORNERS and 2 <= rows <= MAX_BOARD_CORNERS):
        raise ValueError(f"board needs 2 to {MAX_BOARD_CORNERS} inner corners per side, got {text!r}")
    return cols, rows


def detect_chessboard(image: np.ndarray, board: tuple[int, int]) -> np.ndarray | None:
    """Inner chessboard corners (N, 2) refined to subpixel, or None if not found.

    ``cv2.findChessboardCorners`` (adaptive threshold + normalization) followed
    by ``cv2.cornerSubPix`` (half window 11 px, less for small squares). The half-turn ambiguity of the
    board is resolved by numbering from the corner nearest the image's top-left
    (first-to-last corner pointing right/down), so stereo pairs agree.
    """
    gray = _checks.image("image", image)
    if gray.ndim == 3:
        gray = cv2.cvtColor(np.ascontiguousarray(gray[:, :, :3]).astype(np.uint8), cv2.COLOR_BGR2GRAY)
    gray = np.ascontiguousarray(gray, dtype=np.uint8)
    cols, rows = board
    flags = cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE
    found, corners = cv2.findChessboardCorners(gray, (cols, rows), flags=flags)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-3)
    grid = corners.reshape(rows, cols, 2)
    spacing = min(np.linalg.norm(np.diff(grid, axis=0), axis=-1).min(),
                  np.linalg.norm(np.diff(grid, axis=1), axis=-1).min())
    win = int(max(2, min(11, 0.4 * spacing)))   # the window must stay inside one square
    corners = cv2.cornerSubPix(gray, corners, (win, win), (-1, -1), criteria).reshape(-1, 2).astype(np.float64)
    # a board is symmetric under a half turn: number it from the corner nearest the
    # top-left of the image so that both images of a stereo pair agree
    d = corners[-1] - corners[0]
    return corners[::-1].copy() if d[0] + d[1] < 0 else corners


def expand_glob(pattern: str, what: str = "images") -> list[Path]:
    """Sorted files matching a glob pattern; ``ValueError`` if none match."""
    paths = sorted(Path(p) for p in _glob.glob(os.path.expanduser(str(pattern))) if Path(p).is_file())
    if not paths:
        raise ValueError(f"no {what} match {pattern!r}")
    return paths


def chessboard_views(paths, board: tuple[int, int], square_m: float
                     ) -> tuple[list[CalibrationView | None], tuple[int, int]]:
    """Detect the board in every image.

    Returns one entry per path (None where the board was not found) and the
    common image size ``(width, height)``; raises ``ValueError`` if the sizes
    differ or the board is found in no image.
    """
    square_m = _checks.finite_number("square_m", square_m, positive=True)
    grid = planar_grid(board[0], board[1], square_m)
    views, size = [], None
    for path in paths:
        img = read_image(path, gray=True)
        this = (img.shape[1], img.shape[0])
        if size is None:
            size = this
        elif this != size:
            raise ValueError(f"image {path} is {this[0]}x{this[1]}, the others {size[0]}x{size[1]}")
        corners = detect_chessboard(img, board)
        views.append(None if corners is None else CalibrationView(grid, corners, name=Path(path).name))
    if all(v is None for v in views):
        raise ValueError(f"the {board[0]}x{board[1]} chessboard was not found in any of {len(views)} images")
    return views, size


def agree_with_left(left: CalibrationView, right: CalibrationView) -> CalibrationView:
    """Undo a half-turn renumbering of a point-symmetric target (a chessboard) in the right view.

    Reversing the point order of a grid turns it by 180 degrees about its centre, so detectors may
    number the two images of one pair from opposite corners (a board near 45 degrees). When the
    target is symmetric that way and the right first-to-last direction opposes the left one, the
    right order is reversed.
    """
    p = left.points_target
    symmetric = np.allclose(p[::-1], 2.0 * p.mean(axis=0) - p, atol=1e-9)
    if symmetric and float(np.dot(left.uv[-1] - left.uv[0], right.uv[-1] - right.uv[0])) < 0:
        return CalibrationView(right.points_target, right.uv[::-1].copy(), name=right.name)
    return right


@dataclass(frozen=True)
class ChessboardPairs:
    """Chessboard views of a stereo image set, matched by sorted order.

    ``left[i]`` and ``right[i]`` show the same board pose with the corners in the
    same order; ``skipped`` names the pairs where either board was not found.
    """

    left: list
    right: list
    skipped: list
    size: tuple


def chessboard_pairs(left_paths, right_paths, board: tuple[int, int], square_m: float) -> ChessboardPairs:
    """Detect the board in both images of every pair (paths matched by position), numbered alike
    (:func:`agree_with_left`)."""
    left_paths, right_paths = list(left_paths), list(right_paths)
    if len(left_paths) != len(right_paths):
        raise ValueError(f"{len(left_paths)} left images but {len(right_paths)} right images; pairs are "
                         "matched by sorted order and must be equal in number")
    lv, size_l = chessboard_views(left_paths, board, square_m)
    rv, size_r = chessboard_views(right_paths, board, square_m)
    if size_l != size_r:
        raise ValueError(f"left images are {size_l[0]}x{size_l[1]}, right images {size_r[0]}x{size_r[1]}")
    left, right, skipped = [], [], []
    for a, b, pa, pb in zip(lv, rv, left_paths, right_paths):
        if a is None or b is None:
            skipped.append(f"{Path(pa).name}/{Path(pb).name}")
            continue
        left.append(a)
        right.append(agree_with_left(a, b))
    return ChessboardPairs(left=left, right=right, skipped=skipped, size=size_l)


def read_control_points(path: str | os.PathLike, *, units: str | None = None) -> CalibrationView:
    """Read a control-point CSV (paper section 2.1): columns X, Y, Z, u, v with a header.

    Target coordinates are in metres unless the file declares ``# units: mm``
    in a leading comment line or ``units="mm"`` is passed (an explicit argument
    wins). Pixels are raw image coordinates.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"control point file not found: {path}")
    text = read_text(path, "control points file")
    declared = None
    body = []
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("#"):
            low = stripped[1:].strip().lower()
            if low.startswith("units"):
                declared = low.split(":", 1)[-1].split("=", 1)[-1].strip()
            continue
        if stripped:
            body.append(line)
    unit = units if units is not None else (declared or "m")
    if unit not in _UNITS_M:
        raise ValueError(f"units must be 'm' or 'mm', got {unit!r}")
    reader = csv.DictReader(_io.StringIO("\n".join(body)))
    fields = [f.strip() for f in (reader.fieldnames or [])]
    need = ["X", "Y", "Z", "u", "v"]
    if any(n not in fields for n in need):
        raise ValueError(f"{path}: header must name the columns X, Y, Z, u, v; got {fields}")
    rows = []
    for i, row in enumerate(reader, start=2):
        row = {k.strip(): v for k, v in row.items() if k is not None}
        try:
            rows.append([float(row[n]) for n in need])
        except (TypeError, ValueError):
            raise ValueError(f"{path}: data line {i} is not numeric: {row}") from None
    if not rows:
        raise ValueError(f"{path}: no control points")
    arr = np.asarray(rows)
    return CalibrationView(arr[:, :3] * _UNITS_M[unit], arr[:, 3:], name=path.name)


def pose_looking_at(centre_target, *, distance_m: float, tilt_x_rad: float = 0.0, tilt_y_rad: float = 0.0,
                    roll_rad: float = 0.0, offset_px=(0.0, 0.0), focal_px: float = 1.0) -> np.ndarray:
    """4x4 ``T_cam_from_target`` of a camera ``distance_m`` in front of a target point.

    The target (Z axis pointing away from the camera) is tilted about its x and y
    axes and rolled about the optical axis; ``offset_px`` shifts the target
    point off the image centre (in pixels for ``focal_px``).
    """
    R = rotation_from_rpy(tilt_x_rad, tilt_y_rad, roll_rad)
    c = np.asarray(centre_target, dtype=np.float64)
    pos = np.array([offset_px[0] / focal_px * distance_m, offset_px[1] / focal_px * distance_m, distance_m])
    return T_from_R_t(R, pos - R @ c)


def synthetic_view(camera, points_target, T_cam_from_target, *, noise_px: float = 0.0, rng=None,
                   name: str = "synthetic") -> CalibrationView:
    """Project target points through a known camera and pose (+ Gaussian pixel noise)."""
    p = _checks.points3("points_target", points_target)
    T = _checks.matrix("T_cam_from_target", T_cam_from_target, (4, 4))
    uv = camera.project(p @ T[:3, :3].T + T[:3, 3])
    if noise_px > 0:
        uv = uv + np.random.default_rng(rng).normal(0.0, noise_px, uv.shape)
    return CalibrationView(p, uv, name=name)
