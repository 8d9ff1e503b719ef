"""Occupancy grid: ray clearing, log-odds closed form, clamping, union fusion, ROS map files."""
from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest

from mrstereo.mapping import GridSpec, MappingConfig, OccupancyGrid, plot_map, read_ros_map, write_ros_map
from mrstereo.mapping.occupancy import log_odds_from_probability, probability_from_log_odds, view_cells

RES = 0.05
PLAIN = MappingConfig(p_miss=0.4, min_points_per_cell=1, disparity_sigma_px=None, occlusion_gap_m=None,
                      see_through_ratio=None, overhang_shadow=False, map_occlusion_p=None, clear_below_m=None)
"""OctoMap's plain ray model: the stereo rules of the default config off; a test turns on the rule it checks."""


def with_rules(**rules) -> MappingConfig:
    return replace(PLAIN, **rules)


def centre(row: int, col: int, grid: GridSpec | None = None) -> tuple[float, float]:
    x, y = (grid or GridSpec()).xy_from_cells(row, col)
    return float(x), float(y)


def test_single_obstacle_clears_the_cells_before_it_and_nothing_behind():
    grid = OccupancyGrid(config=PLAIN)
    sensor = centre(60, 20)
    stats = grid.update(np.array([[*centre(60, 40), 0.7]]), None, sensor)
    p = grid.probability()
    assert stats.hit_cells == 1 and stats.miss_cells == 20 and stats.points_outside == 0
    assert p[60, 40] == pytest.approx(0.7)
    np.testing.assert_allclose(p[60, 20:40], 0.4)
    assert np.isnan(p[60, 41:]).all()                 # behind the obstacle: still unknown
    assert np.isnan(p[61]).all() and np.isnan(p[59]).all()
    assert (~np.isnan(p)).sum() == 21
    assert grid.occupied[60, 40] and grid.free[60, 25] and grid.unknown[60, 45]


def test_oblique_ray_clears_every_cell_it_crosses():
    grid = OccupancyGrid(config=PLAIN)
    sensor = np.array([0.512, -0.733])
    target = np.array([2.71, 1.388])
    grid.update(target[None], np.empty((0, 3)), sensor)
    spec = grid.grid
    t = np.linspace(0.0, 1.0, 20001)[:, None]
    rows, cols = spec.cells_from_xy(sensor + t * (target - sensor))
    end = spec.cells_from_xy(target)
    crossed = {(int(r), int(c)) for r, c in zip(rows, cols)} - {(int(end[0]), int(end[1]))}
    free = {tuple(rc) for rc in np.argwhere(grid.free)}
    assert free == crossed                            # exactly the crossed cells, end excluded
    assert grid.occupied[end] and grid.occupied.sum() == 1
    behind = spec.cells_from_xy(target + 0.3 * (target - sensor) / np.linalg.norm(target - sensor))
    assert grid.unknown[behind]


def test_floor_points_clear_their_own_cell():
    grid = OccupancyGrid(config=PLAIN)
    grid.update(None, np.array([[*centre(70, 30), 0.0]]), centre(60, 20))
    assert grid.free[70, 30] and grid.free[60, 20] and not grid.occupied.any()


def test_hits_are_counted_once_per_update_and_win_over_misses():
    grid = OccupancyGrid(config=PLAIN)
    x, y = centre(60, 40)
    pts = np.c_[x + np.linspace(-0.02, 0.02, 500), np.full(500, y), np.zeros(500)]
    far = np.array([[*centre(60, 50), 0.0]])           # its ray crosses cell (60, 40)
    grid.update(np.vstack([pts, far]), None, centre(60, 20))
    p = grid.probability()
    assert p[60, 40] == pytest.approx(0.7)            # one hit, the miss is dropped
    assert p[60, 30] == pytest.approx(0.4)            # one miss although 501 rays cross it


@pytest.mark.parametrize("k_hits, m_misses", [(1, 0), (3, 2), (4, 1), (0, 3)])
def test_log_odds_match_closed_form(k_hits, m_misses):
    config = PLAIN
    grid = OccupancyGrid(config=config)
    sensor = centre(60, 20)
    for _ in range(k_hits):
        grid.update([centre(60, 40)], None, sensor)
    for _ in range(m_misses):
        grid.update([centre(60, 60)], None, sensor)    # passes through (60, 40)
    expected_l = k_hits * np.log(0.7 / 0.3) + m_misses * np.log(0.4 / 0.6)
    assert grid.log_odds[60, 40] == pytest.approx(expected_l)
    assert grid.probability()[60, 40] == pytest.approx(1.0 / (1.0 + np.exp(-expected_l)))


