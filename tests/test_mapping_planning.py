"""A* planning on ROS maps and the ``mrstereo plan`` command."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.mapping import GridSpec, RosMap, inflate_obstacles, plan_path, write_ros_map

GRID = GridSpec()           # 240 x 120 cells of 5 cm, x in [0, 12], y in [-3, 3]


def free_map() -> np.ndarray:
    return np.zeros(GRID.shape)


def ros(occ: np.ndarray) -> RosMap:
    return RosMap(occupancy=occ, grid=GRID)


def wall_with_gap(gap_cells: int) -> np.ndarray:
    """A wall across the corridor at column 120 (x = 6 m) with a centred gap of free cells."""
    occ = free_map()
    occ[:, 120] = 1.0
    lo = 60 - gap_cells // 2
    occ[lo:lo + gap_cells, 120] = 0.0
    return occ


def assert_valid_path(result, blocked):
    steps = np.diff(result.path_xy, axis=0) / GRID.resolution_m
    assert np.all(np.abs(np.round(steps)) <= 1) and np.allclose(steps, np.round(steps))
    r, c = GRID.cells_from_xy(result.path_xy)
    assert not blocked[r, c].any()
    length = np.hypot(*np.diff(result.path_xy, axis=0).T).sum()
    assert result.length_m == pytest.approx(length)


def test_empty_map_gives_the_octile_distance():
    start, goal = (0.62, -2.31), (10.93, 1.77)
    result = plan_path(ros(free_map()), start, goal, smooth=False)
    (r0, r1), (c0, c1) = zip(GRID.cells_from_xy(start), GRID.cells_from_xy(goal))
    dr, dc = abs(r1 - r0), abs(c1 - c0)
    octile = (max(dr, dc) + (math.sqrt(2) - 1) * min(dr, dc)) * GRID.resolution_m
    assert result.success and result.length_m == pytest.approx(octile)
    np.testing.assert_allclose(result.path_xy[0], GRID.xy_from_cells(r0, c0))
    np.testing.assert_allclose(result.path_xy[-1], GRID.xy_from_cells(r1, c1))
    assert_valid_path(result, np.zeros(GRID.shape, bool))
    # smoothed: the straight line between the two cell centres, headings along it
    straight = plan_path(ros(free_map()), start, goal)
    assert straight.length_m == pytest.approx(np.hypot(*(result.path_xy[-1] - result.path_xy[0])))
    np.testing.assert_allclose(straight.yaw_rad, math.atan2(*(result.path_xy[-1] - result.path_xy[0])[::-1]))
    assert straight.poses.shape == (len(straight.path_xy), 3)


def assert_clear(result, blocked):
    """Every point of the polyline (sampled at a tenth of a cell) lies in an unblocked cell."""
    a, b = result.path_xy[:-1], result.path_xy[1:]
    t = np.linspace(0.0, 1.0, 11)[None, :, None]
    dense = (a[:, None] + t * (b - a)[:, None]).reshape(-1, 2)
    r, c = GRID.cells_from_xy(dense)
    assert not blocked[r, c].any()


def test_goes_around_a_wall_and_keeps_the_radius():
    occ = free_map()
    occ[20:120, 120] = 1.0                   # wall from y = -2 m up to the top, open below
    result = plan_path(ros(occ), (3.0, 1.0), (9.0, 1.0), robot_radius_m=0.25, smooth=False)
    blocked = inflate_obstacles(ros(occ), robot_radius_m=0.25)
    assert result.success
    assert_valid_path(result, blocked)
    assert result.path_xy[:, 1].min() < -2.0 - 0.25       # passed below the wall end
    around_the_end = 2 * np.hypot(3.0, 1.0 + 2.0 + 0.25)  # via the inflated wall end
    assert around_the_end < result.length_m < around_the_end * 1.1
    # smoothed: shorter, still clear of the inflated wall, within a cell of the shortest way round it
    smooth = plan_path(ros(occ), (3.0, 1.0), (9.0, 1.0), robot_radius_m=0.25, goal_yaw_rad=math.pi / 2)
    assert_clear(smooth, blocked)
    assert around_the_end - 0.1 < smooth.length_m < result.length_m
    assert smooth.length_m < around_the_end * 1.02
    assert smooth.yaw_rad[-1] == pytest.approx(math.pi / 2) and smooth.yaw_rad[0] < 0     # heads down first


def test_a_shortcut_crosses_no_blocked_cell_and_no_blocked_corner():
    from mrstereo.mapping._kernels import segment_free

    blocked = np.zeros((5, 5), np.uint8)
    assert segment_free(blocked, 0, 0, 4, 4) and segment_free(blocked, 4, 1, 0, 3)
    blocked[1, 0] = 1                       # beside the corner the diagonal (0,0)-(1,1) passes: refused
    assert not segment_free(blocked, 0, 0, 1, 1) and not segment_free(blocked, 2, 2, 0, 0)
    assert segment_free(blocked, 0, 0, 0, 4)
    blocked[:] = 0
    blocked[2, 2] = 1                       # (0,1)-(4,3) passes through (2,2); (0,0)-(4,1) does not
    assert not segment_free(blocked, 0, 1, 4, 3) and segment_free(blocked, 0, 0, 4, 1)


@pytest.mark.parametrize("gap_cells, passes", [(8, False), (10, False), (11, True), (16, True)])
def test_inflation_blocks_gaps_narrower_than_the_robot(gap_cells, passes):
    result = plan_path(ros(wall_with_gap(gap_cells)), (3.0, 0.0), (9.0, 0.0), robot_radius_m=0.25)
    assert result.success is passes
    if passes:
        assert result.length_m == pytest.approx(6.0, abs=0.2)
        assert_clear(result, inflate_obstacles(ros(wall_with_gap(gap_cells)), robot_radius_m=0.25))
    else:
        assert "no path" in result.message and result.path_xy.shape == (0, 2)


def test_no_corner_cutting_through_a_diagonal_wall():
    occ = free_map()
    i = np.arange(120)
    occ[i, i + 60] = 1.0                     # a one-cell diagonal wall corner to corner
    ok = plan_path(ros(occ), (1.0, 0.0), (2.0, 2.5), robot_radius_m=0.0)
    assert ok.success
    result = plan_path(ros(occ), (1.0, 0.0), (11.0, 0.0), robot_radius_m=0.0)
    assert not result.success and "no path" in result.message


def test_enclosed_goal_start_outside_and_blocked_start():
    occ = free_map()
    occ[50:71, 180] = occ[50:71, 200] = 1.0
    occ[50, 180:201] = occ[70, 180:201] = 1.0
    result = plan_path(ros(occ), (2.0, 0.0), (9.5, 0.0))
    assert not result.success and "no path" in result.message and result.expanded_cells > 0
    assert "outside the map" in plan_path(ros(occ), (-1.0, 0.0), (9.5, 0.0)).message
    assert "obstacle" in plan_path(ros(occ), (9.0, 0.0), (2.0, 0.0)).message
    assert "robot radius" in plan_path(ros(occ), (8.9, 0.0), (2.0, 0.0)).message


def test_unknown_cells_blocked_or_free():
    occ = free_map()
    occ[:, 100:140] = np.nan
    assert not plan_path(ros(occ), (2.0, 0.0), (10.0, 0.0)).success
    assert plan_path(ros(occ), (2.0, 0.0), (10.0, 0.0), unknown_is_obstacle=False).success
    assert "unknown" in plan_path(ros(occ), (6.0, 0.0), (10.0, 0.0)).message


def test_goal_near_unknown_says_unknown_not_obstacle():
    """A goal in free space next to unknown cells: the message names unknown space, not an obstacle."""
    occ = free_map()
    occ[58:63, 198:203] = np.nan             # an unseen pocket around x = 10 m, y = 0
    occ[0, :] = 1.0                          # a wall far away (y = -3 m)
    goal = (10.0, 0.2)                       # free, 0.1-0.2 m from the pocket
    r, c = GRID.cells_from_xy(goal)
    assert occ[r, c] == 0.0
    blocked = plan_path(ros(occ), (2.0, 0.0), goal, robot_radius_m=0.25)
    assert not blocked.success
    assert "unknown space" in blocked.message and "occupied" not in blocked.message
    assert "--unknown free" in blocked.message
    assert plan_path(ros(occ), (2.0, 0.0), goal, robot_radius_m=0.25, unknown_is_obstacle=False).success
    occ[62, 200] = 1.0                       # now an occupied cell is within the radius too
    assert "occupied cell" in plan_path(ros(occ), (2.0, 0.0), goal, robot_radius_m=0.25).message


def test_bad_inputs_raise():
    with pytest.raises(ValueError, match="start_xy"):
        plan_path(ros(free_map()), (np.nan, 0.0), (1.0, 1.0))
    with pytest.raises(ValueError, match="robot_radius_m"):
        plan_path(ros(free_map()), (1.0, 0.0), (2.0, 0.0), robot_radius_m=-1.0)
    with pytest.raises(TypeError, match="ros_map"):
        plan_path(free_map(), (1.0, 0.0), (2.0, 0.0))


def test_cli_plan_writes_json_and_fails_with_one_line(tmp_path, capsys):
    write_ros_map(tmp_path / "map.yaml", ros(wall_with_gap(16)))
    out = tmp_path / "path.json"
    code = entry(["plan", str(tmp_path / "map.yaml"), "--start", "3,0", "--goal", "9,0",
                  "-o", str(out), "--plot", str(tmp_path / "path.png")])
    assert code == 0, capsys.readouterr().err
    record = json.loads(out.read_text())
    assert record["length_m"] == pytest.approx(6.0, abs=0.2)
    assert record["robot_radius_m"] == 0.25 and record["start"] == [3.0, 0.0]
    assert len(record["path_xy"]) > 100 and (tmp_path / "path.png").is_file()
    assert "path length" in capsys.readouterr().out

    write_ros_map(tmp_path / "narrow.yaml", ros(wall_with_gap(8)))
    code = entry(["plan", str(tmp_path / "narrow.yaml"), "--start", "3,0", "--goal", "9,0",
                  "-o", str(tmp_path / "none.json")])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("mrstereo: error: no path") and err.count("\n") == 1
    assert not (tmp_path / "none.json").exists()

    assert entry(["plan", str(tmp_path / "map.yaml"), "--start", "3", "--goal", "9,0",
                  "-o", str(out)]) == 2
    capsys.readouterr()
    assert entry(["plan", str(tmp_path / "map.yaml"), "--start", "3,0", "--goal", "9,0",
                  "-o", str(tmp_path / "map.json"), "--plot", str(tmp_path / "map.pgm")]) == 2
    assert "--plot must end in" in capsys.readouterr().err
    (tmp_path / "link.json").symlink_to(tmp_path / "map.yaml")
    assert entry(["plan", str(tmp_path / "map.yaml"), "--start", "3,0", "--goal", "9,0",
                  "-o", str(tmp_path / "link.json")]) == 2
    assert "would overwrite the input" in capsys.readouterr().err


def test_cli_plan_from_the_robots_last_pose_with_a_heading_into_a_bag(tmp_path, capsys):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    from mrstereo.odometry.trajectory import write_tum
    from mrstereo.transforms import T_from_planar

    write_ros_map(tmp_path / "map.yaml", ros(wall_with_gap(16)))
    code = entry(["plan", str(tmp_path / "map.yaml"), "--start", "robot", "--goal", "9,0", "-o",
                  str(tmp_path / "p.json")])
    err = capsys.readouterr().err
    assert code == 2 and "trajectory.txt" in err and err.count("\n") == 1     # no trajectory beside the map
    write_tum(tmp_path / "trajectory.txt", [0.0, 1.0], [T_from_planar(1.0, 0.5, 0.0), T_from_planar(3.0, 0.4, 0.2)])
    code = entry(["plan", str(tmp_path / "map.yaml"), "--start", "robot", "--goal", "9,0,1.5708", "-o",
                  str(tmp_path / "p.json"), "--record-bag", str(tmp_path / "bag")])
    assert code == 0, capsys.readouterr().err
    record = json.loads((tmp_path / "p.json").read_text())
    assert record["start"] == pytest.approx([3.0, 0.4])
    assert record["poses"][-1][2] == pytest.approx(1.5708) and record["goal_yaw_rad"] == pytest.approx(1.5708)
    r, c = GRID.cells_from_xy(np.array([3.0, 0.4]))
    np.testing.assert_allclose(record["path_xy"][0], GRID.xy_from_cells(r, c))
    store = get_typestore(Stores.ROS2_HUMBLE)
    with Reader(tmp_path / "bag") as reader:
        msgs = {c.topic: store.deserialize_cdr(raw, c.msgtype) for c, _, raw in reader.messages()}
    assert set(msgs) == {"/map", "/plan"}
    plan = msgs["/plan"]
    assert plan.header.frame_id == "map" and len(plan.poses) == len(record["poses"])
    xy = np.array([[p.pose.position.x, p.pose.position.y] for p in plan.poses])
    np.testing.assert_allclose(xy, record["path_xy"], atol=1e-6)
    q = plan.poses[-1].pose.orientation
    assert 2 * math.atan2(q.z, q.w) == pytest.approx(1.5708, abs=1e-6)
    values = np.asarray(msgs["/map"].data, np.int8).reshape(GRID.shape)
    assert set(np.unique(values)) == {0, 100} and (values[:, 120] == 100).sum() == 120 - 16
    for bad in ("9,0,90", "9"):            # degrees for radians; one number
        assert entry(["plan", str(tmp_path / "map.yaml"), "--start", "3,0", "--goal", bad, "-o",
                      str(tmp_path / "q.json")]) == 2
        assert "--goal" in capsys.readouterr().err


def test_plan_starts_where_a_map_run_left_the_robot(synthetic_dataset, tmp_path, capsys):
    """`mrstereo map` writes trajectory.txt; `plan --start robot` on its map.yaml starts at its last pose."""
    from mrstereo.odometry.trajectory import read_tum

    data = synthetic_dataset(seed=5, n_frames=6, width=160, height=120, supersample=1)
    assert entry(["map", str(data), "-o", str(tmp_path / "m"), "--quiet"]) == 0
    _, T = read_tum(tmp_path / "m" / "trajectory.txt")
    assert len(T) == 6
    code = entry(["plan", str(tmp_path / "m" / "map.yaml"), "--start", "robot", "--goal",
                  f"{T[-1][0, 3] + 0.5},{T[-1][1, 3]}", "--unknown", "free", "-o", str(tmp_path / "p.json")])
    assert code == 0, capsys.readouterr().err
    record = json.loads((tmp_path / "p.json").read_text())
    assert record["start"] == pytest.approx([T[-1][0, 3], T[-1][1, 3]])


@pytest.mark.parametrize("gap_m, passes", [(0.3, False), (0.8, True)])
def test_plan_crosses_a_ledge_of_drop_cells_only_through_a_gap_wider_than_the_robot(gap_m, passes):
    from mrstereo.mapping import MappingConfig, OccupancyGrid

    grid = GridSpec(width_m=4.0, height_m=2.0, resolution_m=0.05, origin_x_m=0.0, origin_y_m=-1.0)
    config = MappingConfig(footprint_radius_m=None)
    occupancy = OccupancyGrid(grid, config=config, log_odds=np.full(grid.shape, config.l_min))   # all seen free
    # a ledge at x = 2.0-2.05 m across the whole map, its edge found by the drop test but for a gap at y in [0, gap)
    y = np.arange(-1.0, 1.0, 0.05) + 0.025
    y = y[(y < 0.0) | (y > gap_m)]
    edge = np.repeat(np.column_stack([np.full(len(y), 2.025), y, np.zeros(len(y))]), config.drop_min_points, axis=0)
    floor = np.array([[x, -0.5, 0.0] for x in np.arange(0.5, 3.5, 0.05) for _ in range(5)])
    for _ in range(3):                 # rays over the ledge (at y = -0.5) clear nothing of it: it stays lethal
        occupancy.update(None, floor, (0.3, -0.5, 0.5), layers=(np.empty((0, 3)), floor, edge))
    assert occupancy.drop.sum() == len(y) and not occupancy.free[occupancy.drop].any()
    result = plan_path(occupancy, (0.5, 0.1), (3.5, 0.1), robot_radius_m=0.25, unknown_is_obstacle=False)
    assert result.success == passes, result.message
    if passes:                         # through the gap, never nearer a drop cell than the robot's radius
        centres = grid.xy_from_cells(*np.nonzero(occupancy.drop))
        gaps = np.linalg.norm(result.path_xy[:, None, :] - centres[None], axis=-1).min(axis=1)
        assert gaps.min() >= 0.25 and (np.abs(result.path_xy[:, 0] - 2.025) < 0.03).any()
