"""Top view (paper Figs 8b-10b) and a virtual laser scan of the obstacle points.

:func:`top_view` bins robot-frame points on a grid laid out like the mapping stage's ``GridSpec``;
:func:`laser_scan_from_points` keeps the nearest obstacle per bearing, like ROS
``depthimage_to_laserscan``, with the values of REP 117 (:class:`LaserScan`). Files:
docs/obstacles.md (Laser scan files). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from ..camera import StereoCamera
from ..io import atomic_write
from . import _scan_kernels

__all__ = [
    "LaserScan", "laser_scan_from_points", "near_limit_range_m", "scan_angles_of_camera", "top_view",
    "write_scan_json",
    "read_scan_json", "write_scan_csv", "plot_top_view",
]


_SPECIAL_JSON = {"NaN": math.nan, "Infinity": math.inf, "-Infinity": -math.inf}


def _json_float(value: float):
    """A float for JSON: finite numbers as numbers, the others as the proto3 JSON strings."""
    value = float(value)
    if math.isfinite(value):
        return value
    return "NaN" if math.isnan(value) else ("Infinity" if value > 0 else "-Infinity")


def _from_json_float(value, what: str) -> float:
    if value is None:                       # how other JSON writers store NaN: no measurement
        return math.nan
    if isinstance(value, str):
        if value not in _SPECIAL_JSON:
            raise ValueError(f"{what} must be a number, 'NaN', 'Infinity' or '-Infinity', got {value!r}")
        return _SPECIAL_JSON[value]
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{what} must be a number, got {value!r}")
    return float(value)


@dataclass(frozen=True)
class LaserScan:
    """A planar scan in the robot frame: the fields of ROS ``sensor_msgs/LaserScan``.

    ``ranges_m[i]`` at ``angle_min_rad + i * angle_increment_rad``, with REP 117's values: a finite
    range, ``+inf`` seen clear up to ``range_max_m``, ``nan`` no measurement, ``-inf`` nearer than
    ``range_min_m``. ``intensities`` is empty or one gray level per ray; a stereo scan is
    instantaneous (``time_increment_s = 0``).
    """

    angle_min_rad: float
    angle_max_rad: float
    angle_increment_rad: float
    range_min_m: float
    range_max_m: float
    ranges_m: np.ndarray
    intensities: np.ndarray = field(default_factory=lambda: np.empty(0))
    frame_id: str = "base_link"
    stamp_s: float = 0.0
    time_increment_s: float = 0.0
    scan_time_s: float = 0.0

    @property
    def angles_rad(self) -> np.ndarray:
        return self.angle_min_rad + self.angle_increment_rad * np.arange(self.ranges_m.size)

    def points_robot(self) -> np.ndarray:
        """The returns (finite ranges) as (N, 2) robot-frame (x, y) points."""
        ok = np.isfinite(self.ranges_m)
        a, r = self.angles_rad[ok], self.ranges_m[ok]
        return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)

    def to_dict(self) -> dict:
        """The message as JSON-ready data: ``sensor_msgs/LaserScan`` field names (ROS 2 header),
        non-finite values as the proto3 JSON strings ``"NaN"``, ``"Infinity"``, ``"-Infinity"``
        (``float(s)`` reads them back)."""
        sec = math.floor(self.stamp_s)
        nanosec = min(int(round((self.stamp_s - sec) * 1e9)), 999_999_999)
        return {
            "header": {"frame_id": self.frame_id, "stamp": {"sec": int(sec), "nanosec": nanosec}},
            "angle_min": float(self.angle_min_rad), "angle_max": float(self.angle_max_rad),
            "angle_increment": float(self.angle_increment_rad),
            "time_increment": float(self.time_increment_s), "scan_time": float(self.scan_time_s),
            "range_min": float(self.range_min_m), "range_max": float(self.range_max_m),
            "ranges": [_json_float(r) for r in self.ranges_m],
            "intensities": [_json_float(v) for v in self.intensities],
        }

    @classmethod
    def from_dict(cls, data) -> LaserScan:
        """Inverse of :meth:`to_dict`; ``header``, timing and ``intensities`` are optional."""
        keys = ("angle_min", "angle_max", "angle_increment", "range_min", "range_max", "ranges")
        if not isinstance(data, dict) or any(k not in data for k in keys):
            raise ValueError(f"laser scan must have the fields {', '.join(keys)}")
        for key in ("ranges", "intensities"):
            if not isinstance(data.get(key, []), list):
                raise ValueError(f"laser scan field {key} must be a list")
        ranges = np.array([_from_json_float(r, "ranges[]") for r in data["ranges"]], dtype=np.float64)
        intensities = np.array([_from_json_float(v, "intensities[]") for v in data.get("intensities", [])],
                               dtype=np.float64)
        if intensities.size not in (0, ranges.size):
            raise ValueError(f"laser scan has {ranges.size} ranges but {intensities.size} intensities")
        header = data.get("header") or {}
        stamp = header.get("stamp") or {}
        try:
            stamp_s = float(stamp.get("sec", 0)) + 1e-9 * float(stamp.get("nanosec", 0))
            numbers = {k: float(data[k]) for k in (*keys[:-1],)}
            timing = {k: float(data.get(k, 0.0)) for k in ("time_increment", "scan_time")}
        except (TypeError, ValueError, AttributeError):
            raise ValueError("laser scan angles, ranges limits, timing and stamp must be numbers") from None
        return cls(angle_min_rad=numbers["angle_min"], angle_max_rad=numbers["angle_max"],
                   angle_increment_rad=numbers["angle_increment"], range_min_m=numbers["range_min"],
                   range_max_m=numbers["range_max"], ranges_m=ranges, intensities=intensities,
                   frame_id=str(header.get("frame_id", "base_link")), stamp_s=stamp_s,
                   time_increment_s=timing["time_increment"], scan_time_s=timing["scan_time"])


def scan_angles_of_camera(stereo: StereoCamera, *, pan_rad: float = 0.0) -> tuple[float, float]:
    """Bearings ``(angle_min_rad, angle_max_rad)`` covered by the rectified left image.

    The right image edge (``u = W - 1``) looks to the right (negative angle),
    the left edge (``u = 0``) to the left; the pan turns both.
    """
    _checks.instance("stereo", stereo, StereoCamera)
    pan = _checks.finite_number("pan_rad", pan_rad)
    f, cx, w = stereo.focal_px, stereo.cx_px, stereo.size[0]
    return pan - math.atan2(w - 1 - cx, f), pan + math.atan2(cx, f)


def laser_scan_from_points(points_robot, *, angle_min_rad: float = -math.pi / 4,
                           angle_max_rad: float = math.pi / 4,
                           angle_increment_rad: float = math.radians(0.5), range_min_m: float = 0.1,
                           range_max_m: float = 10.0, min_points: int = 1, intensities=None,
                           observed_points_robot=None, frame_id: str = "base_link",
                           stamp_s: float = 0.0) -> LaserScan:
    """Nearest obstacle per bearing, like ``depthimage_to_laserscan``.

    Parameters
    ----------
    points_robot : ndarray of shape (N, 3) or (N, 2)
        Obstacle points in the robot frame (x and y used; the caller selects the height band).
    angle_min_rad, angle_max_rad : float
        First and last bearing (0 straight ahead, positive left).
    angle_increment_rad : float
    range_min_m, range_max_m : float
        Returns outside ``[range_min, range_max]`` are ignored.
    min_points : int
        A ray's range is that of its ``min_points``-th nearest point (1: the nearest), ignoring up
        to ``min_points - 1`` stray points; rays with fewer points report no return.
    intensities : ndarray of shape (N,), optional
        One value per point; a ray's intensity is that of its range's point (NaN without return).
    observed_points_robot : ndarray of shape (M, 3) or (M, 2), optional
        Everything seen in this frame: a ray without return whose farthest seen point is at
        ``>= range_max_m`` is ``+inf`` (REP 117), else ``nan``.
    frame_id, stamp_s : str, float
        Header of the scan.

    Returns
    -------
    LaserScan
    """
    p = _scan_points("points_robot", points_robot)
    a0 = _checks.finite_number("angle_min_rad", angle_min_rad)
    a1 = _checks.finite_number("angle_max_rad", angle_max_rad)
    inc = _checks.finite_number("angle_increment_rad", angle_increment_rad, positive=True)
    r0 = _checks.finite_number("range_min_m", range_min_m, nonnegative=True)
    r1 = _checks.finite_number("range_max_m", range_max_m, positive=True)
    stamp = _checks.finite_number("stamp_s", stamp_s, nonnegative=True)
    if not isinstance(frame_id, str) or not frame_id:
        raise ValueError(f"frame_id must be a non-empty str, got {frame_id!r}")
    if a1 <= a0:
        raise ValueError(f"angle_max_rad ({a1}) must exceed angle_min_rad ({a0})")
    if r1 <= r0:
        raise ValueError(f"range_max_m ({r1}) must exceed range_min_m ({r0})")
    m = _checks.positive_int("min_points", min_points)
    value = None
    if intensities is not None:
        value = np.asarray(intensities, dtype=np.float64).ravel()
        if value.shape != (p.shape[0],):
            raise ValueError(f"intensities must have one value per point ({p.shape[0]}), got shape "
                             f"{np.shape(intensities)}")
    observed = None if observed_points_robot is None else _scan_points("observed_points_robot", observed_points_robot)
    n_float = math.floor((a1 - a0) / inc + 1e-9) + 1
    _checks.fits_in_memory("angle_increment_rad", n_float * (40.0 + 16.0 * m), f"a scan of {n_float:.4g} rays")
    n = int(n_float)
    # one pass per point set: each bearing keeps its m nearest returns (sorted), and whether anything
    # was seen on it at range_max or beyond
    near_r = np.full((n, m), np.inf)
    near_i = np.full((n, m), -1, np.int64)
    count = np.zeros(n, np.int64)
    _scan_kernels.nearest_per_bearing(p, a0, inc, r0, r1, m, near_r, near_i, count)
    ranges = np.where(count >= m, near_r[:, m - 1], np.nan)
    scan_values = np.full(n, np.nan)
    if value is not None:
        has = count >= m
        scan_values[has] = value[near_i[has, m - 1]]
    reach = np.zeros(n, bool)
    for seen in (p, observed):
        if seen is not None and len(seen):
            _scan_kernels.seen_to_range(seen, a0, inc, r1, reach)
    ranges[np.isnan(ranges) & reach] = np.inf
    return LaserScan(angle_min_rad=a0, angle_max_rad=a0 + (n - 1) * inc, angle_increment_rad=inc,
                     range_min_m=r0, range_max_m=r1, ranges_m=ranges,
                     intensities=scan_values if value is not None else np.empty(0),
                     frame_id=frame_id, stamp_s=stamp)


def _scan_points(name: str, value) -> np.ndarray:
    """Points (N, 2 or 3) as given when they are float32 or float64 (the kernels read both), else as float64."""
    arr = np.asarray(value)
    if arr.dtype not in (np.float32, np.float64):
        arr = np.asarray(arr, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] not in (2, 3):
        raise ValueError(f"{name} must have shape (N, 3) or (N, 2), got {arr.shape}")
    return arr


def near_limit_range_m(stereo: StereoCamera, T_robot_from_cam, max_disparity_px: float) -> float:
    """Smallest horizontal range (robot frame) at which a search up to ``max_disparity_px`` measures.

    Nothing nearer than the depth ``Z = f B / d_max`` can be matched; over the image, the points at
    that depth lie at horizontal ranges of at least the returned value (the scan's honest
    ``range_min``). Evaluated on a grid of rectified pixels back-projected to depth ``Z`` and
    moved into the robot frame with ``T_robot_from_cam``.
    """
    _checks.instance("stereo", stereo, StereoCamera)
    d_max = _checks.finite_number("max_disparity_px", max_disparity_px, positive=True)
    T = _checks.matrix("T_robot_from_cam", T_robot_from_cam, (4, 4))
    depth_m = stereo.focal_px * stereo.baseline_m / d_max
    width, height = stereo.size
    u, v = np.meshgrid(np.linspace(0, width - 1, 33), np.linspace(0, height - 1, 25))
    f = stereo.focal_px
    points_cam = np.stack([(u - stereo.cx_px) / f * depth_m, (v - stereo.cy_px) / f * depth_m,
                           np.full(u.shape, depth_m)], axis=-1).reshape(-1, 3)
    points_robot = points_cam @ T[:3, :3].T + T[:3, 3]
    return float(np.hypot(points_robot[:, 0], points_robot[:, 1]).min())


def top_view(points_robot, *, x_range_m: tuple[float, float] = (0.0, 8.0),
             y_range_m: tuple[float, float] = (-3.0, 3.0), resolution_m: float = 0.05) -> np.ndarray:
    """Histogram (rows, cols) int32 of points over a robot-frame grid (the paper's top view, Figs 8b-10b).

    Cells as :class:`mrstereo.mapping.grid.GridSpec` (row 0 at the lowest y, column 0 at the lowest x,
    lower-left corner at ``(x_range_m[0], y_range_m[0])``), so the result can be laid on a map.
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
    """Write a scan as JSON: the ``sensor_msgs/LaserScan`` fields (:meth:`LaserScan.to_dict`)."""
    _checks.instance("scan", scan, LaserScan)
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
    """Write a scan as CSV rows ``angle_rad,range_m[,intensity]`` with the true values.

    ``range_m`` is a number, ``inf`` (seen clear to range_max), ``nan`` (no measurement) or
    ``-inf`` (too close) -- what ``float()``, ``numpy.loadtxt`` and pandas read as such.
    """
    _checks.instance("scan", scan, LaserScan)

    def number(value: float, digits: int) -> str:
        return f"{value:.{digits}f}" if math.isfinite(value) else str(float(value))

    with atomic_write(path) as tmp, open(tmp, "w", newline="") as fh:
        out = csv.writer(fh)
        with_intensity = scan.intensities.size == scan.ranges_m.size and scan.ranges_m.size > 0
        out.writerow(["angle_rad", "range_m"] + (["intensity"] if with_intensity else []))
        for k, (a, r) in enumerate(zip(scan.angles_rad, scan.ranges_m)):
            out.writerow([f"{a:.6f}", number(r, 4)] + ([number(scan.intensities[k], 2)] if with_intensity else []))


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
            clear = scan.angles_rad[np.isposinf(scan.ranges_m)]
            if clear.size:                # +inf: seen clear to range_max, drawn at range_max
                ax.plot(scan.range_max_m * np.sin(clear), scan.range_max_m * np.cos(clear), "|",
                        color="#80a0e0", ms=6)
                handles.append(Line2D([], [], ls="", marker="|", ms=8, color="#80a0e0",
                                      label=f"clear to range_max ({clear.size} rays)"))
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