def test_clamping_limits_are_reached_and_kept():
    grid = OccupancyGrid(config=PLAIN)
    sensor = centre(60, 20)
    for _ in range(15):
        grid.update([centre(60, 40)], None, sensor)
    assert grid.log_odds[60, 40] == pytest.approx(log_odds_from_probability(0.971))
    assert grid.probability()[60, 40] == pytest.approx(0.971)
    assert grid.probability()[60, 30] == pytest.approx(0.1192)   # 15 misses, clamped low
    grid.update([centre(60, 60)], None, sensor)                  # one miss on the clamped cell
    expected = log_odds_from_probability(0.971) + log_odds_from_probability(0.4)
    assert grid.log_odds[60, 40] == pytest.approx(expected)      # so it can still change


def test_moved_obstacle_is_cleared_by_log_odds_but_not_by_union():
    sensor = centre(60, 20)
    grids = {f: OccupancyGrid(config=with_rules(fusion=f)) for f in ("log_odds", "union")}
    for grid in grids.values():
        for _ in range(2):
            grid.update([centre(60, 40)], None, sensor)          # a person stands here
        for _ in range(10):
            grid.update([centre(60, 70)], None, sensor)          # ... and walks away
    assert grids["log_odds"].free[60, 40]
    assert grids["union"].occupied[60, 40]
    for grid in grids.values():                                  # both agree elsewhere
        assert grid.occupied[60, 70] and grid.free[60, 55] and grid.free[60, 30]


def test_points_outside_the_grid_are_clipped_along_their_ray():
    grid = OccupancyGrid(config=PLAIN)
    stats = grid.update([[25.0, centre(60, 0)[1], 0.5]], None, centre(60, 200))
    assert stats.points_outside == 1
    assert grid.free[60, 200:].all() and not grid.occupied.any()
    assert (~grid.unknown).sum() == 40
    outside_sensor = OccupancyGrid(config=PLAIN)
    outside_sensor.update([centre(60, 10)], None, (-1.0, centre(60, 0)[1]))
    assert outside_sensor.free[60, :10].all() and outside_sensor.occupied[60, 10]


def test_max_range_cuts_the_ray_without_a_hit():
    grid = OccupancyGrid(config=with_rules(max_range_m=1.0))
    grid.update([centre(60, 60)], None, centre(60, 20))          # 2 m away
    assert not grid.occupied.any()
    assert grid.free[60, 20:40].all() and grid.unknown[60, 41:].all()


def test_nan_points_are_ignored_and_2d_points_accepted():
    grid = OccupancyGrid(config=PLAIN)
    stats = grid.update(np.array([[np.nan, 1.0], [*centre(60, 40)]]), None, centre(60, 20))
    assert stats.hit_cells == 1 and grid.occupied[60, 40]


def test_map_orientation_left_of_robot_is_upper_half_of_pgm(tmp_path):
    grid = OccupancyGrid(config=PLAIN)
    grid.update([[1.0, 2.0, 0.3]], None, (0.0, 0.0))
    write_ros_map(tmp_path / "map.yaml", grid.to_ros_map())
    image = cv2.imread(str(tmp_path / "map.pgm"), cv2.IMREAD_UNCHANGED)
    rows, cols = np.nonzero(image == 0)
    assert len(rows) == 1
    assert rows[0] < image.shape[0] / 2                 # y = +2 m (left): top half
    assert rows[0] == image.shape[0] - 1 - 100 and cols[0] == 20
    assert image[image.shape[0] - 1 - 60, 0] == 254    # sensor cell free, y = 0 at row 60 from below


def test_ros_map_round_trip_keeps_free_occupied_unknown(tmp_path):
    grid = OccupancyGrid(GridSpec(width_m=3.0, height_m=2.0, origin_x_m=-0.5, origin_y_m=-1.2), config=PLAIN)
    rng = np.random.default_rng(3)
    grid.update(rng.uniform([0.5, -1.0], [2.4, 0.7], (50, 2)), rng.uniform([0, -1], [2, 0.5], (50, 2)),
                (0.0, 0.0))
    ros_map = grid.to_ros_map()
    write_ros_map(tmp_path / "m.yaml", ros_map)
    back = read_ros_map(tmp_path / "m.yaml")
    assert back.grid == ros_map.grid
    for mask in ("occupied", "free", "unknown"):
        np.testing.assert_array_equal(getattr(back, mask), getattr(grid, mask))
    assert grid.occupied.any() and grid.free.any() and grid.unknown.any()


