"""Drop-offs: worlds with drops and their truth, the drop test on exact and matched disparities, the height layer."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

from mrstereo.geometry import ObstacleConfig, detect_obstacles
from mrstereo.geometry.drops import DropConfig, find_drops
from mrstereo.mapping import GridSpec
from mrstereo.mapping.heights import HeightLayer, read_height_layer
from mrstereo.transforms import T_from_planar
from mrstereo.world import LABEL_FLOOR, drop_edges, floor_heights, random_world, render_stereo_frame
from mrstereo.world.randomize import DROP_RANGES, RAMP_RISER_M

LEDGE_SEED, RAMP_SEED = 0, 1        # tuning seeds: seed 0 ends in a ledge, seed 1 in a ramp down


@pytest.fixture(scope="module")
def ledge():
    return random_world(LEDGE_SEED, drops=True)


@pytest.fixture(scope="module")
def ramp():
    return random_world(RAMP_SEED, drops=True)


def _world_points(world, pose, result):
    T = T_from_planar(*pose)
    p = result.drop_points_robot
    return p @ T[:3, :3].T + T[:3, 3]


def test_drops_are_an_option_that_leaves_the_rest_of_the_world(ledge):
    plain = random_world(LEDGE_SEED)
    assert random_world(LEDGE_SEED, drops=False).scene == plain.scene
    assert "drops" not in plain.summary and ledge.summary["drops"]["end"]["kind"] == "ledge"
    np.testing.assert_array_equal(ledge.stereo.left.P, plain.stereo.left.P)
    assert ledge.sensors == plain.sensors and ledge.scene.lights == plain.scene.lights
    # the path is the plain world's, stopped 0.7 m before the edge
    x_e = ledge.summary["drops"]["end"]["x_m"]
    assert ledge.waypoints_xy[-1, 0] == pytest.approx(x_e - 0.7, abs=1e-3)
    np.testing.assert_array_equal(ledge.waypoints_xy[:-1], plain.waypoints_xy[:len(ledge.waypoints_xy) - 1])


def test_truth_of_a_ledge_holes_and_a_ramp(ledge, ramp):
    grid = GridSpec()
    for world in (ledge, ramp):
        drops = world.summary["drops"]
        height = floor_heights(world.scene, grid)
        edges = drop_edges(world.scene, grid)
        centres = grid.cell_centres()
        x, y = centres[..., 0], centres[..., 1]
        x_e = drops["end"]["x_m"]
        inside = np.abs(y) < world.scene.half_width_m - 0.05
        on_floor = inside & (x > 0.0) & (x < x_e - 0.1)
        holes = [p for p in drops["patches"] if p["kind"] in ("hole", "stairwell", "sunken", "kerb")]
        for p in holes:
            x0, x1, y0, y1 = p["rect_m"]
            in_patch = (x > x0 - 0.1) & (x < x1 + 0.1) & (y > y0 - 0.1) & (y < y1 + 0.1)
            on_floor &= ~in_patch
            cells = (x > x0) & (x < x1) & (y > y0) & (y < y1)
            expected = p["height_m"] if p["kind"] == "kerb" else -p["depth_m"]
            if p["kind"] != "stairwell":
                np.testing.assert_allclose(height[cells], expected, atol=1e-3)
            # a hole's rim is an edge all round (inside the corridor), a kerb's or a sunken step's nowhere
            rim = in_patch & ~cells & inside & (x > x0 - 0.05) & (x < x1 + 0.05) & (y > y0 - 0.05) & (y < y1 + 0.05)
            assert edges[rim].any() == (p["kind"] in ("hole", "stairwell"))
        assert np.all(height[on_floor] == 0.0) and not edges[on_floor].any()
        across = inside & (np.abs(x - x_e) < 0.5 * grid.resolution_m + 1e-9)
        if drops["end"]["kind"] == "ledge":
            assert edges[inside & (x < x_e) & (x > x_e - grid.resolution_m)].all()
            beyond = inside & (x > x_e + 0.05) & (x < world.scene.x_range_m[1])
            np.testing.assert_allclose(height[beyond], -drops["end"]["depth_m"], atol=1e-3)
        else:                                   # a ramp of 1 cm risers: no edge, down to its depth
            assert not edges[inside & (x > x_e - 0.5)].any()
            section = inside & (x > x_e) & (x < world.scene.x_range_m[1])
            assert np.nanmin(height[section]) == pytest.approx(-drops["end"]["depth_m"], abs=1e-3)
            row = grid.cells_from_xy(np.array([[0.0, 0.0]]))[0][0]
            along = height[row][(x[row] > x_e - 0.2) & (x[row] < world.scene.x_range_m[1])]
            assert along.min() < 0.0 and np.all(np.abs(np.diff(along)) <= RAMP_RISER_M + 1e-9)
        assert across.any()
    assert DROP_RANGES["kerb_m"][1] <= DropConfig().max_step_m
    assert all(b.label == LABEL_FLOOR for b in ledge.scene.boxes if b.max_m[2] <= 0.05 and b.min_m[2] < 0.0)


def _frame(world, pose):
    return render_stereo_frame(world.scene, world.stereo, pose=pose, sensors=world.sensors, supersample=1)


def test_exact_disparity_marks_the_ledge_and_not_the_ramp(ledge, ramp):
    for world, is_ledge in ((ledge, True), (ramp, False)):
        x_e = world.summary["drops"]["end"]["x_m"]
        pose = (float(world.waypoints_xy[-1, 0]), float(world.waypoints_xy[-1, 1]), 0.0)
        frame = _frame(world, pose)
        res = detect_obstacles(frame.disparity_px, world.stereo, config=ObstacleConfig(drops=DropConfig()))
        pts = _world_points(world, pose, res)
        if not is_ledge:
            assert len(pts) == 0, pts[:5]
            continue
        edge = pts[pts[:, 0] < x_e + 0.05]
        assert len(edge) > 100
        # on the edge: within 0.1 m before it (edge_reach_m), none on the floor nearer than that
        assert edge[:, 0].min() > x_e - 0.15 and edge[:, 0].max() < x_e + 0.05
        # the edge at floor level, the points below it (the ledge's face) at their height, none deeper than it
        depth = world.summary["drops"]["end"]["depth_m"]
        assert np.all(edge[:, 2] == 0.0)
        lower = pts[pts[:, 2] < 0.0]                 # the lower floor and the walls down to it
        assert len(lower) > 100 and np.all(lower[:, 0] > x_e - 0.01)
        assert lower[:, 2].min() < -0.5 and np.all(lower[:, 2] > -depth - 0.01)       # the ledge's face
        # the robot frame's obstacle points end with them at floor level; without the drop test they are not there
        at_floor = res.drop_points_robot.copy()
        at_floor[:, 2] = 0.0
        np.testing.assert_array_equal(res.obstacle_points_robot[-len(res.drop_points_robot):], at_floor)
        # the chain leaves out the rows above the horizon: the same drops and noise margin as the test on the whole
        # point image (a noisy disparity, so that the floor's residuals sampled at other rows would change them)
        from mrstereo.geometry.obstacles import first_floor_row
        noisy = frame.disparity_px + np.random.default_rng(5).normal(0.0, 0.3, frame.disparity_px.shape)
        chain = detect_obstacles(noisy.astype(np.float32), world.stereo, config=ObstacleConfig(drops=DropConfig()))
        assert first_floor_row(world.stereo, chain.ground) > 40
        whole = find_drops(chain.points_robot_image, chain.T_robot_from_cam,
                           world.stereo.baseline_m * world.stereo.focal_px, doffs_px=world.stereo.doffs_px)
        assert whole.disparity_sigma_px > 0.2 and len(whole.points_robot) > 100
        np.testing.assert_array_equal(whole.points_robot, chain.drop_points_robot)
        np.testing.assert_array_equal(whole.weak_points_robot, chain.drop_weak_points_robot)
        # the drop test's point image is written in the triangulation pass: with the camera below
        # min_obstacle_height_m it is the whole image, the listed points scattered
        from mrstereo.geometry import _kernels
        low = detect_obstacles(noisy.astype(np.float32), world.stereo,
                               config=ObstacleConfig(drops=DropConfig(), min_obstacle_height_m=1.0))
        scattered = np.empty((noisy.size, 3))
        _kernels.scatter_points(low.points_robot, low.pixels, scattered)
        assert np.isfinite(low.points_robot_image).all(axis=-1).sum() == len(low.points_robot) > 10000
        np.testing.assert_array_equal(low.points_robot_image, scattered.reshape(*noisy.shape, 3))
        off = detect_obstacles(frame.disparity_px, world.stereo, config=ObstacleConfig(drops=None))
        assert len(off.drop_points_robot) == 0
        assert len(off.obstacle_points_robot) == len(res.obstacle_points_robot) - len(res.drop_points_robot)


def test_the_robot_limits_decide_what_is_a_drop(ledge):
    depth = ledge.summary["drops"]["end"]["depth_m"]
    pose = (float(ledge.waypoints_xy[-1, 0]), float(ledge.waypoints_xy[-1, 1]), 0.0)
    res = detect_obstacles(_frame(ledge, pose).disparity_px, ledge.stereo, config=ObstacleConfig(drops=DropConfig()))
    assert len(res.drop_points_robot)
    # a robot that climbs more than the ledge is deep sees no drop
    config = ObstacleConfig(drops=DropConfig(max_step_m=depth + 0.1))
    h, w = res.obstacle_mask.shape
    image = res.points_robot_image
    bf = ledge.stereo.baseline_m * ledge.stereo.focal_px
    assert len(find_drops(image, res.T_robot_from_cam, bf, config=config.drops).points_robot) == 0
    # nor one that drives any slope when the lower floor is seen far from the edge... unless it is steep
    steep = find_drops(image, res.T_robot_from_cam, bf, config=DropConfig(max_slope_deg=89.0))
    assert len(steep.edge_points_robot) <= len(res.drop_points_robot)
    with pytest.raises(ValueError, match="max_slope_deg"):
        DropConfig(max_slope_deg=90.0)
    with pytest.raises(ValueError, match="max_step_m"):
        DropConfig(max_step_m=-0.1)
    with pytest.raises(TypeError, match="drops must be a DropConfig"):
        ObstacleConfig(drops=0.05)
    with pytest.raises(ValueError, match="points_robot_image"):
        find_drops(image[..., :2], res.T_robot_from_cam, bf)
    assert w == ledge.stereo.size[0] and h == ledge.stereo.size[1]


def _tilted_rig(h=240, w=320, f=200.0, height=0.5, tilt_deg=10.0):
    """Rays (H, W, 3) in the robot frame of a camera ``height`` m above the floor tilted down by ``tilt_deg``,
    its pose T_robot_from_cam, its ``b f`` (0.12 m baseline) and the rays' z in the camera (depth per metre)."""
    v, u = np.mgrid[0:h, 0:w].astype(float)
    tilt = math.radians(tilt_deg)
    ray_cam = np.stack([(u - w / 2) / f, (v - h / 2) / f, np.ones_like(u)], -1)
    # camera x right, y down, z forward -> robot x forward, y left, z up, tilted down by `tilt`
    R = np.array([[0, -math.sin(tilt), math.cos(tilt)], [-1, 0, 0], [0, -math.cos(tilt), -math.sin(tilt)]])
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, (0.0, 0.0, height)
    return ray_cam @ R.T, T, 0.12 * f


