"""Free-space boundary (where the floor ends per image column) on hand-made frames.

A camera at height H tilted down by TILT sees a flat floor and, in some frames, a plain wall
``x = WALL_X`` (robot frame) with no texture: the matcher measures nothing on it, the floor is
measured on a sparse set of pixels. Image gray levels with noise; no stereo matching involved.
"""

import numpy as np
import pytest

from mrstereo.camera import Camera, CameraMount, StereoCamera
from mrstereo.geometry import ObstacleConfig, detect_obstacles
from mrstereo.geometry.freespace import FreeSpaceConfig, free_space_boundary
from mrstereo.mapping import GridSpec
from mrstereo.transforms import T_robot_from_cam

W, H, F, CX, CY, B = 320, 240, 200.0, 161.0, 118.5, 0.1
HEIGHT, TILT = 0.6, 0.3
WALL_X = 2.0


def _stereo():
    return StereoCamera.ideal(Camera(width=W, height=H, fx=F, fy=F, cx=CX, cy=CY), B,
                              mount=CameraMount.from_rig(HEIGHT, TILT))


def _frame(*, wall_x=WALL_X, floor_gray=None, measured_share=0.05, measured_below=200, skirting_m=0.0, seed=0):
    """(image, disparity): the floor's gray level from ``floor_gray(x, y)``; a plain wall at ``wall_x`` (None: none).

    The floor is measured on ``measured_share`` of its pixels below row ``measured_below``; the
    wall's lowest ``skirting_m`` is a skirting board of the floor's gray level.
    """
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    rays = np.stack([(u - CX) / F, (v - CY) / F, np.ones_like(u)], axis=-1)
    T = T_robot_from_cam(height_m=HEIGHT, tilt_rad=TILT)
    dirs = rays @ T[:3, :3].T
    origin = T[:3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        t_floor = np.where(dirs[..., 2] < 0, -origin[2] / dirs[..., 2], np.inf)
        t_wall = np.where(dirs[..., 0] > 0, (wall_x - origin[0]) / dirs[..., 0], np.inf) if wall_x else \
            np.full(u.shape, np.inf)
    t_hit = np.minimum(t_floor, t_wall)
    on_floor = np.isfinite(t_floor) & (t_floor <= t_wall)
    height = origin[2] + t_hit * dirs[..., 2]
    gray = np.where(on_floor | (height < skirting_m), 60.0, 120.0)
    if floor_gray is not None:
        p = origin + np.where(on_floor, t_floor, 0.0)[..., None] * dirs
        gray = np.where(on_floor, floor_gray(p[..., 0], p[..., 1]), gray)
    image = np.clip(gray + rng.normal(0.0, 3.0, gray.shape), 0, 255).astype(np.uint8)
    depth = t_hit * (dirs @ T[:3, :3][:, 2])          # camera z of the hit point
    disparity = np.full((H, W), np.nan, np.float32)
    measured = on_floor & (rng.uniform(size=(H, W)) < measured_share) & np.isfinite(depth) & (v >= measured_below)
    disparity[measured] = (B * F / depth[measured]).astype(np.float32)
    return image, disparity


def _boundary(image, disparity, config=FreeSpaceConfig()):
    stereo = _stereo()
    obstacles = detect_obstacles(disparity, stereo, config=ObstacleConfig(max_range_m=4.0))
    return free_space_boundary(image, obstacles, disparity, stereo, config=config, max_range_m=4.0)


def test_plain_wall_base_within_two_cells():
    image, disparity = _frame()
    out = _boundary(image, disparity)
    assert out.columns.size > 0.8 * W                  # nearly every column sees the wall's base
    x = out.base_points_robot[:, 0]
    assert np.median(np.abs(x - WALL_X)) < 0.05       # one 5 cm cell
    assert np.mean(np.abs(x - WALL_X) <= 0.10) > 0.95  # two cells
    assert np.all(out.base_points_robot[:, 2] == 0.0)
    # obstacle points on the vertical lines over the bases, in the height band
    z = out.points_robot[:, 2]
    assert z.min() > 0.08 and z.max() <= 1.5
    assert np.all(np.isin(out.points_robot[:, 0], x))


def test_skirting_of_the_floor_colour_is_not_taken_for_the_floor():
    """The floor is measured up to the board's foot; the edge at its top lies 0.4 m farther on the floor."""
    image, disparity = _frame(skirting_m=0.1, measured_share=0.5, measured_below=0)
    out = _boundary(image, disparity)
    # no edge at the foot: no boundary at all is right, one at the board's top (x = 2.4 m) is not
    assert np.all(np.abs(out.base_points_robot[:, 0] - WALL_X) <= 0.1), out.base_points_robot[:, 0].max()
    # without the gap rule the board's top edge is taken, and where the floor below is not
    # measured right up to it the base lands behind the wall
    loose = _boundary(image, disparity, FreeSpaceConfig(gap_rows=12))
    assert (loose.base_points_robot[:, 0] > WALL_X + 0.2).any()


def test_wall_base_at_640x480(monkeypatch):
    """A larger image is reduced to about 320x240 first: the same answer, in full-image rows and columns."""
    import sys
    module = sys.modules[__name__]
    for name, value in (("W", 640), ("H", 480), ("F", 400.0), ("CX", 322.0), ("CY", 237.0)):
        monkeypatch.setattr(module, name, value)
    image, disparity = _frame(measured_below=400)
    out = _boundary(image, disparity)
    assert out.columns.size > 0.8 * 320 and out.columns.max() < 640
    assert np.mean(np.abs(out.base_points_robot[:, 0] - WALL_X) <= 0.10) > 0.95
    # the base row is the wall's foot in the full image: the floor point of that row lies at the wall
    v = out.base_row[out.columns]
    ray = np.stack([(out.columns - CX) / F, (v - CY) / F, np.ones(v.size)], axis=1) @ \
        T_robot_from_cam(height_m=HEIGHT, tilt_rad=TILT)[:3, :3].T
    x = HEIGHT * ray[:, 0] / -ray[:, 2]
    assert np.median(np.abs(x - WALL_X)) < 0.05


def test_no_wall_nothing_invented_on_plain_floor():
    image, disparity = _frame(wall_x=None)
    assert _boundary(image, disparity).columns.size == 0


@pytest.mark.parametrize("name,floor_gray,share", [
    # thin dark grout lines every 0.5 m (2 cm wide): one or two rows, the floor again above them
    ("grout", lambda x, y: np.where(np.mod(x, 0.5) < 0.02, 30.0, 60.0), 0.05),
    # stripes across the view, 0.3 m wide: a patterned floor, measured (its texture) on 30 % of its pixels
    ("stripes", lambda x, y: np.where(np.mod(x, 0.6) < 0.3, 40.0, 110.0), 0.3),
    # a chequered floor
    ("checker", lambda x, y: np.where((np.floor(x / 0.3) + np.floor(y / 0.3)) % 2 == 0, 30.0, 200.0), 0.3),
    # a lamp's gradient along the floor
    ("gradient", lambda x, y: 40.0 + 15.0 * x, 0.05),
])
def test_patterned_floor_without_wall_gives_no_boundary(name, floor_gray, share):
    image, disparity = _frame(wall_x=None, floor_gray=floor_gray, measured_share=share, measured_below=0)
    out = _boundary(image, disparity)
    assert out.columns.size == 0, f"{name}: {out.columns.size} columns"


def test_no_floor_measured_no_boundary():
    image, disparity = _frame(measured_share=0.0)
    disparity[:] = np.nan
    assert _boundary(image, disparity).columns.size == 0


def test_bad_input():
    image, disparity = _frame()
    stereo = _stereo()
    obstacles = detect_obstacles(disparity, stereo)
    with pytest.raises(TypeError, match="obstacles"):
        free_space_boundary(image, "x", disparity, stereo)
    with pytest.raises(ValueError, match="disparity_px"):
        free_space_boundary(image, obstacles, disparity[:-1], stereo)
    with pytest.raises(ValueError, match="check_rows"):
        FreeSpaceConfig(persist_rows=8, check_rows=4)
    with pytest.raises(ValueError, match="adapt"):
        FreeSpaceConfig(adapt=2.0)


def test_boundary_points_join_the_observation_marked_and_map_the_plain_wall():
    from mrstereo.mapping import OccupancyGrid
    from mrstereo.mapping.fusion import add_observation
    from mrstereo.geometry.pair import Observed
    from mrstereo.mapping.fusion import world_observation
    from mrstereo.pipeline.mapper import PipelineConfig
    from mrstereo.recordings.manifest import FrameRecord
    from mrstereo.transforms import T_from_planar, transform_points

    image, disparity = _frame()
    stereo = _stereo()
    obstacles = detect_obstacles(disparity, stereo, config=ObstacleConfig(max_range_m=4.0))
    boundary = free_space_boundary(image, obstacles, disparity, stereo, max_range_m=4.0)
    def observed(boundary_points):
        return Observed(index=0, stamp_s=0.0, pan_rad=0.0, mount=None, ground=obstacles.ground,
                        obstacle_points_robot=np.concatenate([obstacles.obstacle_points_robot, boundary_points]),
                        n_boundary=len(boundary_points), floor_points_robot=obstacles.floor_points_robot)

    record = FrameRecord(pose=(1.0, 0.5, 0.3))
    config = PipelineConfig()
    obs = world_observation(observed(boundary.points_robot), record.pose, stereo)
    n = len(boundary.points_robot)
    assert n > 0 and obs.boundary_points == n
    np.testing.assert_allclose(obs.obstacle_points_world[-n:],
                               transform_points(T_from_planar(*record.pose), boundary.points_robot), atol=1e-5)
    window = GridSpec()                              # the corridor's 12 x 6 m
    grid = OccupancyGrid(window, config=config.mapping)
    add_observation(grid, obs)
    occupied = grid.to_ros_map().occupied
    wall_xy = transform_points(T_from_planar(*record.pose), boundary.base_points_robot)[:, :2]
    r, c = window.cells_from_xy(wall_xy)
    assert occupied[r, c].mean() > 0.8               # the plain wall is in the map
    bare = world_observation(observed(np.empty((0, 3))), record.pose, stereo)
    assert bare.boundary_points == 0 and len(bare.obstacle_points_world) == len(obs.obstacle_points_world) - n