def test_log_odds_npy_round_trip(tmp_path):
    grid = OccupancyGrid(config=PLAIN)
    grid.update([centre(60, 40)], None, centre(60, 20))
    grid.save_log_odds(tmp_path / "lo.npy")
    back = OccupancyGrid.load_log_odds(tmp_path / "lo.npy")
    np.testing.assert_array_equal(back.log_odds, grid.log_odds)   # NaN positions included
    with pytest.raises(ValueError, match="shape"):
        OccupancyGrid.load_log_odds(tmp_path / "lo.npy", GridSpec(width_m=1.0))
    with pytest.raises(ValueError, match=".npy"):
        grid.save_log_odds(tmp_path / "lo.txt")


def test_probability_helpers_are_inverse():
    p = np.array([0.1, 0.4, 0.5, 0.97, np.nan])
    np.testing.assert_allclose(probability_from_log_odds(log_odds_from_probability(p)), p)


def test_bad_inputs_raise():
    grid = OccupancyGrid(config=PLAIN)
    with pytest.raises(ValueError, match="points_obstacle_world"):
        grid.update(np.zeros((3, 4)), None, (0, 0))
    with pytest.raises(ValueError, match="sensor_origin_world"):
        grid.update(np.zeros((3, 3)), None, (np.nan, 0))
    with pytest.raises(ValueError, match="p_hit"):
        MappingConfig(p_hit=0.4)
    with pytest.raises(ValueError, match="fusion"):
        MappingConfig(fusion="max")
    with pytest.raises(ValueError, match="p_clamp_min"):
        MappingConfig(p_clamp_min=0.6)
    with pytest.raises(TypeError, match="grid"):
        OccupancyGrid((12, 6))


def test_plot_map_writes_an_image(tmp_path):
    grid = OccupancyGrid(config=PLAIN)
    grid.update([centre(60, 40), centre(80, 60)], [centre(65, 30)], centre(60, 20))
    out = tmp_path / "map.png"
    plot_map(grid, out, robot_path=np.array([[1.0, 0.0, 0.0], [2.0, 0.2, 0.4]]),
             fov_views=[(1.0, 0.0, 0.0, 0.4, 4.0), (1.0, 0.0, 0.785, 0.4, 4.0)],
             planned_path=np.array([[1.0, 0.0], [3.0, 1.0]]), ground_truth=grid.to_ros_map())
    image = cv2.imread(str(out))
    assert image is not None and image.shape[1] == 1000
    with pytest.raises(ValueError, match="fov_views"):
        plot_map(grid, tmp_path / "bad.png", fov_views=[(1.0, 0.0, 0.0)])
    assert not (tmp_path / "bad.png").exists()


def test_min_points_per_cell_drops_isolated_hits():
    grid = OccupancyGrid(config=with_rules(min_points_per_cell=3))
    sensor = centre(60, 20)
    wall = np.repeat(np.array([[*centre(60, 40), 0.5]]), 3, axis=0)   # three points: supported
    stray = np.array([[*centre(80, 30), 0.5]])                         # one point: not a hit
    stats = grid.update(np.vstack([wall, stray]), None, sensor)
    assert stats.hit_cells == 1
    assert grid.occupied[60, 40] and not grid.occupied[80, 30]
    assert grid.unknown[80, 30]
    with pytest.raises(ValueError, match="min_points_per_cell must be >= 1"):
        MappingConfig(min_points_per_cell=0)


def test_view_cells_of_one_ray_and_their_ordered_application():
    from mrstereo.mapping import ViewCells, view_cells
    spec = GridSpec()
    cells = view_cells(np.array([[*centre(60, 40), 0.7]]), None, centre(60, 20), config=PLAIN)
    assert isinstance(cells, ViewCells)
    np.testing.assert_array_equal(cells.hit, [np.ravel_multi_index((60, 40), spec.shape)])
    np.testing.assert_array_equal(cells.miss, np.ravel_multi_index((np.full(20, 60), np.arange(20, 40)), spec.shape))
    # views computed anywhere (in any order), applied in order == updated one after another
    rng = np.random.default_rng(3)
    views = [(rng.uniform([0.5, -2.5], [6.0, 2.5], (200, 2)), rng.uniform([0.5, -2.5], [6.0, 2.5], (300, 2)),
              rng.uniform([0.0, -1.0], [1.0, 1.0])) for _ in range(6)]
    config = with_rules(min_points_per_cell=1, max_range_m=4.0)
    precomputed = [view_cells(*v, config=config) for v in reversed(views)][::-1]
    a, b = OccupancyGrid(config=config), OccupancyGrid(config=config)
    for v, c in zip(views, precomputed):
        ua, ub = a.update(*v), b.apply(c)
        assert ua == ub
    np.testing.assert_array_equal(a.log_odds, b.log_odds)
    assert np.isfinite(a.log_odds).sum() > 100