def _surface(rays, T, height_of, rng=None, bf=24.0, reach_m=6.0):
    """Points where the rays first meet the surface ``z = height_of(points)`` (marched in 2 mm steps), with a
    disparity error of 0.25 px (sigma) when ``rng`` is given (each point moved along its ray); NaN where no
    surface is met within ``reach_m`` horizontally."""
    t = T[:3, 3]
    flat = rays.reshape(-1, 3)
    out = np.full(flat.shape, np.nan)
    todo = flat[:, 2] < 0.0
    for s in np.arange(0.01, 20.0, 0.002):
        p = t + flat[todo] * s
        hit = p[:, 2] <= height_of(p)
        idx = np.nonzero(todo)[0]
        out[idx[hit]] = p[hit]
        todo[idx[hit | (np.hypot(p[:, 0], p[:, 1]) > reach_m)]] = False
        if not todo.any():
            break
    out = out.reshape(rays.shape)
    if rng is not None:
        depth = (out - t) @ T[:3, :3][:, 2]                       # camera z of each point
        noisy = depth + rng.normal(0, 1, depth.shape) * 0.25 * depth ** 2 / bf
        out = t + (out - t) * (noisy / depth)[..., None]
    return out


def test_a_flat_floor_has_no_drop():
    """A flat floor seen by a tilted camera (analytic points plus noise): nothing below it is a drop."""
    rng = np.random.default_rng(3)
    rays, T, bf = _tilted_rig()
    t = T[:3, 3]
    height = t[2]
    s = np.where(rays[..., 2] < -1e-6, height / -np.minimum(rays[..., 2], -1e-6), np.nan)
    points = t + rays * s[..., None]
    depth = s * (rays @ T[:3, :3])[..., 2]
    points[..., 2] += rng.normal(0, 1, depth.shape) * 0.25 * depth ** 2 / bf * height / np.maximum(depth, 1e-9)
    points[np.hypot(points[..., 0], points[..., 1]) > 6.0] = np.nan
    assert len(find_drops(points, T, bf).points_robot) == 0
    flat = points.copy()
    # the same floor ending 1.5 m ahead, 0.5 m down: its edge is found (no 10 degree slope reaches the lower
    # floor seen 3 m ahead); 3 m ahead the lower floor is seen 6 m ahead: a drivable slope could hide in between
    beyond = points[..., 0] > 1.5
    lower = t + rays * np.where(rays[..., 2] < 0, (height + 0.5) / -np.minimum(rays[..., 2], -1e-6), np.nan)[..., None]
    points[beyond] = lower[beyond]
    found = find_drops(points, T, bf)
    assert len(found.edge_points_robot) and np.all(np.abs(found.edge_points_robot[:, 0] - 1.5) < 0.15)
    assert np.count_nonzero(found.edge_columns) > 0.5 * points.shape[1]
    assert np.all(found.below_points_robot[:, 0] > 1.5)
    far = np.where((flat[..., 0] > 3.0)[..., None], t + rays * np.where(
        rays[..., 2] < 0, (height + 0.5) / -np.minimum(rays[..., 2], -1e-6), np.nan)[..., None], flat)
    far[np.hypot(far[..., 0], far[..., 1]) > 6.0] = np.nan
    assert len(find_drops(far, T, bf).edge_points_robot) == 0


def test_a_ledge_is_found_within_a_cell_of_where_it_is():
    """A floor ending 1.2 m ahead (straight across), 0.4 m above a lower floor, exact points: every edge mark
    lies within one 5 cm cell of the edge (between the last floor point and where the next sight line passes
    floor level), in nearly every column. (The points are exact: a margin for the matcher's noise, not the
    floor's, which is nil.)"""
    rays, T, bf = _tilted_rig(h=120, w=160, f=100.0)
    points = _surface(rays, T, lambda p: np.where(p[:, 0] < 1.2, 0.0, -0.4))
    found = find_drops(points, T, bf, config=DropConfig(noise_from_floor=False))
    x = found.edge_points_robot[:, 0]
    assert len(x) > 100 and np.all(np.abs(x - 1.2) < 0.05), (x.min(), x.max())
    assert np.all(found.edge_points_robot[:, 2] == 0.0)
    assert np.count_nonzero(found.edge_columns) > 0.5 * points.shape[1]     # (farther out a slope may hide)


@pytest.mark.parametrize("slope_deg, is_drop", [(6.0, False), (9.0, False), (30.0, True)])
def test_a_ramp_within_the_slope_limit_is_no_drop(slope_deg, is_drop):
    """A floor going down a ramp 1 m ahead (straight across) to 0.3 m lower, points with disparity noise: a
    ramp within ``max_slope_deg`` (10) has no drop mark, a 30 degree one has."""
    rng = np.random.default_rng(5)
    rays, T, bf = _tilted_rig(h=120, w=160, f=100.0)
    tan = math.tan(math.radians(slope_deg))
    points = _surface(rays, T, lambda p: -np.clip((p[:, 0] - 1.0) * tan, 0.0, 0.3), rng=rng, bf=bf)
    found = find_drops(points, T, bf)
    if is_drop:
        assert np.count_nonzero(found.edge_columns) > 0.5 * points.shape[1]
    else:
        assert len(found.points_robot) == 0, found.points_robot[:5]


def test_a_textureless_or_mismatched_patch_of_floor_is_no_drop():
    """A flat floor with a patch that has no points (texture-less) or whose points a mismatch put too far
    along their rays (below the floor, the floor seen again right after it): no drop; the same patch with no
    floor after it (a hole whose far side is not seen) is one."""
    rng = np.random.default_rng(7)
    rays, T, bf = _tilted_rig(h=120, w=160, f=100.0)
    floor = _surface(rays, T, lambda p: np.zeros(len(p)), rng=rng, bf=bf)
    r = np.hypot(floor[..., 0], floor[..., 1])
    patch = (r > 1.2) & (r < 1.5) & (np.abs(floor[..., 1]) < 0.4)
    holes = floor.copy()
    holes[patch] = np.nan
    assert len(find_drops(holes, T, bf).points_robot) == 0
    t = T[:3, 3]
    mismatched = floor.copy()
    mismatched[patch] = t + (floor[patch] - t) * 2.0              # twice too far: 0.5 m below the floor
    assert np.all(mismatched[patch][:, 2] < -0.4)
    assert len(find_drops(mismatched, T, bf).points_robot) == 0
    cut = mismatched.copy()
    cut[(r >= 1.5) & (np.abs(floor[..., 1]) < 0.4)] = np.nan       # nothing seen after the patch
    assert np.count_nonzero(find_drops(cut, T, bf).edge_columns) > 10


def test_points_below_the_floor_whose_floor_would_match_outside_the_right_image_are_no_drop():
    """At the image's left border the floor on a pixel's sight line may match outside the right image
    (``x - d_floor < 0``): no matcher finds it there, so a floor pixel matched too far (below the floor) is
    likely. A patch of floor matched twice too far with nothing seen after it is a drop in every column but the
    border's; the rig's disparity offset (``Z = b f / (d + doffs)``) moves the border."""
    rays, T, bf = _tilted_rig(h=120, w=160, f=100.0)
    floor = _surface(rays, T, lambda p: np.zeros(len(p)))
    t = T[:3, 3]
    r = np.hypot(floor[..., 0], floor[..., 1])
    patch = (r > 1.2) & (r < 1.5)
    points = floor.copy()
    points[patch] = t + (floor[patch] - t) * 2.0                   # 0.5 m below the floor
    points[r >= 1.5] = np.nan                                      # nothing seen after it
    d_floor = bf / ((floor - t) @ T[:3, 2])                        # the floor's disparity, doffs 0
    u = np.arange(floor.shape[1])
    for doffs in (0.0, -30.0):
        border = u < d_floor - doffs
        inside = patch.any(axis=0) & np.all(border | ~patch, axis=0)           # all the patch's pixels
        clear = patch.any(axis=0) & ~np.any(border & patch, axis=0)            # none of them
        assert inside.sum() >= 5 - doffs and clear.sum() >= 100 + doffs
        found = find_drops(points, T, bf, doffs_px=doffs)
        assert not found.edge_columns[inside].any() and np.all(found.edge_columns[clear] > 0)
        hidden = points[patch & border]                            # no lower point is a border pixel's
        assert len(hidden) and not (found.below_points_robot[:, None] == hidden[None]).all(-1).any()
    with pytest.raises(ValueError, match="doffs_px"):
        find_drops(points, T, bf, doffs_px=float("nan"))


