"""A* path planning on an occupancy map with obstacles inflated by the robot radius.

8-connected A* with the octile heuristic (admissible and consistent) and no corner cutting;
every cell within ``robot_radius_m`` of an occupied cell is blocked (the lethal zone of Nav2's
inflation layer). The cell path is then smoothed by line-of-sight shortcuts that cross no blocked
cell (the inflated clearance is kept) and given headings: the direction of travel, the goal's own
heading at the end when one is asked for. User guide: docs/mapping.md, "Planning". Conventions: docs/conventions.md.

References
----------
.. [1] P. E. Hart, N. J. Nilsson, B. Raphael, "A formal basis for the heuristic determination of
   minimum cost paths", IEEE Trans. Systems Science and Cybernetics 4(2), 1968.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import _checks
from . import _kernels
from .grid import distance_cells
from .rosmap import RosMap, as_ros_map

__all__ = ["PlanResult", "plan_path", "inflate_obstacles"]


@dataclass(frozen=True)
class PlanResult:
    """Outcome of :func:`plan_path`.

    ``path_xy`` holds world (x, y) points from the start cell's centre to the goal cell's, shape
    (K, 2) (empty on failure): the A* cell centres, or with smoothing the shortcut polyline sampled
    about every cell; ``yaw_rad`` (K,) the heading at each (direction of travel; the goal heading at
    the end when given); ``length_m`` the path's length (inf on failure).
    """

    success: bool
    message: str
    path_xy: np.ndarray = field(repr=False)
    length_m: float
    expanded_cells: int
    yaw_rad: np.ndarray = field(default_factory=lambda: np.empty(0), repr=False)

    @property
    def poses(self) -> np.ndarray:
        """(K, 3) ``(x_m, y_m, yaw_rad)`` along the path (a nav_msgs/Path's poses)."""
        return np.column_stack([self.path_xy, self.yaw_rad]) if len(self.path_xy) else np.empty((0, 3))


def inflate_obstacles(ros_map: RosMap, *, robot_radius_m: float = 0.25,
                      unknown_is_obstacle: bool = True) -> np.ndarray:
    """Blocked cells (bool, ``grid.shape``): occupied (and unknown) cells grown by the radius.

    A cell is blocked when the distance between its centre and the centre of the nearest
    occupied cell is <= ``robot_radius_m`` (exact Euclidean distance transform).
    """
    _checks.instance("ros_map", ros_map, RosMap)
    radius = _checks.finite_number("robot_radius_m", robot_radius_m, nonnegative=True)
    obstacles = ros_map.occupied | (ros_map.unknown if unknown_is_obstacle else False)
    if not obstacles.any():
        return obstacles.copy()
    distance_m = distance_cells(obstacles) * ros_map.grid.resolution_m
    return distance_m <= radius + 1e-9


def _point(name: str, value) -> np.ndarray:
    try:
        arr = np.asarray(value, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be two numbers (x, y), got {value!r}") from None
    if arr.shape != (2,) or not np.isfinite(arr).all():
        raise ValueError(f"{name} must be two finite numbers (x, y) in metres, got {value!r}")
    return arr


_UNKNOWN_HINT = ("unknown cells are blocked: plan with unknown as free, `--unknown free` / "
                 "unknown_is_obstacle=False, to allow it")


def _fail(message: str, expanded: int = 0) -> PlanResult:
    return PlanResult(False, message, np.empty((0, 2)), math.inf, expanded)


def plan_path(ros_map, start_xy, goal_xy, *, robot_radius_m: float = 0.25,
              unknown_is_obstacle: bool = True, smooth: bool = True, goal_yaw_rad: float | None = None) -> PlanResult:
    """Shortest 8-connected path between two world points for a disc robot (A*), smoothed.

    Parameters
    ----------
    ros_map : RosMap or OccupancyGrid
        The map (an OccupancyGrid is converted with ``to_ros_map()``).
    start_xy, goal_xy : sequence of 2 floats
        World (x, y) in metres.
    robot_radius_m : float
        Obstacles are inflated by this radius (cell-centre distances).
    unknown_is_obstacle : bool
        Block unknown cells (default) or treat them as free.
    smooth : bool
        Replace the staircase of cells by line-of-sight shortcuts through unblocked cells only
        (:func:`mrstereo.mapping._kernels.shortcut_path`): never closer to an obstacle than the
        inflation allows, never longer than the A* path.
    goal_yaw_rad : float, optional
        The heading the robot should have at the goal (the last pose's yaw); default the direction
        of the last step.

    Examples
    --------
    >>> import numpy as np
    >>> from mrstereo.mapping import GridSpec, RosMap, plan_path
    >>> free = RosMap(np.zeros((40, 40)), GridSpec(4.0, 4.0, 0.1, 0.0, 0.0))
    >>> result = plan_path(free, (0.25, 0.25), (3.75, 3.75), robot_radius_m=0.2)
    >>> round(result.length_m, 3), len(result.path_xy) > 2
    (4.95, True)

    Returns
    -------
    PlanResult
        ``success`` False with a one-line ``message`` when the start or goal is outside the map
        or blocked, or when no path exists; ``expanded_cells`` counts A* expansions.
    """
    ros_map = as_ros_map("ros_map", ros_map)
    start = _point("start_xy", start_xy)
    goal = _point("goal_xy", goal_xy)
    grid = ros_map.grid
    if np.shape(ros_map.occupancy) != grid.shape:
        raise ValueError(f"ros_map.occupancy has shape {np.shape(ros_map.occupancy)} but its grid is {grid.shape}")
    blocked = inflate_obstacles(ros_map, robot_radius_m=robot_radius_m,
                                unknown_is_obstacle=unknown_is_obstacle)
    x0, x1, y0, y1 = grid.extent_m
    cells = []
    for name, xy in (("start", start), ("goal", goal)):
        r, c = (int(v) for v in grid.cells_from_xy(xy))
        where = f"{name} ({xy[0]:g}, {xy[1]:g})"
        if not grid.inside(r, c):
            return _fail(f"{where} is outside the map [{x0:g}, {x1:g}] x [{y0:g}, {y1:g}] m")
        if ros_map.occupied[r, c]:
            return _fail(f"{where} is inside an obstacle")
        if unknown_is_obstacle and ros_map.unknown[r, c]:
            return _fail(f"{where} is in unknown space ({_UNKNOWN_HINT})")
        if blocked[r, c]:
            near_occupied = inflate_obstacles(ros_map, robot_radius_m=robot_radius_m,
                                              unknown_is_obstacle=False)[r, c]
            if near_occupied:
                return _fail(f"{where} is closer than the robot radius {robot_radius_m:g} m "
                             f"to an occupied cell")
            return _fail(f"{where} is closer than the robot radius {robot_radius_m:g} m to unknown "
                         f"space ({_UNKNOWN_HINT})")
        cells.append((r, c))
    (sr, sc), (gr, gc) = cells
    n = blocked.size
    came_from = np.full(n, -1, np.int64)
    g_cost = np.full(n, np.inf)
    expanded = _kernels.astar(np.ascontiguousarray(blocked, dtype=np.uint8), sr, sc, gr, gc,
                              came_from, g_cost)
    if expanded < 0:
        return _fail(f"no path from ({start[0]:g}, {start[1]:g}) to ({goal[0]:g}, {goal[1]:g}) "
                     f"for a robot of radius {robot_radius_m:g} m", -expanded - 1)
    cols = grid.shape[1]
    chain = [gr * cols + gc]
    while chain[-1] != sr * cols + sc:
        if len(chain) > n or came_from[chain[-1]] < 0:       # a broken chain: never loop forever
            raise RuntimeError("A* returned a path that does not lead back to the start")
        chain.append(int(came_from[chain[-1]]))
    idx = np.array(chain[::-1])
    rows_, cols_ = idx // cols, idx % cols
    if smooth and len(idx) > 2:
        keep = np.zeros(len(idx), np.uint8)
        _kernels.shortcut_path(np.ascontiguousarray(blocked, dtype=np.uint8), rows_, cols_, keep)
        corners = grid.xy_from_cells(rows_[keep > 0], cols_[keep > 0])
        path_xy = _sampled(corners, grid.resolution_m)
    else:
        path_xy = grid.xy_from_cells(rows_, cols_)
    length_m = float(np.linalg.norm(np.diff(path_xy, axis=0), axis=1).sum())
    yaw = _headings(path_xy, goal_yaw_rad)
    what = f"{len(path_xy)} points" if smooth else f"{len(idx)} cells"
    return PlanResult(True, f"path of {length_m:.3f} m through {what}", path_xy, length_m, int(expanded), yaw)


def _sampled(corners: np.ndarray, step_m: float) -> np.ndarray:
    """The polyline through ``corners`` (K, 2) with points about every ``step_m`` on each segment (corners kept)."""
    parts = [corners[:1]]
    for a, b in zip(corners[:-1], corners[1:]):
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / step_m - 1e-9)))
        t = np.arange(1, n + 1)[:, None] / n
        parts.append(a + t * (b - a))
    return np.concatenate(parts)


def _headings(path_xy: np.ndarray, goal_yaw_rad: float | None) -> np.ndarray:
    """The direction of travel at each point of a path (the next step's; the last step's at the end, or the goal's)."""
    if len(path_xy) < 2:
        yaw = np.zeros(len(path_xy))
    else:
        step = np.diff(path_xy, axis=0)
        yaw = np.arctan2(step[:, 1], step[:, 0])
        yaw = np.append(yaw, yaw[-1])
    if goal_yaw_rad is not None and len(yaw):
        yaw[-1] = _checks.finite_number("goal_yaw_rad", goal_yaw_rad)
    return yaw