def test_apply_refuses_cells_of_another_config():
    from mrstereo.mapping import view_cells
    cells = view_cells(np.array([[1.0, 0.0]]), None, (0.0, 0.0), config=with_rules(max_range_m=4.0))
    with pytest.raises(ValueError, match="max_range_m"):
        OccupancyGrid(config=PLAIN).apply(cells)
    with pytest.raises(TypeError, match="cells must be ViewCells"):
        OccupancyGrid(config=PLAIN).apply([1, 2])


def test_range_uncertainty_keeps_the_cells_just_before_a_far_return_unchanged():
    """sigma_r = r^2 sigma_d / (b f): 3 m, 0.25 px, b f = 24 m px -> 9.4 cm; k = 2 -> 18.75 cm (3.75 cells)."""
    config = with_rules(disparity_sigma_px=0.25, clear_margin_sigmas=2.0)
    grid = OccupancyGrid(config=config)
    sensor = centre(60, 20)
    target = np.array([[sensor[0] + 3.0, sensor[1]]])          # 60 cells ahead, centre of cell (60, 80)
    grid.update(target, None, sensor, baseline_focal_m_px=24.0)
    # cells are entered at x = 0.5, 1.5, ... cells from the sensor; cleared while entry < 60 - 3.75
    assert grid.free[60, 20:77].all() and grid.unknown[60, 77:80].all() and grid.occupied[60, 80]
    near = OccupancyGrid(config=config)
    near.update(np.array([[sensor[0] + 0.5, sensor[1]]]), None, sensor, baseline_focal_m_px=24.0)
    assert near.free[60, 20:30].all() and near.occupied[60, 30]    # 0.5 m: margin 0.5 mm, all cleared
    plain = OccupancyGrid(config=PLAIN)
    plain.update(target, None, sensor, baseline_focal_m_px=24.0)   # no sigma: up to the point
    assert plain.free[60, 20:80].all()
    with pytest.raises(ValueError, match="baseline_focal_m_px"):
        grid.update(target, None, sensor, baseline_focal_m_px=-1.0)
    with pytest.raises(ValueError, match="disparity_sigma_px"):
        MappingConfig(disparity_sigma_px=0.0)


def test_a_point_seen_through_a_wall_of_the_same_view_is_dropped():
    sensor = centre(60, 20)
    wall = np.array([[centre(r, 60)[0], centre(r, 60)[1]] for r in range(40, 81) for _ in range(6)])
    phantom = np.array([[centre(61, 100)[0], centre(61, 100)[1]]] * 6)       # 2 m behind the wall
    points = np.vstack([wall, phantom])
    tested = with_rules(occlusion_gap_m=0.25, min_points_per_cell=5)
    cells = view_cells(points, None, sensor, config=tested)
    hit = np.zeros(GridSpec().shape, bool).ravel()
    hit[cells.hit] = True
    hit = hit.reshape(GridSpec().shape)
    assert hit[40:81, 60].all() and not hit[61, 100] and cells.occluded == 1
    missed = np.zeros(hit.size, bool)
    missed[cells.miss] = True
    missed = missed.reshape(hit.shape)
    assert not missed[55:66, 61:101].any()                        # nothing cleared behind the wall
    plain = view_cells(points, None, sensor, config=with_rules(min_points_per_cell=5))
    assert np.ravel_multi_index((61, 100), hit.shape) in plain.hit and plain.occluded == 0
    # a floor point behind the wall clears nothing behind it either
    floor = view_cells(wall, np.array([[*centre(60, 90), 0.0]]), sensor, config=tested)
    assert np.ravel_multi_index((60, 90), hit.shape) not in floor.miss and floor.occluded == 1


def test_grazing_wall_is_not_occluded_by_itself():
    """A wall 1 m to the side seen along its length up to 4 m: every wall cell stays a hit."""
    sensor = (0.5, 0.0)
    xs = np.arange(1.0, 4.5, 0.01)
    wall = np.c_[xs, np.full(xs.size, 1.02)]
    cells = view_cells(wall, None, sensor, config=with_rules(occlusion_gap_m=0.25))
    assert cells.occluded == 0
    plain = view_cells(wall, None, sensor, config=PLAIN)
    np.testing.assert_array_equal(cells.hit, plain.hit)