def _layers_grid():
    from mrstereo.mapping import MappingConfig, OccupancyGrid

    grid = GridSpec(width_m=4.0, height_m=1.0, resolution_m=0.1, origin_x_m=0.0, origin_y_m=-0.5)
    return OccupancyGrid(grid, config=MappingConfig(footprint_radius_m=None))


def test_height_layer_keeps_the_lowest_and_highest_point_and_round_trips(tmp_path):
    occupancy = _layers_grid()
    grid = occupancy.grid
    occupancy.add_layers(np.array([[0.52, 0.01, 0.4], [9.0, 0.0, 1.0], [np.nan, 0.0, 0.0]]),
                         np.array([[0.55, 0.05, 0.01]]), np.array([[0.58, 0.09, -0.3]]))
    occupancy.add_layers(np.array([[0.51, 0.02, 0.6]]), np.empty((0, 3)))
    r, c = (int(v[0]) for v in grid.cells_from_xy(np.array([[0.55, 0.05]])))
    layer = HeightLayer.of(occupancy)
    assert layer.max_height_m[r, c] == pytest.approx(0.6) and layer.min_height_m[r, c] == pytest.approx(-0.3)
    assert np.isnan(layer.max_height_m).sum() == grid.shape[0] * grid.shape[1] - 1
    assert not layer.drop.any()                        # one drop point: fewer than drop_min_points
    files = layer.save(tmp_path / "heights")
    assert files["heights_png"].stat().st_size > 1000
    back = read_height_layer(tmp_path / "heights")
    assert back.grid == grid
    np.testing.assert_array_equal(back.min_height_m, layer.min_height_m)
    assert back.max_height_m.dtype == np.float32 and back.drop.dtype == np.bool_
    with pytest.raises(ValueError, match="points_world"):
        occupancy.add_layers(np.zeros((3, 2)), np.empty((0, 3)))
    with pytest.raises(ValueError, match="heights.yaml"):
        read_height_layer(tmp_path)
    with pytest.raises(ValueError, match="drop"):
        HeightLayer(grid, layer.max_height_m, layer.min_height_m, layer.drop[:, :3])


def test_a_drop_cell_stays_lethal_under_rays_and_is_cleared_only_by_floor_measured_in_it():
    occupancy = _layers_grid()
    grid = occupancy.grid
    edge = np.array([[2.05, 0.05, 0.0]] * 4)                            # 4 drop points in cell (x 2.0-2.1)
    r, c = (int(v[0]) for v in grid.cells_from_xy(edge[:1, :2]))
    assert occupancy.add_layers(np.empty((0, 3)), np.empty((0, 3)), edge) == 1
    assert occupancy.drop[r, c] and occupancy.occupied[r, c] and occupancy.drop.sum() == 1
    # later views see far beyond the edge: their rays cross the cell (misses) many times
    floor = np.array([[x, 0.05, 0.0] for x in np.linspace(2.5, 3.9, 30) for _ in range(6)])
    for _ in range(10):
        occupancy.update(None, floor, (0.2, 0.05, 0.5), layers=(np.empty((0, 3)), floor, None))
    assert occupancy.log_odds[r, c] < 0                                   # the log-odds alone say free
    assert occupancy.drop[r, c] and occupancy.occupied[r, c] and not occupancy.free[r, c]
    assert occupancy.to_ros_map().occupied[r, c]
    # floor measured in the cell itself: one vote off per view with enough floor points there
    on_cell = np.array([[2.05, 0.05, 0.0]] * occupancy.config.drop_clear_points)
    occupancy.add_layers(np.empty((0, 3)), on_cell, np.empty((0, 3)))
    assert not occupancy.drop[r, c] and occupancy.free[r, c]
    # votes add up to drop_max_votes; a view voting for the drop is not counted against it
    for _ in range(5):
        occupancy.add_layers(np.empty((0, 3)), on_cell, edge)
    assert occupancy._drop_votes[r, c, 0] == occupancy.config.drop_max_votes
    # the robot's footprint clears it (it stood there)
    occupancy.clear_disc((2.05, 0.05), 0.1)
    assert not occupancy.drop.any()


def test_the_drop_layer_survives_tiles_and_their_file(tmp_path):
    from mrstereo.mapping import MappingConfig
    from mrstereo.mapping.tiles import TiledOccupancyGrid

    tiles = TiledOccupancyGrid(0.1, config=MappingConfig(footprint_radius_m=None), view_reach_m=5.0, tile_cells=16)
    edge = np.array([[2.05, 0.05, 0.0]] * 4 + [[2.15, 0.05, -0.4]] * 3)
    floor = np.array([[x, 0.05, 0.0] for x in np.linspace(0.5, 1.9, 15) for _ in range(6)])
    tiles.update(edge, floor, (0.2, 0.05, 0.5), layers=(edge, floor, edge))
    dense = tiles.to_grid()
    r, c = (int(v[0]) for v in dense.grid.cells_from_xy(np.array([[2.15, 0.05]])))
    assert dense.drop[r, c] and dense.drop[r, c - 1] and dense.drop.sum() == 2
    assert dense.heights_m[r, c, 0] == pytest.approx(-0.4)
    tiles.save(tmp_path / "tiles.npz")
    back = TiledOccupancyGrid.load(tmp_path / "tiles.npz").to_grid()
    np.testing.assert_array_equal(back.drop, dense.drop)
    np.testing.assert_array_equal(back.heights_m, dense.heights_m)
    assert tiles.overview()[0][r, c] == 0                                 # occupied in the overview


def test_scan_command_reports_the_ledge_unless_told_not_to(ledge, tmp_path):
    """`mrstereo scan` on a matched frame 0.7 m before the ledge: returns at the edge, none without the test."""
    import cv2
    from click.testing import CliRunner

    from mrstereo.camera import write_stereo
    from mrstereo.cli import main
    from mrstereo.geometry.scan import read_scan_json

    pose = (float(ledge.waypoints_xy[-1, 0]), float(ledge.waypoints_xy[-1, 1]), 0.0)
    frame = render_stereo_frame(ledge.scene, ledge.stereo, pose=pose, sensors=ledge.sensors)
    cv2.imwrite(str(tmp_path / "l.png"), frame.left_rect)
    cv2.imwrite(str(tmp_path / "r.png"), frame.right_rect)
    write_stereo(tmp_path / "calib.yaml", ledge.stereo)
    x_e = ledge.summary["drops"]["end"]["x_m"]
    ranges = {}
    for name, extra in (("drops", ["--drops"]), ("none", ["--no-drops"])):
        out = tmp_path / f"{name}.json"
        result = CliRunner().invoke(main, ["scan", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--calib",
                                           str(tmp_path / "calib.yaml"), "--rectified", "-o", str(out), *extra])
        assert result.exit_code == 0, result.output
        ranges[name] = np.asarray(read_scan_json(out).ranges_m)
    ahead = np.isfinite(ranges["drops"]) & (ranges["drops"] < x_e - pose[0] + 0.1)
    assert ahead.sum() >= 5                                  # bearings that stop at the edge
    assert not np.any(np.isfinite(ranges["none"][ahead]) & (ranges["none"][ahead] < x_e - pose[0] + 0.1))
    bad = CliRunner().invoke(main, ["scan", str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--calib",
                                    str(tmp_path / "calib.yaml"), "-o", str(tmp_path / "x.json"), "--max-slope", "95"])
    assert bad.exit_code == 2 and "--max-slope" in bad.output


