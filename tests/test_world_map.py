"""Ground-truth map of the synthetic corridor against the scene and the rendered geometry."""
from __future__ import annotations

import numpy as np
import pytest

from mrstereo.geometry import points_cam_from_disparity
from mrstereo.mapping.grid import GridSpec
from mrstereo.transforms import transform_points
from mrstereo.world import LABEL_FLOOR, default_scene, default_stereo, is_obstacle_label, render_stereo_frame
from mrstereo.world.groundtruth import ground_truth_map


@pytest.fixture(scope="module")
def gt():
    return ground_truth_map(default_scene(0))


def _at(ros_map, x, y):
    row, col = ros_map.grid.cells_from_xy(np.array([[x, y]]))
    return ros_map.occupancy[row[0], col[0]]


def test_known_cells(gt):
    assert gt.occupancy.shape == (120, 240)
    assert _at(gt, 5.0, 1.3) == 1.0          # left wall
    assert _at(gt, 7.0, -1.3) == 1.0         # right wall
    assert _at(gt, 5.0, 0.0) == 0.0          # corridor centre
    assert _at(gt, 6.2, 0.0) == 1.0          # obstacle in the middle
    assert _at(gt, 3.9, -0.6) == 1.0         # cylinder centre
    assert _at(gt, 3.9, -0.35) == 0.0        # just outside the cylinder (r = 0.2 m)
    assert _at(gt, 3.5, 1.25) == 0.0         # door recess: free under the lintel
    assert _at(gt, 3.5, 1.35) == 1.0         # the recessed door panel
    assert np.isnan(_at(gt, 5.0, 2.0))       # behind the wall: unknown
    assert np.isnan(_at(gt, 5.0, -2.5))


def test_ros_map_classes(gt):
    assert gt.occupied.sum() == np.sum(gt.occupancy == 1.0)
    assert gt.free.sum() == np.sum(gt.occupancy == 0.0)
    assert gt.unknown.sum() == np.isnan(gt.occupancy).sum()


def test_rendered_surfaces_agree_with_map(gt):
    stereo = default_stereo(160, 120)
    frame = render_stereo_frame(default_scene(0), stereo, pose=(0.2, 0.0, 0.0), supersample=1)
    pts = points_cam_from_disparity(frame.disparity_px, focal_px=stereo.focal_px, baseline_m=stereo.baseline_m,
                                    cx_px=stereo.cx_px, cy_px=stereo.cy_px)
    world = transform_points(frame.T_world_from_cam, pts)
    inside = (world[..., 0] > 0.1) & (world[..., 0] < 11.9)
    floor = (frame.labels == LABEL_FLOOR) & inside
    rows, cols = gt.grid.cells_from_xy(world[floor][:, :2])
    # Floor seen by the camera is free in the map (except where an obstacle footprint rounds over it).
    assert np.mean(gt.occupancy[rows, cols] == 0.0) > 0.97
    # Obstacle surfaces lie in (or within one cell of) occupied cells.
    obst = is_obstacle_label(frame.labels) & inside
    rows, cols = gt.grid.cells_from_xy(world[obst][:, :2])
    occ = gt.occupied
    near = np.zeros_like(occ)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            near |= np.roll(np.roll(occ, dr, 0), dc, 1)
    assert obst.sum() > 200 and np.all(near[rows, cols])


def test_other_grid_and_bad_inputs():
    fine = ground_truth_map(default_scene(0), GridSpec(width_m=4.0, height_m=3.0, resolution_m=0.02,
                                                       origin_x_m=0.0, origin_y_m=-1.5))
    assert fine.occupancy.shape == (150, 200)
    with pytest.raises(TypeError, match="scene"):
        ground_truth_map("corridor")
    with pytest.raises(TypeError, match="grid"):
        ground_truth_map(default_scene(0), grid=(12, 6))
    with pytest.raises(ValueError, match="height_band_m"):
        ground_truth_map(default_scene(0), height_band_m=(2.0, 0.1))


def test_obstacle_footprints_are_the_obstacles_of_the_ground_truth_map():
    from mrstereo.mapping import GridSpec
    from mrstereo.world import LABEL_OBSTACLE, ground_truth_map, obstacle_footprints, random_world

    world = random_world(3)
    grid = GridSpec()
    footprints = obstacle_footprints(world.scene, grid)
    assert len(footprints) == len(world.summary["obstacles"])        # one per drawn obstacle
    truth = ground_truth_map(world.scene, grid).occupied
    for cells in footprints.values():
        assert cells.any() and truth[cells].all()
    first, second = list(footprints.values())[:2]
    assert not np.logical_and(first, second).any()                    # placed apart
    assert sorted(footprints) == [LABEL_OBSTACLE + k for k in range(len(footprints))]