def _hit_mask(cells):
    mask = np.zeros(GridSpec().shape, bool).ravel()
    mask[cells.hit] = True
    return mask.reshape(GridSpec().shape)


def test_occlusion_is_three_dimensional_a_table_top_hides_nothing_below_it():
    sensor_xy = centre(60, 20)
    table = np.array([[*centre(60, 40), z] for z in np.linspace(0.68, 0.72, 8)])     # a table-top edge, 1 m
    wall = np.array([[*centre(60, 80), z] for z in np.linspace(0.1, 0.45, 8)])        # 3 m, seen below it
    config = with_rules(occlusion_gap_m=0.25, min_points_per_cell=5)
    with_height = view_cells(np.vstack([table, wall]), None, (*sensor_xy, 0.5), config=config)
    assert _hit_mask(with_height)[60, 40] and _hit_mask(with_height)[60, 80] and with_height.occluded == 0
    flat = view_cells(np.vstack([table, wall]), None, sensor_xy, config=config)      # 2-D: the top hides the wall
    assert _hit_mask(flat)[60, 40] and not _hit_mask(flat)[60, 80] and flat.occluded == 1
    # a wall point whose sight line crosses the table top's height is hidden by it
    high = np.array([[*centre(60, 80), 0.95]] * 8)
    hidden = view_cells(np.vstack([table, high]), None, (*sensor_xy, 0.5), config=config)
    assert not _hit_mask(hidden)[60, 80] and hidden.occluded == 1


def test_a_floating_mismatch_with_the_floor_seen_through_it_is_cleared():
    """Obstacle points 0.3 m up, 1 m ahead, with floor points 1.8-2.5 m ahead along the same sight lines."""
    sensor = (*centre(60, 20), 0.5)
    ghost = np.array([[*centre(60, 40), 0.3]] * 6)
    floor = np.array([[*centre(60, c), 0.0] for c in range(56, 71) for _ in range(10)])
    config = with_rules(occlusion_gap_m=0.25, see_through_ratio=1.0, min_points_per_cell=5)
    cells = view_cells(ghost, floor, sensor, config=config)
    flat = np.ravel_multi_index((60, 40), GridSpec().shape)
    assert flat not in cells.hit and flat in cells.miss and cells.occluded == 1
    kept = view_cells(ghost, floor, sensor, config=with_rules(occlusion_gap_m=0.25, min_points_per_cell=5))
    assert flat in kept.hit                        # without the test the ghost hides the floor instead
    table = np.array([[*centre(60, 40), 0.7]] * 6)  # the floor seen *below* a table top is no evidence against it
    under = view_cells(table, floor, sensor, config=config)
    assert flat in under.hit


def _mask(flat_indices):
    mask = np.zeros(GridSpec().shape, bool).ravel()
    mask[flat_indices] = True
    return mask.reshape(GridSpec().shape)


def test_no_clearing_beyond_an_overhang_but_the_wall_under_it_is_hit():
    """Camera 0.5 m up at column 20; a table-top edge 0.7 m up at column 40 (1 m); floor seen under it
    at columns 45-70; a wall seen under it at column 80 (3 m)."""
    sensor = (*centre(60, 20), 0.5)
    table = np.array([[*centre(60, 40), z] for z in np.linspace(0.68, 0.72, 8)])
    wall = np.array([[*centre(60, 80), z] for z in np.linspace(0.05, 0.2, 8)])
    floor = np.array([[*centre(60, c), 0.0] for c in range(45, 71)])
    base = with_rules(occlusion_gap_m=0.25, min_points_per_cell=5)
    plain = view_cells(np.vstack([table, wall]), floor, sensor, config=base)
    shadow = view_cells(np.vstack([table, wall]), floor, sensor, config=with_rules(
        occlusion_gap_m=0.25, min_points_per_cell=5, overhang_shadow=True))
    assert _mask(plain.miss)[60, 41:80].all()                 # plain: everything under the table cleared
    missed, hit = _mask(shadow.miss), _mask(shadow.hit)
    assert missed[60, 21:40].all() and not missed[60, 40:].any()   # up to the table edge, nothing beyond
    assert hit[60, 40] and hit[60, 80] and shadow.occluded == 0
    # the floor 2 m ahead seen over a low box (0.15 m, 1 m ahead; the line is 0.25 m high there): the
    # line is not under the box, clearing goes on behind it
    box = np.array([[*centre(60, 40), z] for z in np.linspace(0.05, 0.15, 8)])
    over = view_cells(box, np.array([[*centre(60, 60), 0.0]]), sensor, config=with_rules(
        occlusion_gap_m=0.25, min_points_per_cell=5, overhang_shadow=True))
    assert _mask(over.miss)[60, 41:61].all() and over.occluded == 0