def test_map_marks_the_ledge_lethal_writes_the_height_layer_and_plan_stops_short_of_it(ledge, tmp_path):
    """`mrstereo map --drops` on two frames 0.7 m before the ledge: drop cells at the ledge in heights/drop.npy,
    occupied in map.pgm and magenta in map.png; `plan` across the ledge finds no way; `--no-drops` marks none."""
    import cv2
    from click.testing import CliRunner

    from mrstereo.camera import write_stereo
    from mrstereo.cli import main
    from mrstereo.mapping import read_ros_map

    pose = (float(ledge.waypoints_xy[-1, 0]), float(ledge.waypoints_xy[-1, 1]), 0.0)
    frame = render_stereo_frame(ledge.scene, ledge.stereo, pose=pose, sensors=ledge.sensors)
    for side, image in (("left", frame.left_rect), ("right", frame.right_rect)):
        (tmp_path / "rec" / side).mkdir(parents=True)
        for k in range(2):
            cv2.imwrite(str(tmp_path / "rec" / side / f"{k:06d}.png"), image)
    write_stereo(tmp_path / "calib.yaml", ledge.stereo)
    x_e = ledge.summary["drops"]["end"]["x_m"] - pose[0]       # the edge ahead of the robot (at the map's origin)
    layers = {}
    for flag in ("--drops", "--no-drops"):
        out = tmp_path / flag.strip("-")
        result = CliRunner().invoke(main, ["map", str(tmp_path / "rec"), "--calib", str(tmp_path / "calib.yaml"),
                                           "-o", str(out), "--quiet", flag, "--max-step", "0.05"])
        assert result.exit_code == 0, result.output
        layers[flag] = read_height_layer(out / "heights")
        assert (out / "heights" / "heights.png").stat().st_size > 1000
    drop, grid = layers["--drops"].drop, layers["--drops"].grid
    assert not layers["--no-drops"].drop.any()
    centres = grid.cell_centres()
    at_edge = drop & (np.abs(centres[..., 0] - x_e) < 0.3)
    assert at_edge.sum() >= 10 and (drop & (centres[..., 0] < x_e - 0.3)).sum() <= 0.05 * drop.sum()
    ros_map = read_ros_map(tmp_path / "drops" / "map.yaml")
    assert ros_map.occupied[drop].all()
    # the lower floor beyond the edge is seen below the floor: the height layer's lowest points there
    low = layers["--drops"].min_height_m
    assert np.nanmin(low[centres[..., 0] > x_e]) < -0.3
    # planning straight across the ledge, unknown cells allowed: no path, or one that never enters a drop cell
    result = CliRunner().invoke(main, ["plan", str(tmp_path / "drops" / "map.yaml"), "--start", "0,0", "--goal",
                                       f"{x_e + 0.8:.2f},0", "--unknown", "free", "-o", str(tmp_path / "p.json")])
    if result.exit_code == 0:
        import json

        path = np.array(json.loads((tmp_path / "p.json").read_text())["path_xy"])
        r, c = grid.cells_from_xy(path)
        assert not drop[r[grid.inside(r, c)], c[grid.inside(r, c)]].any()
    else:                                   # (the console script prints it as "mrstereo: error: no path ...")
        assert isinstance(result.exception, RuntimeError) and "no path" in str(result.exception), result.output


def test_drops_need_a_randomized_world(tmp_path):
    from mrstereo.world import write_synthetic_dataset

    with pytest.raises(ValueError, match="drops applies to a randomized world"):
        write_synthetic_dataset(tmp_path / "x", drops=True, progress=False)
    assert not (tmp_path / "x").exists()


def _two_frames(surface, rng):
    """Frame k-1 at x = 0 sees the floor only up to 1.35 m (what lies beyond it unmatched); frame k at x = 0.5
    sees nothing before 1.4 m (the floor there unmatched, as at the near end of the view) and ``surface`` from
    there on. Both in the world frame (the robot frame of frame k-1), with frame k's drop test."""
    rays, T, bf = _tilted_rig(h=120, w=160, f=100.0)
    before = _surface(rays, T, lambda p: np.zeros(len(p)), rng=rng, bf=bf)
    before[before[..., 0] > 1.35] = np.nan
    shift = np.array([0.5, 0.0, 0.0])
    after = _surface(rays, T, lambda p: surface(p + shift), rng=rng, bf=bf, reach_m=2.0)
    after[after[..., 0] + 0.5 < 1.4] = np.nan
    found = find_drops(after, T, bf)
    floor_k = after[np.abs(after[..., 2]) < 0.05] + shift
    move = T_from_planar(0.5, 0.0, 0.0)
    from mrstereo.geometry.drops import transform_candidates

    return (before[np.isfinite(before[..., 2])], found, floor_k, transform_candidates(move, found.candidates_robot),
            found.points_robot + shift)


def _map_of(frames):
    from mrstereo.mapping import MappingConfig, OccupancyGrid

    grid = GridSpec(width_m=4.0, height_m=3.0, resolution_m=0.05, origin_x_m=0.0, origin_y_m=-1.5)
    occupancy = OccupancyGrid(grid, config=MappingConfig(footprint_radius_m=None))
    for floor, drops, candidates in frames:
        occupancy.add_layers(np.empty((0, 3)), floor, drops, candidates)
    return occupancy


def test_the_map_confirms_an_edge_seen_only_at_the_near_end_of_the_view_with_floor_it_saw_before():
    """A ledge 0.2 m down 0.9 m ahead of frame k, the floor before it unmatched in frame k: one frame cannot
    tell it from a ramp starting out of view (no drop mark, only candidates), and a map of frame k alone marks
    nothing; floor measured up to it in frame k-1 confirms it: frame k makes its edge lethal, within a cell of
    where it is (and the lower floor's deepest points past it). A drivable ramp (8 degrees) seen the same way
    (points with disparity noise) stays free."""
    ledge = lambda p: np.where(p[:, 0] < 1.4, 0.0, -0.2)                          # noqa: E731
    floor_before, found, floor_k, candidates, drop_points = _two_frames(ledge, None)     # exact points
    assert len(found.edge_points_robot) == 0 and len(found.candidates_robot) > 20
    alone = _map_of([(floor_k, drop_points, candidates)])
    assert not alone.drop.any()
    occupancy = _map_of([(floor_before, np.empty((0, 3)), None), (floor_k, drop_points, candidates)])
    assert not _map_of([(floor_before, np.empty((0, 3)), None)]).drop.any()
    drop = occupancy.drop
    x = occupancy.grid.cell_centres()[..., 0][drop]
    assert np.sum(np.abs(x - 1.4) <= 0.1) >= 10 and np.all(x > 1.3), x      # the edge, and the lower floor past it
    assert np.all(occupancy.occupied[drop])
    ramp = lambda p: -np.clip((p[:, 0] - 1.4) * math.tan(math.radians(8.0)), 0.0, 0.3)   # noqa: E731
    floor_before, found, floor_k, candidates, drop_points = _two_frames(ramp, np.random.default_rng(11))
    occupancy = _map_of([(floor_before, np.empty((0, 3)), None), (floor_k, drop_points, candidates)])
    assert not occupancy.drop.any()


def test_a_candidate_is_confirmed_only_by_floor_above_any_drivable_slope_and_not_under_measured_floor():
    """Hand-made candidates: the edge E at x = 1.4, the run's point q 0.3 m further at ``z_q``; the floor the
    map measured before E confirms it when it lies higher than a 10 degree slope from q reaches (a lower
    floor 0.25 m down: yes; a floor 0.05 m down at 1.3 m, the top of a ramp: no), floor measured between E
    and q rejects it (its sight line would pass under that floor: a mismatch)."""
    tan = math.tan(math.radians(10.0))

    def candidate(zq):
        c0 = zq + 0.01 + 0.05                   # its noise and the robot's step
        return np.array([[1.3, 0.0, 1.4, 0.0, 1.7, 0.0, zq, c0, tan, 0.0, 0.3]])

    floor = np.array([[x, 0.0, z] for x in np.arange(0.6, 1.38, 0.02) for z in (0.0, 0.005)])
    occupancy = _map_of([(floor, None, None), (np.empty((0, 3)), np.empty((0, 3)), candidate(-0.25))])
    assert occupancy.drop[:, (occupancy.grid.cell_centres()[0, :, 0] > 1.29) &
                          (occupancy.grid.cell_centres()[0, :, 0] < 1.41)].any()
    # a ramp: the floor before E measured lower and lower toward it (5 cm down at 1.3 m), q 0.1 m down
    ramp = floor.copy()
    ramp[:, 2] -= np.clip(ramp[:, 0] - 1.0, 0.0, None) * (0.05 / 0.3)
    assert not _map_of([(ramp, None, None), (np.empty((0, 3)), np.empty((0, 3)), candidate(-0.1))]).drop.any()
    # floor measured beyond E, before q: a mismatch
    beyond = np.concatenate([floor, [[1.55, 0.0, 0.0]] * 3])
    assert not _map_of([(beyond, None, None), (np.empty((0, 3)), np.empty((0, 3)), candidate(-0.25))]).drop.any()
    # no floor before E (none measured): nothing
    assert not _map_of([(np.empty((0, 3)), np.empty((0, 3)), candidate(-0.25))]).drop.any()


def test_a_floor_without_disparity_is_unknown_not_a_drop_without_the_robot_floor():
    """A floor that gives no disparity but for a patch matched three times too far (1 m below the floor,
    nothing measured around it): judged against the floor under the robot it is a drop; with ``robot_floor=False`` it
    is only a candidate, and a map that never measured that floor marks nothing (unknown)."""
    rays, T, bf = _tilted_rig(h=120, w=160, f=100.0)
    floor = _surface(rays, T, lambda p: np.zeros(len(p)))
    r = np.hypot(floor[..., 0], floor[..., 1])
    patch = (r > 0.8) & (r < 1.0) & (np.abs(floor[..., 1]) < 0.4)
    t = T[:3, 3]
    points = np.full(floor.shape, np.nan)
    points[patch] = t + (floor[patch] - t) * 3.0
    assert np.count_nonzero(find_drops(points, T, bf).edge_columns) > 10
    found = find_drops(points, T, bf, config=DropConfig(robot_floor=False))
    assert len(found.points_robot) == 0 and len(found.candidates_robot) > 10
    assert not _map_of([(np.empty((0, 3)), found.points_robot, found.candidates_robot)]).drop.any()
    with pytest.raises(TypeError, match="robot_floor"):
        DropConfig(robot_floor=1)


