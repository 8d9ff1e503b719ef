"""Top view (paper Figs 8b-10b) and a virtual laser scan of the obstacle points.

* :func:`top_view` bins robot-frame points into a 2D histogram laid out like a
  ``GridSpec`` of the mapping stage (x forward = depth, y lateral): the
  paper's "top view of the depth-by-column projection".
* :func:`laser_scan_from_points` keeps, for each bearing, the nearest obstacle
  in the robot frame, like ROS ``depthimage_to_laserscan`` /
  ``pointcloud_to_laserscan``: angle 0 straight ahead, positive to the left
  (REP 103), ``ranges[i]`` at ``angle_min + i * angle_increment``; no return =
  NaN here, ``null`` in JSON, empty in CSV.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass

import numpy as np

from .. import _checks
from ..camera import StereoCamera
from ..io import atomic_write

__all__ = [
    "LaserScan", "laser_scan_from_points", "scan_angles_of_camera", "top_view", "write_scan_json",
    "read_scan_json", "write_scan_csv", "plot_top_view",
]


@dataclass(frozen=True)
class LaserScan:
    """A planar scan in the robot frame (the fields of ROS ``sensor_msgs/LaserScan``).

    ``ranges_m[i]`` is the range at ``angle_min_rad + i * angle_increment_rad``,
    NaN where there is no return; ``angle_max_rad`` is the angle of the last ray.
    """

    angle_min_rad: float
    angle_max_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    ranges_m: np.ndarray

    @property
    def angles_rad(self) -> np.ndarray:
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.ranges_m.size)

    def points_robot(self) -> np.ndarray:
        """The returns as (N, 2) robot-frame (x, y) points."""
        ok = np.isfinite(self.ranges_m)
        a, r = self.angles_rad[ok], self.ranges_m[ok]
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)

    def to_dict(self) -> dict:
        """ROS LaserScan field names; ranges without return are None (JSON null)."""
        return {
            "angle_min": float(self.angle_min_rad), "angle_max": float(self.angle_max_rad),
            "angle_increment": float(self.angle_increment_rad), "range_min": float(self.range_min_m),
            "range_max": float(self.range_max_m),
            "ranges": [float(r) if np.isfinite(r) else None for r in self.ranges_m],
        }

    @classmethod
    def from_dict(cls, data) -> LaserScan:
        keys = ("angle_min", "angle_max", "angle_increment", "range_min", "range_max", "ranges")
        if not isinstance(data, dict) or any(k not in data for k in keys):
            raise ValueError(f"laser scan must have the fields {', '.join(keys)}")
        ranges = np.array([np.nan if r is None else float(r) for r in data["ranges"]], dtype=np.float64)
        return cls(angle_min_rad=float(data["angle_min"]), angle_max_rad=float(data["angle_max"]),
                   angle_increment_rad=float(data["angle_increment"]), range_min_m=float(data["range_min"]),
                   range_max_m=float(data["range_max"]), ranges_m=ranges)


def scan_angles_of_camera(stereo: StereoCamera, *, pan_rad: float = 0.0) -> tuple[float, float]:
    """Bearings ``(angle_min_rad, angle_max_rad)`` covered by the rectified left image.

    The right image edge (``u = W - 1``) looks to the right (negative angle),
    the left edge (``u = 0``) to the left; the pan turns both.
    """
    if not isinstance(stereo, StereoCamera):
        raise TypeError(f"stereo must be a StereoCamera, got {type(stereo).__name__}")
    pan = _checks.finite_number("pan_rad", pan_rad)
    f, cx, w = stereo.focal_px, stereo.cx_px, stereo.size[0]
    return pan - math.atan2(w - 1 - cx, f), pan + math.atan2(cx, f)


def laser_scan_from_points(points_robot, *, angle_min_rad: float = -math.pi / 4,
                           angle_max_rad: float = math.pi / 4,
                           angle_increment_rad: float = math.radians(0.5), range_min_m: float = 0.1,
                           range_max_m: float = 10.0, min_points: int = 1) -> LaserScan:
    """Nearest obstacle per bearing, like ``depthimage_to_laserscan``.

    Parameters
    ----------
    points_robot : ndarray of shape (N, 3) or (N, 2)
        Obstacle points in the robot frame (only x and y are used; the caller
        selects the height band, e.g. :attr:`ObstacleResult.obstacle_points_robot`).
    angle_min_rad, angle_max_rad : float
        First and last bearing (0 straight ahead, positive left).
    angle_increment_rad : float
        Bearing step; the last ray is at ``angle_min + (n - 1) * increment <= angle_max``.
    range_min_m, range_max_m : float
        Returns outside ``[range_min, range_max]`` are ignored.
    min_points : int
        The range of a ray is that of its ``min_points``-th nearest point (1 =
        the nearest, as ``depthimage_to_laserscan``); a larger value ignores up
        to ``min_points - 1`` stray points in front of the obstacle, and rays
        with fewer points report no return.

    Returns
    -------
    LaserScan
        ``ranges_m`` NaN where no point falls in the bearing's bin
        (bin = nearest ray, half an increment each side).
    """
    p = np.asarray(points_robot, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise ValueError(f"points_robot must have shape (N, 3) or (N, 2), got {p.shape}")
    a0 = _checks.finite_number("angle_min_rad", angle_min_rad)
    a1 = _checks.finite_number("angle_max_rad", angle_max_rad)
    inc = _checks.finite_number("angle_increment_rad", angle_increment_rad, positive=True)
    r0 = _checks.finite_number("range_min_m", range_min_m, nonnegative=True)
    r1 = _checks.finite_number("range_max_m", range_max_m, positive=True)
    if a1 <= a0:
        raise ValueError(f"angle_max_rad ({a1}) must exceed angle_min_rad ({a0})")
    if r1 <= r0:
        raise ValueError(f"range_max_m ({r1}) must exceed range_min_m ({r0})")
    n_float = math.floor((a1 - a0) / inc + 1e-9) + 1
    _checks.fits_in_memory("angle_increment_rad", n_float * 40.0, f"a scan of {n_float:.4g} rays")
    n = int(n_float)
    p = p[np.isfinite(p[:, :2]).all(axis=1)]
    r = np.hypot(p[:, 0], p[:, 1])
    k = np.rint((np.arctan2(p[:, 1], p[:, 0]) - a0) / inc).astype(np.int64)
    m = _checks.positive_int("min_points", min_points)
    keep = (r >= r0) & (r <= r1) & (k >= 0) & (k < n)
    k, r = k[keep], r[keep]
    ranges = np.full(n, np.nan)
    if m == 1:
        ranges_inf = np.full(n, np.inf)
        np.minimum.at(ranges_inf, k, r)
        ranges = np.where(np.isfinite(ranges_inf), ranges_inf, np.nan)
    elif k.size:
        order = np.lexsort((r, k))                 # by ray, then by range
        k, r = k[order], r[order]
        first = np.searchsorted(k, np.arange(n))   # index of each ray's nearest point
        count = np.bincount(k, minlength=n)
        has = count >= m
        ranges[has] = r[first[has] + m - 1]
    return LaserScan(angle_min_rad=a0, angle_max_rad=a0 + (n - 1) * inc, angle_increment_rad=inc,
                     range_min_m=r0, range_max_m=r1, ranges_m=ranges)


def top_view(points_robot, *, x_range_m: tuple[float, float] = (0.0, 8.0),
             y_range_m: tuple[float, float] = (-3.0, 3.0), resolution_m: float = 0.05) -> np.ndarray:
    """Histogram of points over a robot-frame grid (the paper's top view, Figs 8b-10b).

    The cells follow :class:`mrstereo.mapping.grid.GridSpec` (row 0 at the
    lowest y, column 0 at the lowest x, lower-left corner at
    ``(x_range_m[0], y_range_m[0])``), so the result can be laid on a map.

    Returns
    -------
    ndarray of shape (rows, cols), int32
        ``counts[row, col]``: row along y (lateral, row 0 = rightmost),
        column along x (forward / depth).
    """
    p = _checks.points3("points_robot", points_robot)
    res = _checks.finite_number("resolution_m", resolution_m, positive=True)
    (x0, x1), (y0, y1) = (_checks.ordered_pair("x_range_m", x_range_m), _checks.ordered_pair("y_range_m", y_range_m))
    rows, cols = int(round((y1 - y0) / res)), int(round((x1 - x0) / res))
    p = p[np.isfinite(p).all(axis=1)]
    col = np.floor((p[:, 0] - x0) / res).astype(np.int64)
    row = np.floor((p[:, 1] - y0) / res).astype(np.int64)
    inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
    counts = np.bincount(row[inside] * cols + col[inside], minlength=rows * cols)
    return counts.reshape(rows, cols).astype(np.int32)


def write_scan_json(path: str | os.PathLike, scan: LaserScan) -> None:
    """Write a scan as JSON with the ROS LaserScan field names (null = no return)."""
    with atomic_write(path) as tmp:
        tmp.write_text(json.dumps(scan.to_dict(), indent=1) + "\n")


def read_scan_json(path: str | os.PathLike) -> LaserScan:
    """Read a scan written by :func:`write_scan_json`."""
    try:
        data = json.loads(open(path, encoding="utf-8").read())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not a JSON laser scan ({exc})") from None
    return LaserScan.from_dict(data)


def write_scan_csv(path: str | os.PathLike, scan: LaserScan) -> None:
    """Write a scan as CSV ``angle_rad,range_m`` (empty range = no return)."""
    with atomic_write(path) as tmp, open(tmp, "w", newline="") as fh:
        out = csv.writer(fh)
        out.writerow(["angle_rad", "range_m"])
        for a, r in zip(scan.angles_rad, scan.ranges_m):
            out.writerow([f"{a:.6f}", f"{r:.4f}" if np.isfinite(r) else ""])


def plot_top_view(path: str | os.PathLike, *, obstacle_points_robot=None, floor_points_robot=None,
                  scan: LaserScan | None = None, x_range_m: tuple[float, float] = (0.0, 8.0),
                  y_range_m: tuple[float, float] = (-3.0, 3.0), title: str = "top view") -> None:
    """PNG of the top view: floor points, obstacle points and the scan (matplotlib Agg).

    Drawn as the paper's figures: depth upward, the robot at the bottom centre,
    what is on the robot's left on the figure's left. The horizontal axis is the
    robot-frame y (REP 103: left is +y), so its ticks run from +y on the left to
    -y on the right and an obstacle at y = +1 m is drawn 1 m left of the robot.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from matplotlib.lines import Line2D

    fig, ax = plt.subplots(figsize=(6, 7), dpi=100)
    handles = []
    try:
        for pts, colour, label, size in ((floor_points_robot, "#60b060", "floor", 0.5),
                                         (obstacle_points_robot, "#c03020", "obstacle", 0.6)):
            if pts is not None:
                p = _checks.points3(label + "_points_robot", pts)
                if p.shape[0] > 60000:           # a plot does not need every point
                    p = p[:: int(math.ceil(p.shape[0] / 60000))]
                ax.scatter(p[:, 1], p[:, 0], s=size, c=colour, linewidths=0)
                handles.append(Line2D([], [], ls="", marker="o", ms=4, color=colour,
                                      label=f"{label} points ({len(pts)})"))
        if scan is not None:
            xy = scan.points_robot()
            ax.plot(xy[:, 1], xy[:, 0], ".", color="#1040c0", ms=3)
            handles.append(Line2D([], [], ls="", marker=".", ms=8, color="#1040c0",
                                  label=f"laser scan ({len(xy)} returns)"))
            for a in (scan.angle_min_rad, scan.angle_max_rad):
                ax.plot([0, scan.range_max_m * math.sin(a)], [0, scan.range_max_m * math.cos(a)],
                        "--", color="0.6", lw=0.8)
        ax.plot([0], [0], "k^", ms=9)
        handles.append(Line2D([], [], ls="", marker="^", ms=7, color="k", label="robot"))
        ax.set_xlim(y_range_m[1], y_range_m[0])       # +y (the robot's left) on the left
        ax.set_ylim(*x_range_m)
        ax.set_aspect("equal")
        ax.set_xlabel("y [m] (left +, right -)")
        ax.set_ylabel("x [m] (forward)")
        ax.set_title(title)
        ax.grid(True, lw=0.3)
        ax.legend(handles=handles, loc="upper right", fontsize=8)
        with atomic_write(path) as tmp:
            fig.savefig(tmp, format="png")
    finally:
        plt.close(fig)