def test_clearing_only_where_the_sight_line_is_low_enough():
    """Camera 1.2 m up, floor point 3 m ahead: the sight line is 1.2 (1 - d / 3) m high at d, at most
    0.8 m from d = 1 m on (cells whose whole crossing is below 0.8 m: entered at d >= 1.0 m)."""
    sensor_xy = centre(60, 20)                            # x at the centre of column 20
    floor = np.array([[sensor_xy[0] + 3.0, sensor_xy[1], 0.0]])
    config = with_rules(clear_below_m=0.8)
    missed = _mask(view_cells(None, floor, (*sensor_xy, 1.2), config=config).miss)
    # column c is entered at d = (c - 20 - 0.5) * 0.05 m: column 41 at 1.025 m is the first cleared
    assert not missed[60, 20:41].any() and missed[60, 41:81].all()
    everywhere = _mask(view_cells(None, floor, (*sensor_xy, 1.2), config=PLAIN).miss)
    assert everywhere[60, 20:81].all()
    flat = _mask(view_cells(None, floor[:, :2], sensor_xy, config=config).miss)     # no heights: no limit
    assert flat[60, 20:81].all()
    with pytest.raises(ValueError, match="clear_below_m"):
        MappingConfig(clear_below_m=0.0)


def test_map_occlusion_stops_rays_at_cells_the_map_holds_occupied():
    """Two views see a wall (column 60, rows 40-80); a third sees only a phantom 2 m behind it and the
    floor behind it (a low-texture stretch of the same wall): with map occlusion they clear nothing
    behind the wall and the phantom is no hit."""
    sensor = (*centre(60, 20), 0.5)
    wall = np.array([[*centre(r, 60), z] for r in range(40, 81) for z in np.linspace(0.1, 1.0, 6)])
    phantom = np.array([[*centre(62, 100), 0.3]] * 6)
    floor_behind = np.array([[*centre(58, c), 0.0] for c in range(70, 90)])
    config = with_rules(occlusion_gap_m=0.25, min_points_per_cell=5, map_occlusion_p=0.8)
    results = {}
    for name, cfg in (("map", config), ("plain", with_rules(occlusion_gap_m=0.25, min_points_per_cell=5))):
        grid = OccupancyGrid(config=cfg)
        grid.update(wall, None, sensor)
        grid.update(wall, None, sensor)                     # two hits: P = 0.845 >= 0.8
        known, z = grid.known_occupied()
        if name == "map":
            assert known[40:81, 60].all() and known.sum() == 41
            np.testing.assert_allclose(z[50, 60], (0.1, 1.0), atol=1e-6)
        results[name] = (grid.update(np.vstack([phantom]), floor_behind, sensor), grid)
    (stats, grid), (_, plain) = results["map"], results["plain"]
    assert stats.hit_cells == 0                                       # the phantom lies behind the wall
    assert grid.unknown[62, 100] and grid.unknown[58, 61:90].all()   # nothing behind the wall cleared
    assert grid.occupied[40:81, 60].all()
    assert plain.occupied[62, 100] and plain.free[58, 70:90].all()   # without: phantom hit, floor cleared
    # update is apply(view_cells(..., known_occupied=grid.known_occupied())): the same cells
    again = OccupancyGrid(config=config)
    again.update(wall, None, sensor)
    again.update(wall, None, sensor)
    cells = view_cells(phantom, floor_behind, sensor, config=config, known_occupied=again.known_occupied())
    np.testing.assert_array_equal(cells.miss, view_cells(phantom, floor_behind, sensor, config=config,
                                                         known_occupied=grid.copy().known_occupied()).miss)
    assert len(cells.hit) == 0