def test_an_observation_keeps_its_drop_candidates_through_its_file(tmp_path):
    """A frame's observation saved by a batch run and loaded back keeps its drop candidates, so the map fused
    from files confirms the same drops as the live one; one without keeps none."""
    from dataclasses import replace

    from mrstereo.mapping.fusion import FrameObservation
    from mrstereo.mapping.observations import load_observation, save_observation

    candidates = np.arange(22, dtype=np.float32).reshape(2, 11)
    obs = FrameObservation(index=3, pose=(1.0, 2.0, 0.5), pan_rad=0.0, obstacle_points_world=np.zeros((1, 3)),
                           floor_points_world=np.ones((2, 3)), n_valid_disparity=9, ground_message="m",
                           drop_points_world=np.full((1, 3), -0.3, np.float32), drop_candidates_world=candidates)
    for name, value in (("with", obs), ("without", replace(obs, drop_candidates_world=None))):
        save_observation(tmp_path / f"{name}.obs.npz", value)
    np.testing.assert_array_equal(load_observation(tmp_path / "with.obs.npz").layers[3], candidates)
    assert load_observation(tmp_path / "without.obs.npz").drop_candidates_world is None


def _ledge_column(depth_m=0.2, step_m=0.05):
    """One image column (12, 1, 3) seen from a camera 0.5 m up: floor from 0.8 to 1.2 m, then three points of a
    lower floor ``depth_m`` down from 1.7 m (past the ledge's sight line), and the disparity sigma [px] that
    puts that floor 1.5 combined sigma (of the last floor point's and the first lower point's height noise)
    below the floor and a step: the drop test's margin ``sqrt(sigma_a^2 + sigma_q^2)`` (with ``max_slope_deg``
    0, ``b f`` = 20 m px)."""
    x = np.concatenate([np.arange(0.8, 1.201, 0.05), [1.7, 1.72, 1.74]])
    z = np.where(x < 1.5, 0.0, -depth_m)
    column = np.stack([x, np.zeros_like(x), z], -1)[::-1, None, :]      # row 0 the farthest (image top)
    T = np.eye(4)
    T[2, 3] = 0.5
    per_m2 = [abs(zz - 0.5) * math.sqrt(xx ** 2 + (zz - 0.5) ** 2) for xx, zz in ((1.2, 0.0), (1.7, -depth_m))]
    sigma_px = (depth_m - step_m) / 1.5 / math.hypot(*per_m2) * 20.0
    return column, T, sigma_px


