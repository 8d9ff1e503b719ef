"""ROS map_server files and grid geometry."""
import numpy as np
import pytest

from mrstereo.io import read_image
from mrstereo.mapping import GridSpec, RosMap, read_ros_map, write_ros_map


def test_grid_cells_and_orientation(tmp_path):
    g = GridSpec()
    assert g.shape == (120, 240)
    row, col = g.cells_from_xy(np.array([[0.01, -2.99], [1.0, 2.0]]))
    assert (row[0], col[0]) == (0, 0) and (row[1], col[1]) == (100, 20)
    np.testing.assert_allclose(g.xy_from_cells(100, 20), [1.025, 2.025])
    occ = np.zeros(g.shape)
    occ[:] = np.nan
    occ[100, 20] = 1.0          # left of the robot: y = +2 m
    occ[10, 5] = 0.0
    write_ros_map(tmp_path / "map.yaml", RosMap(occupancy=occ, grid=g))
    img = read_image(tmp_path / "map.pgm")
    assert img.shape == (120, 240)
    assert img[119 - 100, 20] == 0 and img[119 - 10, 5] == 254 and img[0, 0] == 205
    back = read_ros_map(tmp_path / "map.yaml")
    assert back.grid == g
    np.testing.assert_array_equal(back.occupied, occ == 1.0)
    np.testing.assert_array_equal(back.free, occ == 0.0)
    assert back.unknown.sum() == occ.size - 2


def test_bad_map_files(tmp_path):
    with pytest.raises(FileNotFoundError, match="map file not found"):
        read_ros_map(tmp_path / "x.yaml")
    (tmp_path / "m.yaml").write_text("image: m.pgm\nresolution: .nan\norigin: [0, 0, 0]\n")
    with pytest.raises(ValueError, match="resolution must be > 0"):
        read_ros_map(tmp_path / "m.yaml")
    with pytest.raises(ValueError, match="resolution_m must be > 0"):
        GridSpec(resolution_m=0.0)