def test_map_occlusion_keeps_a_wall_seen_under_a_known_table_top():
    """The map holds a table top (0.7 m, column 40); a later view sees a wall under it at column 80."""
    sensor = (*centre(60, 20), 0.5)
    table = np.array([[*centre(60, 40), z] for z in np.linspace(0.68, 0.72, 8)])
    wall = np.array([[*centre(60, 80), z] for z in np.linspace(0.05, 0.2, 8)])
    config = with_rules(occlusion_gap_m=0.25, min_points_per_cell=5, map_occlusion_p=0.8)
    grid = OccupancyGrid(config=config)
    grid.update(table, None, sensor)
    grid.update(table, None, sensor)
    loaded = OccupancyGrid(config=config, log_odds=grid.log_odds)     # a map read back has no heights
    assert grid.update(wall, None, sensor).hit_cells == 1 and grid.occupied[60, 80]
    assert loaded.update(wall, None, sensor).hit_cells == 0           # without heights the top hides the wall


def test_map_occlusion_bad_input():
    with pytest.raises(ValueError, match="map_occlusion_p"):
        MappingConfig(map_occlusion_p=0.3)
    with pytest.raises(ValueError, match="map_occlusion_p"):
        MappingConfig(map_occlusion_p=1.0)
    with pytest.raises(TypeError, match="overhang_shadow"):
        MappingConfig(overhang_shadow="yes")
    sensor = centre(60, 20)
    with pytest.raises(ValueError, match="known_occupied mask"):
        view_cells(None, None, sensor, known_occupied=(np.zeros((3, 3), bool), np.zeros((3, 3, 2))))
    with pytest.raises(ValueError, match="known_occupied z_range_m"):
        view_cells(None, None, sensor, known_occupied=(np.zeros(GridSpec().shape, bool), np.zeros((3, 3, 2))))
    with pytest.raises(TypeError, match="known_occupied"):
        view_cells(None, None, sensor, known_occupied=np.zeros(GridSpec().shape, bool))
    with pytest.raises(ValueError, match="p_min"):
        OccupancyGrid(config=PLAIN).known_occupied(1.5)


def _reduced_to_cells(points: np.ndarray, grid: GridSpec) -> np.ndarray:
    """Per cell the points a view's map depends on, in point order: the lowest and the highest (by z) and then
    the last point repeated, as many points as the cell held."""
    row, col = grid.cells_from_xy(points[:, :2])
    key = row * grid.shape[1] + col
    out = []
    for cell in np.unique(key):
        idx = np.flatnonzero(key == cell)
        if len(idx) >= 3:
            idx = [idx[np.argmin(points[idx, 2])], idx[np.argmax(points[idx, 2])]] + [idx[-1]] * (len(idx) - 2)
        out.append(points[idx])
    return np.concatenate(out)


def test_a_view_depends_on_its_points_only_through_their_cells():
    """The points are reduced to their cells before any ray is cast: a cloud with the same count, lowest and
    highest obstacle point and last point per cell gives the same hits, misses, heights and occluded cells,
    with the full stereo sensor model (support, range margin, see-through, occlusion, overhang)."""
    rng = np.random.default_rng(3)
    grid = GridSpec()
    k = 15000
    wall = np.column_stack([rng.uniform(1.0, 6.0, k), np.where(rng.random(k) < 0.5, 1.5, -1.5)
                            + rng.normal(0.0, 0.05, k), rng.uniform(0.05, 1.5, k)])
    table = np.column_stack([rng.uniform(3.0, 3.5, 2000), rng.uniform(-0.4, 0.4, 2000), rng.uniform(0.7, 0.75, 2000)])
    ghosts = np.column_stack([rng.uniform(1.0, 8.0, 300), rng.uniform(-1.4, 1.4, 300), rng.uniform(0.1, 1.0, 300)])
    obstacles = np.concatenate([wall, table, ghosts])
    floor = np.column_stack([rng.uniform(0.5, 9.0, k), rng.uniform(-1.4, 1.4, k), np.zeros(k)])
    sensor = (0.21, 0.03, 0.4)
    full = view_cells(obstacles, floor, sensor, grid=grid, baseline_focal_m_px=40.0)
    small = view_cells(_reduced_to_cells(obstacles, grid), _reduced_to_cells(floor, grid), sensor, grid=grid,
                       baseline_focal_m_px=40.0)
    assert len(_reduced_to_cells(obstacles, grid)) == len(obstacles)
    assert len({tuple(p) for p in _reduced_to_cells(obstacles, grid)}) < 0.4 * len(obstacles)
    for name in ("hit", "miss", "hit_z_m"):
        np.testing.assert_array_equal(getattr(small, name), getattr(full, name))
    assert small.occluded == full.occluded > 0 and len(full.hit) > 100 and len(full.miss) > 1000