def test_a_drop_within_the_noise_margin_is_weak_not_strong():
    """A lower floor 1.5 sigma beyond the step: no drop with the 3-sigma margin, a weak one with 1 sigma (its
    edge from the last floor point to where the sight line passes floor level, its three points), none with
    2 sigma; the strong result is the same with the weak test on or off (one pass)."""
    column, T, sigma_px = _ledge_column()
    config = DropConfig(max_slope_deg=0.0, disparity_sigma_px=sigma_px, weak_n_sigma=1.0)
    found = find_drops(column, T, 20.0, config=config)
    assert len(found.points_robot) == 0 and len(found.candidates_robot) == 0
    weak = found.weak_points_robot
    edge, below = weak[weak[:, 2] == 0.0], weak[weak[:, 2] < 0.0]
    e = 1.7 * 0.5 / 0.7                                                  # the sight line to (1.7, -0.2) at z = 0
    assert len(edge) >= 2 and np.all((edge[:, 0] >= 1.2 - 1e-9) & (edge[:, 0] <= e + 1e-9)), edge
    np.testing.assert_allclose(below, [[1.7, 0.0, -0.2], [1.72, 0.0, -0.2], [1.74, 0.0, -0.2]])
    assert len(find_drops(column, T, 20.0, config=replace(config, weak_n_sigma=2.0)).weak_points_robot) == 0
    assert len(find_drops(column, T, 20.0, config=replace(config, weak_n_sigma=None)).weak_points_robot) == 0
    deep = find_drops(column, T, 20.0, config=replace(config, disparity_sigma_px=sigma_px / 2.5))   # 3.75 sigma
    assert len(deep.below_points_robot) == 3 and len(deep.edge_points_robot) >= 2
    n = len(deep.points_robot)
    np.testing.assert_array_equal(deep.weak_points_robot[:n], deep.points_robot)       # a drop by both margins
    # then where the sight lines to its lower points pass floor level: no floor there
    np.testing.assert_allclose(deep.weak_points_robot[n:], [[x * 0.5 / 0.7, 0.0, 0.0] for x in (1.7, 1.72, 1.74)])
    # noisy surfaces (a ledge, a ramp, a hole): the same strong result with or without the weak test
    rng = np.random.default_rng(13)
    rays, T, bf = _tilted_rig(h=120, w=160, f=100.0)
    for height_of in (lambda p: np.where(p[:, 0] < 1.2, 0.0, -0.15),
                      lambda p: -np.clip((p[:, 0] - 1.0) * 0.3, 0.0, 0.3),
                      lambda p: np.where(np.abs(p[:, 0] - 1.5) < 0.2, -0.3, 0.0)):
        points = _surface(rays, T, height_of, rng=rng, bf=bf)
        a, b = (find_drops(points, T, bf, config=DropConfig(weak_n_sigma=w)) for w in (1.0, None))
        for name in ("edge_points_robot", "below_points_robot", "edge_columns", "candidates_robot"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
        assert len(a.weak_points_robot) >= len(a.points_robot) and len(b.weak_points_robot) == 0
    with pytest.raises(ValueError, match="weak_n_sigma"):
        DropConfig(weak_n_sigma=-1.0)


def test_weak_points_of_two_views_make_a_cell_lethal_one_view_does_not_and_floor_takes_a_vote_back():
    occupancy = _layers_grid()
    grid = occupancy.grid
    weak = np.array([[2.05, 0.05, 0.0]] * 3 + [[2.35, 0.05, -0.3]] * 2)   # 3 points in one cell, 2 in another
    r, c = (int(v[0]) for v in grid.cells_from_xy(weak[:1, :2]))
    none = np.empty((0, 3))
    occupancy.add_layers(none, none, none, None, weak)
    assert not occupancy.drop.any() and occupancy._drop_votes[r, c, 1] == 1
    assert np.isnan(occupancy.heights_m).all()                            # weak points widen no height
    occupancy.add_layers(none, none, none, None, weak)
    assert occupancy.drop[r, c] and occupancy.occupied[r, c] and occupancy.drop.sum() == 1
    assert occupancy._drop_votes[..., 0].sum() == 0                       # no vote of the drop test itself
    copy = occupancy.copy()
    # a view with its own weak vote there: its floor points do not vote against it
    on_cell = np.array([[2.05, 0.05, 0.0]] * occupancy.config.drop_clear_points)
    occupancy.add_layers(none, on_cell, none, None, weak)
    assert occupancy._drop_votes[r, c, 1] == occupancy.config.drop_max_votes
    for votes in (2, 1):                                                  # floor measured in the cell, no weak vote
        occupancy.add_layers(none, on_cell, none, None, none)
        assert occupancy._drop_votes[r, c, 1] == votes
    assert not occupancy.drop[r, c]
    assert copy.drop[r, c]                                                # (a copy keeps its own votes)
    # without the drop test (no drop points) floor takes no vote back; the footprint clears them
    copy.add_layers(none, on_cell, None, None, None)
    assert copy.drop[r, c]
    copy.clear_disc((2.05, 0.05), 0.1)
    assert not copy.drop.any()
    # one view is enough with drop_weak_views=1
    from mrstereo.mapping import MappingConfig, OccupancyGrid

    one = OccupancyGrid(grid, config=MappingConfig(footprint_radius_m=None, drop_weak_views=1))
    one.add_layers(none, none, none, None, weak)
    assert one.drop[r, c] and one.drop.sum() == 1
    with pytest.raises(ValueError, match="drop_weak_views"):
        MappingConfig(drop_weak_views=0)


def test_weak_votes_count_where_they_are_a_share_of_the_views_that_put_weak_votes_or_floor_there():
    """Weak votes from two views make a cell lethal while they are at least ``drop_weak_share`` of the views
    that put weak votes or floor points (no vote) there: far floor's noise gives a weak vote in a few of the many
    views that see it, however many frames a drive gives. A frame without weak points (a robot standing still)
    counts no view."""
    from mrstereo.mapping import MappingConfig, OccupancyGrid

    occupancy = _layers_grid()
    share = occupancy.config.drop_weak_share
    weak = np.array([[2.05, 0.05, 0.0]] * 3)
    floor = weak[:1]                                  # one floor point: fewer than drop_clear_points, no take-back
    r, c = (int(v[0]) for v in occupancy.grid.cells_from_xy(weak[:1, :2]))
    none = np.empty((0, 3))
    for _ in range(2):
        occupancy.add_layers(none, floor, none, None, weak)          # a view with a weak vote: no floor view
    assert occupancy.drop[r, c] and tuple(occupancy._drop_votes[r, c, 2:]) == (2, 0)
    copy = occupancy.copy()
    floor_views = 0
    while occupancy.drop[r, c]:
        occupancy.add_layers(none, floor, none, None, none)
        floor_views += 1
    assert floor_views == int(2 * (1 - share) / share) + 1 == 7 and occupancy._drop_votes[r, c, 1] == 2
    occupancy.add_layers(none, floor, none, None, weak)              # a third weak view: lethal again
    assert occupancy.drop[r, c] and tuple(occupancy._drop_votes[r, c, 2:]) == (3, 7)
    for _ in range(10):                                             # frames whose weak points were left out
        copy.add_layers(none, floor, none, None, None)
    assert copy.drop[r, c] and tuple(copy._drop_votes[r, c, 2:]) == (2, 0)
    off = OccupancyGrid(occupancy.grid, config=MappingConfig(footprint_radius_m=None, drop_weak_share=0.0))
    for views in (weak, weak) + (none,) * 20:
        off.add_layers(none, floor, none, None, views)
    assert off.drop[r, c]
    for bad in (1.0, -0.1, float("nan")):
        with pytest.raises(ValueError, match="drop_weak_share"):
            MappingConfig(drop_weak_share=bad)


def test_the_weak_votes_survive_tiles_their_file_and_an_observation_file(tmp_path):
    from mrstereo.mapping import MappingConfig
    from mrstereo.mapping.fusion import FrameObservation
    from mrstereo.mapping.observations import load_observation, save_observation
    from mrstereo.mapping.tiles import TiledOccupancyGrid

    tiles = TiledOccupancyGrid(0.1, config=MappingConfig(footprint_radius_m=None), view_reach_m=5.0, tile_cells=16)
    weak = np.array([[2.05, 0.05, 0.0]] * 4, np.float32)
    floor = np.array([[x, 0.05, 0.0] for x in np.linspace(0.5, 1.9, 15) for _ in range(6)], np.float32)
    obs = FrameObservation(index=0, pose=(0.2, 0.05, 0.0), pan_rad=0.0, obstacle_points_world=np.empty((0, 3)),
                           floor_points_world=floor, n_valid_disparity=9, ground_message="m",
                           drop_points_world=np.empty((0, 3), np.float32), drop_weak_points_world=weak)
    save_observation(tmp_path / "0.obs.npz", obs)
    back = load_observation(tmp_path / "0.obs.npz")
    np.testing.assert_array_equal(back.layers[4], weak)
    for _ in range(2):
        tiles.update(back.obstacle_points_world, back.floor_points_world, (0.2, 0.05, 0.5), layers=back.layers)
    dense = tiles.to_grid()
    r, c = (int(v[0]) for v in dense.grid.cells_from_xy(weak[:1, :2]))
    assert dense.drop[r, c] and dense.drop.sum() == 1
    tiles.save(tmp_path / "tiles.npz")
    loaded = TiledOccupancyGrid.load(tmp_path / "tiles.npz")
    np.testing.assert_array_equal(loaded.to_grid().drop, dense.drop)
    assert loaded.overview()[0][r, c] == 0                                # occupied in the overview
    assert load_observation(tmp_path / "0.obs.npz").drop_candidates_world is None


def test_a_tiles_file_written_before_the_weak_votes_loads_with_none(tmp_path):
    """A tiles file whose drop layers are (T, T) (the votes only, as written before the weak votes) loads: the
    same votes, no weak votes."""
    from mrstereo.mapping import MappingConfig
    from mrstereo.mapping.tiles import TiledOccupancyGrid

    tiles = TiledOccupancyGrid(0.1, config=MappingConfig(footprint_radius_m=None), view_reach_m=5.0, tile_cells=16)
    edge = np.array([[2.05, 0.05, 0.0]] * 4)
    weak = np.array([[1.05, 0.05, 0.0]] * 4)
    for _ in range(2):
        tiles.update(edge, np.empty((0, 3)), (0.2, 0.05, 0.5), layers=(edge, None, edge, None, weak))
    tiles.save(tmp_path / "new.npz")
    with np.load(tmp_path / "new.npz") as data:
        old = {k: data[k][..., 0] if k.endswith("_drop") else data[k] for k in data.files}
    assert sum(v.sum() for k, v in old.items() if k.endswith("_drop")) == 2          # the edge's two votes
    np.savez_compressed(tmp_path / "old.npz", **old)
    new = TiledOccupancyGrid.load(tmp_path / "new.npz").to_grid()
    back = TiledOccupancyGrid.load(tmp_path / "old.npz").to_grid(new.grid)
    assert new.drop.sum() == 2 and back.drop.sum() == 1                      # the weak-vote cell is gone
    np.testing.assert_array_equal(back._drop_votes[..., 0], new._drop_votes[..., 0])
    assert not back._drop_votes[..., 1].any()


def test_weak_points_of_a_robot_standing_still_are_one_view():
    """Frames from the same pose and pan (a robot standing still sees the same mismatches again) give one weak
    vote, however many; a turn of the camera (another pan) or a move of a cell makes another view."""
    from mrstereo.mapping import MappingConfig
    from mrstereo.mapping.fusion import FrameObservation, fuse

    grid = GridSpec(width_m=4.0, height_m=1.0, resolution_m=0.1, origin_x_m=0.0, origin_y_m=-0.5)
    weak = np.array([[2.05, 0.05, 0.0]] * 4, np.float32)

    def frame(k, pose, pan):
        return FrameObservation(index=k, pose=pose, pan_rad=pan, obstacle_points_world=np.empty((0, 3)),
                                floor_points_world=np.empty((0, 3)), n_valid_disparity=1, ground_message="m",
                                drop_points_world=np.empty((0, 3), np.float32), drop_weak_points_world=weak)

    config = MappingConfig(footprint_radius_m=None)
    r, c = (int(v[0]) for v in grid.cells_from_xy(weak[:1, :2]))
    still = fuse([frame(k, (0.5, 0.0, 0.0), 0.0) for k in range(5)], grid=grid, config=config)
    assert not still.drop.any() and still._drop_votes[r, c, 1] == 1
    for second in (frame(1, (0.5, 0.0, 0.0), 0.1), frame(1, (0.62, 0.0, 0.0), 0.0)):
        two = fuse([frame(0, (0.5, 0.0, 0.0), 0.0), frame(1, (0.5, 0.0, 0.0), 0.0), second], grid=grid,
                   config=config)
        assert two.drop[r, c] and two.drop.sum() == 1


def _column(x, z):
    """One image column (N, 1, 3) of points at ``x`` (forward) and heights ``z``, given from the image's bottom
    (the nearest) up, seen by a camera 0.5 m up; its pose. The drop test with exact points (``n_sigma`` 0)."""
    column = np.stack([x, np.zeros_like(x), z], -1)[::-1, None, :]      # row 0 the farthest (image top)
    T = np.eye(4)
    T[2, 3] = 0.5
    return column, T, DropConfig(n_sigma=0.0, weak_n_sigma=None)


def test_a_far_wall_whose_points_lean_a_hair_nearer_than_the_run_is_no_floor_in_between():
    """Floor to 1.2 m, a ledge 0.3 m down, its far wall at 2 m rising through floor level and leaning toward
    the camera by 1e-5 m a point (its points at floor level a hair nearer than the run's first one): the wall
    is no floor between the sight line's crossing of floor level (1.25 m) and the run, the drop is found,
    its edge between the last floor point and that crossing; a floor patch matched too far stays a mismatch."""
    floor = np.arange(0.8, 1.201, 0.05)
    wall_z = np.arange(-0.3, 0.101, 0.02)
    x = np.concatenate([floor, 2.0 - 1e-5 * np.arange(len(wall_z))])
    z = np.concatenate([np.zeros_like(floor), wall_z])
    column, T, config = _column(x, z)
    found = find_drops(column, T, 20.0, config=config)
    edge = found.edge_points_robot
    assert len(edge) >= 2 and np.all((edge[:, 0] >= 1.2 - 1e-9) & (edge[:, 0] <= 1.25 + 1e-9)), edge
    assert np.all(found.below_points_robot[:, 0] > 1.99) and found.edge_columns[0] == 1
    # floor matched too far (0.3 m down on the sight lines of 1.3-1.4 m), the true floor after it from 1.45 m
    near = np.arange(0.8, 1.251, 0.05)
    true = np.array([1.3, 1.35, 1.4])
    far = np.arange(1.45, 2.0, 0.05)
    x = np.concatenate([near, true * 0.8 / 0.5, far])
    z = np.concatenate([np.zeros_like(near), np.full(3, -0.3), np.zeros_like(far)])
    column, T, config = _column(x, z)
    assert len(find_drops(column, T, 20.0, config=config).points_robot) == 0


def test_a_drivable_ramp_ending_at_a_rising_face_is_no_drop_a_hole_is():
    """Floor to 1.2 m, an 8 degree ramp down to 2.15 m, a face rising there back to floor level and floor
    after it: the run below the floor is entered within a step of the last floor point (down the ramp), the
    face is a step up, not a drop at the ramp's start. A hole 0.4 m wide behind a rim (its far wall seen from
    0.115 m down, within a step and a 10 degree slope of the rim) is one, found by the face rule."""
    tan = math.tan(math.radians(8.0))
    floor = np.arange(0.8, 1.201, 0.05)
    ramp = np.array([1.3, 1.5, 1.7, 1.9, 2.1])
    face_z = np.arange(-0.12, 0.001, 0.02)
    after = np.arange(2.2, 2.61, 0.05)
    x = np.concatenate([floor, ramp, np.full(len(face_z), 2.15), after])
    z = np.concatenate([np.zeros_like(floor), -(ramp - 1.2) * tan, face_z, np.zeros_like(after)])
    column, T, config = _column(x, z)
    found = find_drops(column, T, 20.0, config=config)
    assert len(found.points_robot) == 0 and len(found.candidates_robot) == 0
    floor = np.arange(0.8, 1.501, 0.05)
    face_z = np.arange(-0.115, 0.001, 0.01)
    after = np.arange(1.95, 2.41, 0.05)
    x = np.concatenate([floor, np.full(len(face_z), 1.9), after])
    z = np.concatenate([np.zeros_like(floor), face_z, np.zeros_like(after)])
    column, T, config = _column(x, z)
    found = find_drops(column, T, 20.0, config=config)
    assert found.edge_columns[0] == 1
    e = 1.9 * 0.5 / 0.615                                              # the sight line to (1.9, -0.115) at z = 0
    edge = found.edge_points_robot[found.edge_points_robot[:, 0] < 1.9]
    assert len(edge) >= 2 and np.all((edge[:, 0] >= 1.5 - 1e-9) & (edge[:, 0] <= e + 1e-9)), edge


def test_two_views_of_a_hole_make_its_inside_lethal_where_their_sight_lines_pass_floor_level():
    """A stairwell 1.4 m long, 1 m deep, 1 m ahead (exact points, two views 0.2 m apart; the rim hides its
    bottom): where the sight lines to its far wall pass floor level (weak points) no floor lies, so its inside is
    lethal after two views from the near rim on, up to where the sight line to the far wall's point that lies a
    step, its 3-sigma noise and a 10 degree slope (from there) below the floor passes floor level (1.6 m, worked
    out by hand for the first view) -- without them only the near rim and the far wall's foot are -- and no
    floor cell before or after it is."""
    from mrstereo.mapping import MappingConfig, OccupancyGrid

    rays, T, bf = _tilted_rig()
    grid = GridSpec(width_m=4.0, height_m=3.0, resolution_m=0.05, origin_x_m=0.0, origin_y_m=-1.5)
    maps = {k: OccupancyGrid(grid, config=MappingConfig(footprint_radius_m=None)) for k in ("with", "without")}
    none = np.empty((0, 3))
    t = T[:3, 3]
    down = np.where(rays[..., 2] < 0, -1.0 / np.minimum(rays[..., 2], -1e-9), np.nan)[..., None]
    for x0 in (0.0, 0.2):                    # the floor, else the bottom, else the far wall (x = 2.4 m)
        near, far = 1.0 - x0, 2.4 - x0
        points = t + rays * (t[2] * down)
        bottom = t + rays * ((t[2] + 1.0) * down)
        wall = t + rays * ((far - t[0]) / rays[..., :1])
        in_hole = (points[..., 0] > near) & (points[..., 0] < far)
        points[in_hole] = np.where((bottom[..., 0] < far)[..., None], bottom, wall)[in_hole]
        points[np.hypot(points[..., 0], points[..., 1]) > 3.0] = np.nan
        found = find_drops(points, T, bf)
        shift = np.array([x0, 0.0, 0.0])
        floor = points[np.abs(points[..., 2]) < 0.01] + shift
        for key, weak in (("with", found.weak_points_robot), ("without", found.points_robot)):
            maps[key].add_layers(none, floor, found.points_robot + shift, None, weak + shift)
    centres = grid.cell_centres()
    x, y = centres[..., 0], centres[..., 1]
    inside = (x > 1.05) & (x < 1.55) & (np.abs(y) < 0.25)
    floor_cells = ((x < 0.9) | (x > 2.5)) & (np.abs(y) < 0.25) & (x < 2.9)
    assert maps["with"].drop[inside].all() and not maps["without"].drop[inside].any()
    assert not maps["with"].drop[floor_cells].any()


@pytest.mark.parametrize("side", [-1.0, 1.0])
def test_the_side_of_a_hole_seen_along_it_is_marked_where_the_matcher_carried_the_floor_past_it(side):
    """A hole 1 m deep beside the view (its side edge 0.3 m to the right, ``side`` -1, or to the left, running
    straight ahead from 1 to 3 m), exact points, then as a matcher sees it: along each row the 8 pixels of the
    hole next to the floor carry the floor's disparity (they triangulate onto the floor plane past the edge);
    with the hole to the left, the pixels the right camera does not see (the floors' disparity difference, a
    band left of the floor, wider than ``fattening_px`` here) are unmeasured beyond those. Up the columns the fattened floor pushes the edges into
    the hole; along the rows (``fattening_px``) every 5 cm of the side from 1.3 to 2 m (where the bottom is seen
    within 6 m) has a mark within a cell of it again, and none lies more than ``edge_reach_m`` into the floor."""
    rays, T, _ = _tilted_rig()
    bf = 60.0                               # a 0.3 m baseline: the hidden band is 20-30 px wide
    y_edge = 0.3 * side
    points = _surface(rays, T, lambda p: np.where((p[:, 0] > 1.0) & (p[:, 0] < 3.0) & (side * p[:, 1] > 0.3),
                                                  -1.0, 0.0))
    t = T[:3, 3]
    floor = t + rays * (t[2] / -np.minimum(rays[..., 2], -1e-9))[..., None]
    depth = lambda p: (p - t) @ T[:3, 2]                                            # noqa: E731
    seen = points.copy()
    low = points[..., 2] < -0.5
    w = points.shape[1]
    if side < 0:            # the hole right of the floor in the image: fattened, nothing hidden
        for i, j in np.argwhere(low[:, 1:] & ~low[:, :-1]):
            k = slice(j + 1, j + 9)
            seen[i, k] = np.where(low[i, k, None], floor[i, k], points[i, k])
    else:                   # the hole left of the floor: a band the right camera does not see, then fattened
        for i, j in np.argwhere(low[:, :-1] & ~low[:, 1:]):
            band = int(np.ceil(bf / depth(points[i, j + 1]) - bf / depth(points[i, j])))
            for k in range(max(0, j - band), j + 1):
                seen[i, k] = floor[i, k] if j - k < 8 else np.nan

    def covered(pts, fattening_px):
        edge = find_drops(pts, T, bf, config=DropConfig(fattening_px=fattening_px)).edge_points_robot
        along = edge[(edge[:, 0] > 1.3) & (edge[:, 0] < 2.0)]
        assert np.all(side * along[:, 1] > 0.3 - 0.1 - 1e-9), along[:, 1]
        near = along[np.abs(along[:, 1] - y_edge) < 0.05, 0]
        return np.isin(np.arange(14), np.floor((near - 1.3) / 0.05).astype(int))

    assert covered(points, 0).all() and covered(points, 8).all()
    assert not covered(seen, 0).all()
    assert covered(seen, 8).all()
    with pytest.raises(ValueError, match="fattening_px"):
        DropConfig(fattening_px=-1)
    with pytest.raises(TypeError, match="fattening_px"):
        DropConfig(fattening_px=2.5)


def _noisy_disparity(points, T, bf, sigma_px, rng, block=8):
    """``points`` moved along their sight lines by a disparity error of ``sigma_px`` (Gaussian), the same over each
    ``block`` x ``block`` pixels (a matcher's errors come in patches, a window wide)."""
    t = T[:3, 3]
    depth = (points - t) @ T[:3, :3][:, 2]
    h, w = depth.shape
    error = np.kron(rng.normal(0.0, sigma_px, (-(-h // block), -(-w // block))), np.ones((block, block)))[:h, :w]
    noisy = bf / (bf / depth + error)
    return t + (points - t) * (noisy / depth)[..., None]


def test_the_noise_margin_is_the_matchers_error_measured_on_the_floor():
    """A floor matched with a known disparity error (0.1 and 0.6 px, in patches): the frame's floor gives it back
    within 10 %, with a box standing on it and a ledge in view too (their points are not the floor's); the margin
    built on it marks no drop on the noisy floor and still finds a ledge there; on the clean floor it finds a
    shallow ledge the fixed 0.25 px mostly misses; too little floor falls back to ``disparity_sigma_px``."""
    from mrstereo.geometry.drops import floor_disparity_sigma_px

    rng = np.random.default_rng(7)
    rays, T, bf = _tilted_rig()
    flat = _surface(rays, T, lambda p: np.zeros(len(p)))
    scene = _surface(rays, T, lambda p: np.where(p[:, 0] > 2.5, -0.5,
                                                 np.where((np.abs(p[:, 0] - 1.5) < 0.2) & (p[:, 1] > 0.3), 0.4, 0.0)))
    for sigma in (0.1, 0.6):
        for points in (flat, scene):
            noisy = _noisy_disparity(points, T, bf, sigma, rng)
            assert floor_disparity_sigma_px(noisy, T, bf) == pytest.approx(sigma, rel=0.1)
    noisy = _noisy_disparity(flat, T, bf, 0.6, rng)
    measured = find_drops(noisy, T, bf)
    assert len(measured.points_robot) == 0 and measured.disparity_sigma_px == pytest.approx(0.6, rel=0.1)
    ledge = find_drops(_noisy_disparity(_surface(rays, T, lambda p: np.where(p[:, 0] < 1.2, 0.0, -0.4)), T, bf,
                                        0.6, rng), T, bf)
    assert np.count_nonzero(ledge.edge_columns) > 0.3 * rays.shape[1]
    assert np.median(ledge.edge_points_robot[:, 0]) == pytest.approx(1.2, abs=0.1)
    # a clean matcher (0.1 px) sees a 0.2 m ledge 1.5 m ahead in most columns; the fixed 0.25 px in a fifth
    shallow = _noisy_disparity(_surface(rays, T, lambda p: np.where(p[:, 0] < 1.5, 0.0, -0.2)), T, bf, 0.1, rng)
    fixed = find_drops(shallow, T, bf, config=DropConfig(noise_from_floor=False))
    measured = find_drops(shallow, T, bf)
    assert fixed.disparity_sigma_px == 0.25 and measured.disparity_sigma_px == pytest.approx(0.1, rel=0.1)
    assert np.count_nonzero(measured.edge_columns) > 0.6 * rays.shape[1] > 3 * np.count_nonzero(fixed.edge_columns)
    assert np.all(np.abs(measured.edge_points_robot[:, 0] - 1.5) < 0.15)
    assert floor_disparity_sigma_px(noisy[:4, :4], T, bf, default_px=0.3) == 0.3           # no floor in view
    with pytest.raises(ValueError, match="points_robot_image"):
        floor_disparity_sigma_px(noisy[..., :2], T, bf)
    below = T.copy()
    below[2, 3] = -0.1
    with pytest.raises(ValueError, match="above the floor"):
        floor_disparity_sigma_px(noisy, below, bf)
    with pytest.raises(TypeError, match="noise_from_floor"):
        DropConfig(noise_from_floor=1)


def _pixels_of(points_image, points) -> np.ndarray:
    """Mask (H, W) of the pixels of ``points_image`` whose point is one of ``points`` (N, 3) exactly."""
    wanted = {tuple(p) for p in np.asarray(points, dtype=np.float64)}
    flat = points_image.reshape(-1, 3)
    return np.array([tuple(p) in wanted for p in flat]).reshape(points_image.shape[:2])


def test_a_floor_without_texture_along_the_rows_gives_no_drop(tmp_path):
    """Tuning world 100's first 0.8 m of drive over a wood floor whose planks run across the view: the matcher
    slides along the rows in streaks, and without the row-texture test floor pixels land below the floor as drops
    in most frames; with it none of the true floor's pixels does. A ledge whose lower points lie in untextured
    pixels is not found; a mask of the wrong shape is refused."""
    import cv2

    from mrstereo.geometry import points_robot_from_disparity
    from mrstereo.geometry.pair import obstacles_from_pair
    from mrstereo.io.images import read_pfm
    from mrstereo.pipeline.run import PipelineConfig
    from mrstereo.recordings.manifest import frame_pair
    from mrstereo.world import read_manifest, write_synthetic_dataset

    write_synthetic_dataset(tmp_path, seed=100, n_frames=9, progress=False, randomize=True, drops=True, path="front",
                            step_m=0.096)
    manifest = read_manifest(tmp_path)
    options = PipelineConfig().for_rig(manifest.calibration).pair_options()
    false_drops = {None: [], DropConfig.min_row_texture: []}
    for record in manifest.frames:
        left, right, rectified = frame_pair(record)
        labels = cv2.imread(str(record.gt_labels), cv2.IMREAD_UNCHANGED)
        for texture in false_drops:
            config = replace(options["config"], drops=DropConfig(min_row_texture=texture))
            frame = obstacles_from_pair(left, right, manifest.calibration, rectified=rectified, mount=manifest.mount,
                                        pan_rad=record.pan_rad, **{**options, "config": config}).obstacles
            true = points_robot_from_disparity(read_pfm(record.gt_disparity), manifest.calibration,
                                               frame.T_robot_from_cam)
            floor = (labels == LABEL_FLOOR) & (np.abs(true[..., 2]) < 0.01)
            false_drops[texture].append(int((_pixels_of(frame.points_robot_image, frame.drop_points_robot)
                                             & floor).sum()))
    off = np.array(false_drops[None])
    assert off.sum() > 50 and np.count_nonzero(off) >= 5, false_drops
    assert sum(false_drops[DropConfig.min_row_texture]) == 0, false_drops
    rays, T, bf = _tilted_rig(h=120, w=160, f=100.0)
    points = _surface(rays, T, lambda p: np.where(p[:, 0] < 1.2, 0.0, -0.4))
    assert np.count_nonzero(find_drops(points, T, bf).edge_columns) > 0.5 * rays.shape[1]
    lower = points[..., 2] < -0.1
    assert len(find_drops(points, T, bf, untextured=lower).points_robot) == 0
    with pytest.raises(ValueError, match="untextured"):
        find_drops(points, T, bf, untextured=lower[1:])
    with pytest.raises(ValueError, match="min_row_texture"):
        DropConfig(min_row_texture=-1.0)


def test_untextured_points_are_floor_at_floor_level(tmp_path):
    """Held-out world 306 ends in a ramp down on wood laid across the view. With the true disparity of a view
    down the ramp, the points without texture along the rows stay floor at floor level: no drop, as without the
    test; left out entirely, they take the floor from before the ramp's few textured points below floor level,
    which the rule for a column without floor before its run then calls drops in over a hundred columns."""
    from mrstereo.io.images import read_pfm
    from mrstereo.recordings.manifest import frame_pair
    from mrstereo.rejection import row_texture
    from mrstereo.world import read_manifest, write_synthetic_dataset

    write_synthetic_dataset(tmp_path, seed=306, n_frames=22, progress=False, randomize=True, drops=True)
    manifest = read_manifest(tmp_path)
    record = manifest.frames[21]
    frame = detect_obstacles(read_pfm(record.gt_disparity).astype(np.float32), manifest.calibration,
                             mount=manifest.mount, pan_rad=record.pan_rad, config=ObstacleConfig())
    points, T = frame.points_robot_image, frame.T_robot_from_cam
    bf = manifest.calibration.baseline_m * manifest.calibration.focal_px
    untextured = row_texture(frame_pair(record)[0]) < DropConfig.min_row_texture
    exact = DropConfig(n_sigma=0.0)                               # the data are exact: no noise margin
    assert 0.2 < untextured[np.isfinite(points[..., 2])].mean() < 0.9
    assert len(find_drops(points, T, bf, config=exact).points_robot) == 0
    assert len(find_drops(points, T, bf, config=exact, untextured=untextured).points_robot) == 0
    left_out = np.where(untextured[..., None], np.nan, points)
    assert np.count_nonzero(find_drops(left_out, T, bf, config=exact).edge_columns) > 50


def test_the_row_texture_is_computed_from_the_first_row_that_can_see_the_floor():
    """A camera pitched down by 10 degrees sees its horizon ``f tan(10 deg)`` rows above the image centre: the
    first floor row; level, at the centre row; a failed floor gives 0. Below that row the row texture is exactly
    the whole image's, above it NaN (not computed)."""
    from mrstereo import CameraMount, StereoCamera
    from mrstereo.camera import Camera
    from mrstereo.geometry import ground_from_mount
    from mrstereo.geometry.obstacles import first_floor_row
    from mrstereo.rejection import row_texture

    stereo = StereoCamera.ideal(Camera(width=160, height=120, fx=100.0, fy=100.0, cx=80.0, cy=60.0), 0.1)
    for tilt_deg, row in ((10.0, math.floor(60.0 - 100.0 * math.tan(math.radians(10.0)))), (0.0, 60)):
        mount = CameraMount.from_xyz_rpy((0.0, 0.0, 0.5), (0.0, math.radians(tilt_deg), 0.0))
        assert first_floor_row(stereo, ground_from_mount(mount)) == row
    failed = replace(ground_from_mount(mount), success=False)
    assert first_floor_row(stereo, failed) == 0
    image = np.random.default_rng(2).integers(0, 255, (120, 160)).astype(np.uint8)
    whole, part = row_texture(image), row_texture(image, first_row=42)
    np.testing.assert_allclose(part[42:], whole[42:], rtol=1e-6)
    assert np.isnan(part[:42]).all()
    with pytest.raises(ValueError, match="first_row"):
        row_texture(image, first_row=-1)


def test_floor_nearer_than_the_near_limit_is_no_drop():
    """A camera pitched down 35 degrees sees the floor nearer than the near limit in its bottom rows: the matcher
    flags them too near, and placed at the near limit their points lie below the floor. The drop test never sees
    them (no drop, candidate or weak point); the point cloud keeps them as before (fail-safe obstacle rule)."""
    from mrstereo import CameraMount, StereoCamera
    from mrstereo.camera import Camera
    from mrstereo.geometry import ground_from_mount
    from mrstereo.geometry.ground import T_robot_from_cam_ground

    cam = Camera(width=160, height=120, fx=100.0, fy=100.0, cx=80.0, cy=60.0)
    stereo = StereoCamera.ideal(cam, 0.12)
    mount = CameraMount.from_xyz_rpy((0.0, 0.0, 0.5), (0.0, math.radians(35.0), 0.0))
    T = T_robot_from_cam_ground(ground_from_mount(mount))
    v, u = np.mgrid[0:120, 0:160].astype(float)
    rays = np.stack([(u - 80.0) / 100.0, (v - 60.0) / 100.0, np.ones_like(u)], -1) @ T[:3, :3].T
    depth = np.where(rays[..., 2] < 0, 0.5 / -np.minimum(rays[..., 2], -1e-9), np.nan)    # camera z = ray scale
    truth = (0.12 * 100.0 / depth).astype(np.float32)
    limit = 20.0                                                  # the near limit: 0.6 m of depth
    too_near = truth > limit
    assert 10 <= np.count_nonzero(too_near.any(axis=1)) < 60      # the bottom rows, floor nearer than 0.6 m
    d = np.where(too_near, np.nan, truth).astype(np.float32)
    config = ObstacleConfig(drops=DropConfig())
    obs = detect_obstacles(d, stereo, mount=mount, config=config, too_near=too_near, near_limit_px=limit)
    assert obs.success
    assert len(obs.drop_points_robot) == 0 and len(obs.drop_candidates_robot) == 0
    assert len(obs.drop_weak_points_robot) == 0
    # the placements themselves lie below the floor, in the cloud as before
    image = obs.points_robot_image
    assert np.all(image[too_near][:, 2] < 0.0)
    assert np.isfinite(image[~too_near & np.isfinite(d)]).all()
