"""The map that grows (:class:`~mrstereo.mapping.tiles.TiledOccupancyGrid`): the same cells as one dense
grid over the same views, memory bounded by the area seen, the robot's footprint free."""
from __future__ import annotations

import numpy as np
import pytest

from mrstereo.mapping import GridSpec, MappingConfig, OccupancyGrid
from mrstereo.mapping.tiles import TiledOccupancyGrid


def _view(x0, rng):
    """A wall 3 m ahead of a sensor at (x0, 0), 2 m wide, and floor points before it."""
    wall = np.column_stack([np.full(400, x0 + 3.0), np.linspace(-1.0, 1.0, 400), np.full(400, 0.3)])
    floor = np.column_stack([x0 + rng.uniform(0.5, 2.8, 200), rng.uniform(-0.8, 0.8, 200), np.zeros(200)])
    return wall, floor, (x0, 0.0, 0.4)


def test_tiles_hold_the_cells_of_one_dense_grid_over_the_same_views():
    rng = np.random.default_rng(0)
    views = [_view(x0, rng) for x0 in np.arange(0.013, 20.0, 0.7)]       # (sensors off the cell borders)
    tiles = TiledOccupancyGrid(0.05, tile_cells=32)
    dense = OccupancyGrid(GridSpec(width_m=25.0, height_m=4.0, resolution_m=0.05, origin_x_m=-1.0, origin_y_m=-2.0))
    for wall, floor, sensor in views:
        tiles.update(wall, floor, sensor)
        dense.update(wall, floor, sensor)
    assert tiles.points_outside == dense.points_outside == 0
    np.testing.assert_array_equal(tiles.to_grid(dense.grid).log_odds, dense.log_odds)
    bounds = tiles.bounds()                                 # the cells seen, not the window given
    assert bounds.origin_x_m == pytest.approx(0.0, abs=0.051) and bounds.origin_x_m + bounds.width_m > 22.6
    assert (tiles.to_grid().probability() > 0.5).sum() >= 40         # the last wall at least


def test_a_kilometre_path_holds_the_tiles_along_it_not_a_square_kilometre():
    rng = np.random.default_rng(1)
    tiles = TiledOccupancyGrid(0.05)
    for x0 in np.arange(0.0, 1000.0, 2.5):
        tiles.update(*_view(x0, rng))
    bounds = tiles.bounds()
    assert bounds.width_m > 1000.0
    # a square kilometre of log-odds, obstacle heights, the height layer and drop votes
    dense_bytes = (bounds.width_m / 0.05) ** 2 * (8 + 8 + 8 + 2)
    assert tiles.nbytes < 0.02 * dense_bytes                 # 134 MB, not 10 GB
    assert tiles.n_tiles <= 2 * (1005 / (128 * 0.05) + 2)     # one or two rows of 6.4 m tiles


def test_the_footprint_is_free_and_a_fixed_window_counts_what_falls_outside():
    config = MappingConfig()
    grid = OccupancyGrid(GridSpec(width_m=2.0, height_m=2.0, resolution_m=0.05, origin_x_m=-1.0, origin_y_m=-1.0),
                         config=config)
    n = grid.clear_disc((0.0, 0.0), 0.3)
    p = grid.probability()
    centres = grid.grid.xy_from_cells(*np.mgrid[0:40, 0:40])
    inside = np.hypot(centres[..., 0], centres[..., 1]) <= 0.3
    assert n == int((p < 0.5).sum()) and np.all(p[inside] < 0.5)          # every cell of the disc free
    assert np.isnan(p[np.hypot(centres[..., 0], centres[..., 1]) > 0.42]).all()   # nothing else touched
    tiles = TiledOccupancyGrid(0.05)
    assert tiles.clear_disc((10.0, -5.0), 0.3) == n                         # the same disc anywhere
    wall = np.repeat([[0.8, 0.0, 0.3], [5.0, 0.0, 0.3]], 5, axis=0)     # 5 points a cell: supported
    stats = grid.update(wall, None, (0.0, 0.0))
    assert stats.points_outside == 5 and grid.points_outside == 5 and grid.probability()[20, 36] > 0.5


def test_the_footprint_cleared_in_the_tiles_is_that_of_one_dense_grid():
    rng = np.random.default_rng(5)
    tiles = TiledOccupancyGrid(0.05, tile_cells=16)
    dense = OccupancyGrid(GridSpec(width_m=20.0, height_m=20.0, resolution_m=0.05, origin_x_m=-10.0, origin_y_m=-10.0))
    for xy, radius in zip(rng.uniform(-8.0, 8.0, (40, 2)), rng.uniform(0.0, 0.9, 40)):   # discs across tile borders
        assert tiles.clear_disc(xy, radius) == dense.clear_disc(xy, radius) > 0
    np.testing.assert_array_equal(tiles.to_grid(dense.grid).log_odds, dense.log_odds)
    assert tiles.n_tiles < (20.0 / (16 * 0.05)) ** 2 / 4                    # only the tiles the discs touched