def _layers_by_numpy(grid: GridSpec, config: MappingConfig, views) -> tuple[np.ndarray, np.ndarray]:
    """The height and drop layers of ``views`` ((obstacle, floor, drop, candidates (None), weak drop) point sets)
    by the rules of ``OccupancyGrid.add_layers``, per cell with numpy: heights by ``fmin.at`` / ``fmax.at`` (not
    of the weak points), votes (the drop points', the weak points', the views of weak votes and of floor points
    without a vote) by counts."""
    rows, cols = grid.shape
    heights = np.full((rows * cols, 2), np.nan, np.float32)
    votes = np.zeros((rows * cols, 4), np.int64)
    for view in views:
        counts = []
        for k, points in enumerate(view):
            p = np.empty((0, 3)) if points is None else np.asarray(points, np.float64)
            p = p[np.isfinite(p).all(axis=1)]
            r, c = grid.cells_from_xy(p[:, :2])
            inside = grid.inside(r, c)
            flat = r[inside] * cols + c[inside]
            if k < 3:
                z = p[inside, 2].astype(np.float32)
                np.fmin.at(heights[:, 0], flat, z)
                np.fmax.at(heights[:, 1], flat, z)
            counts.append(np.bincount(flat, minlength=rows * cols))
        if view[2] is None:
            continue
        for v, (count, most) in enumerate(((counts[2], config.drop_max_votes),
                                           (counts[4], max(config.drop_max_votes, config.drop_weak_views)))):
            voted = count >= config.drop_min_points
            votes[voted, v] = np.minimum(votes[voted, v] + 1, most)
            votes[(counts[1] >= config.drop_clear_points) & ~voted & (votes[:, v] > 0), v] -= 1
        if view[4] is not None:
            strong, weak = (counts[k] >= config.drop_min_points for k in (2, 4))
            votes[weak, 2] += 1
            votes[(counts[1] > 0) & ~strong & ~weak, 3] += 1
    return heights.reshape(rows, cols, 2), votes.reshape(rows, cols, 4)


def test_height_and_drop_layers_equal_a_per_cell_count_of_random_views():
    grid = GridSpec(width_m=3.0, height_m=2.0, resolution_m=0.1, origin_x_m=-0.5, origin_y_m=-1.0)
    config = MappingConfig(drop_min_points=2, drop_clear_points=4, drop_weak_views=4)
    rng, weak_rng = np.random.default_rng(3), np.random.default_rng(4)
    views = []
    for k in range(25):
        corner = rng.uniform([0.0, -0.5, -1.0], [0.7, 0.2, -1.0])      # the drop points in 0.3 m x 0.3 m of it
        sets = [rng.uniform(low, high, (n, 3)).astype(dtype)
                for low, high, n, dtype in (([-1.0, -1.5, -1.0], [3.0, 1.5, 1.0], 150, np.float32),
                                            ([0.0, -0.5, -0.05], [1.0, 0.5, 0.05], 600, np.float32),
                                            (corner, corner + [0.3, 0.3, 0.9], 60, np.float64))]
        sets.append(weak_rng.uniform(corner - 0.2, corner + [0.4, 0.4, 0.9], (90, 3)).astype(np.float32))
        sets[0][::13] = np.nan                                    # points without a measurement are skipped
        views.append((sets[0], sets[1], None if k % 6 == 5 else sets[2], None, sets[3]))
    occupancy = OccupancyGrid(grid, config=config)
    voted = [occupancy.add_layers(*view) for view in views]
    heights, votes = _layers_by_numpy(grid, config, views)
    np.testing.assert_array_equal(occupancy.heights_m, heights)
    np.testing.assert_array_equal(occupancy._drop_votes, votes)
    assert 0 < votes[..., 0].sum() and votes[..., 0].max() == config.drop_max_votes and voted[5] == 0
    assert votes[..., 1].max() == config.drop_weak_views and max(voted) > 0
    weak_only = (votes[..., 1] >= config.drop_weak_views) & (votes[..., 0] == 0)
    shared = (1 - config.drop_weak_share) * votes[..., 2] >= config.drop_weak_share * votes[..., 3]
    assert (weak_only & shared).any() and (occupancy.drop == ((votes[..., 0] > 0) | (weak_only & shared))).all()
    # a view's counts do not leak into the next: one drop point in a cell per view never votes
    single = OccupancyGrid(grid, config=config)
    for _ in range(5):
        single.add_layers(np.empty((0, 3)), np.empty((0, 3)), np.array([[0.05, 0.05, -0.5]]))
    assert not single.drop.any() and single.heights_m[10, 5, 0] == pytest.approx(-0.5)
