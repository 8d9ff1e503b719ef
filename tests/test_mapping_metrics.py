"""Map metrics against a ground-truth map: known answers."""
from __future__ import annotations

import json

import numpy as np
import pytest

from mrstereo.mapping import GridSpec, RosMap, cells_in_view, cells_near_path, map_metrics
from mrstereo.mapping.grid import dilate_cells


def corridor(shift_rows: int = 0, *, grid: GridSpec | None = None) -> RosMap:
    """Free corridor between two 1-cell walls (rows 30 and 90), unknown beyond the walls."""
    grid = grid or GridSpec()
    occ = np.full(grid.shape, np.nan)
    occ[30 + shift_rows:91 + shift_rows] = 0.0
    occ[30 + shift_rows] = 1.0
    occ[90 + shift_rows] = 1.0
    return RosMap(occupancy=occ, grid=grid)


def test_ground_truth_against_itself_is_perfect():
    m = map_metrics(corridor(), corridor())
    assert m.precision == 1.0 and m.recall == 1.0 and m.mean_distance_m == 0.0
    assert m.free_recall == 1.0 and m.known_fraction == pytest.approx(61 / 120)
    assert m.true_occupied_cells == 2 * 240 and m.estimated_occupied_cells == 2 * 240


def test_shift_by_two_cells_gives_a_tenth_of_a_metre():
    m = map_metrics(corridor(2), corridor())
    assert m.mean_distance_m == pytest.approx(0.10)
    assert m.precision == 0.0 and m.recall == 0.0        # outside the 1-cell tolerance
    one = map_metrics(corridor(1), corridor())
    assert one.precision == 1.0 and one.recall == 1.0 and one.mean_distance_m == pytest.approx(0.05)
    strict = map_metrics(corridor(1), corridor(), tolerance_cells=0)
    assert strict.precision == 0.0
    assert 0.9 < m.free_recall < 1.0                  # 2 true free rows are now walls/unknown


def test_path_band_restricts_the_evaluated_cells():
    est = corridor()
    occ = est.occupancy.copy()
    occ[60, 220] = 1.0                                  # a ghost 10 m down the corridor
    est = RosMap(occupancy=occ, grid=est.grid)
    everywhere = map_metrics(est, corridor())
    path = np.array([[0.5, 0.0, 0.0], [3.0, 0.0, 0.0]])
    near = map_metrics(est, corridor(), path_xy=path, within_m=4.0)
    assert everywhere.precision < 1.0 and near.precision == 1.0
    assert near.evaluated_cells < everywhere.evaluated_cells
    band = cells_near_path(GridSpec(), path, within_m=1.0)
    x, y = GridSpec().xy_from_cells(*np.nonzero(band)).T
    d = np.where(x < 0.5, np.hypot(x - 0.5, y), np.where(x > 3.0, np.hypot(x - 3.0, y), np.abs(y)))
    half_cell_diagonal = GridSpec().resolution_m / np.sqrt(2)        # rasterization of the path
    assert d.max() <= 1.0 + half_cell_diagonal and band[60, 40] and not band[60, 100]


def test_to_dict_is_json_ready():
    empty = RosMap(occupancy=np.zeros(GridSpec().shape), grid=GridSpec())
    m = map_metrics(empty, corridor())
    d = m.to_dict()
    assert d["precision"] is None and d["mean_distance_m"] is None and d["recall"] == 0.0
    json.dumps(d)


def test_mismatched_grids_raise():
    other = corridor(grid=GridSpec(origin_x_m=1.0))
    with pytest.raises(ValueError, match="share the grid"):
        map_metrics(corridor(), other)
    with pytest.raises(TypeError, match="estimated"):
        map_metrics(np.zeros((120, 240)), corridor())


def test_recall_counts_only_the_visible_faces_of_thick_walls():
    from mrstereo.mapping import GridSpec, RosMap, map_metrics

    grid = GridSpec(width_m=1.0, height_m=1.0, resolution_m=0.1, origin_x_m=0.0, origin_y_m=0.0)
    truth = np.full(grid.shape, np.nan)
    truth[:, :6] = 0.0          # free corridor
    truth[:, 6:] = 1.0          # a wall four cells thick, its far side unknown to any sensor
    seen = np.full(grid.shape, np.nan)
    seen[:, :6] = 0.0
    seen[:, 6] = 1.0            # the camera sees the wall's face only
    m = map_metrics(RosMap(seen, grid), RosMap(truth, grid), tolerance_cells=0)
    assert m.recall == 1.0 and m.true_occupied_cells == 10 and m.precision == 1.0


@pytest.mark.parametrize("density", [0.002, 0.05, 0.6])
def test_grid_distance_and_dilation_equal_scipy(density):
    # The map metrics and the planner's inflation use OpenCV (scipy.ndimage costs 0.25 s of start-up):
    # the values must be scipy's exactly, also at the grid border.
    from scipy import ndimage

    from mrstereo.mapping.grid import dilate_cells, distance_cells

    rng = np.random.default_rng(7)
    for _ in range(20):
        mask = rng.random((int(rng.integers(1, 130)), int(rng.integers(1, 250)))) < density
        mask.flat[int(rng.integers(mask.size))] = True
        assert np.array_equal(distance_cells(mask), ndimage.distance_transform_edt(~mask))
        for r in (0, 1, 3):
            box = np.ones((2 * r + 1, 2 * r + 1), bool)
            assert np.array_equal(dilate_cells(mask, r), ndimage.binary_dilation(mask, structure=box))


def test_cells_in_view_follow_the_field_of_view_and_stop_at_walls():
    from mrstereo.mapping import cells_in_view

    truth = corridor()                                   # free rows 31..89 (y -1.45 .. 1.5), walls at 30, 90
    occ = truth.occupancy.copy()
    occ[60, 60] = 1.0                                    # a one-cell post 2 m ahead of the sensor
    truth = RosMap(occupancy=occ, grid=truth.grid)
    x0, y0 = GridSpec().xy_from_cells(60, 20)
    seen = cells_in_view(truth, [(x0, y0, 0.0, np.radians(30), 4.0)])
    assert seen[60, 21:60].all() and not seen[60, 61:].any()      # the post hides the cells behind it
    assert seen[70, 50] and not seen[85, 30]                      # inside / outside the 30 degree half-angle
    assert not seen[:30].any() and not seen[91:].any()            # never beyond the walls
    assert not seen[:, 101:].any()                                # 4 m range
    est = truth.occupancy.copy()
    est[seen] = 0.0
    est[~seen & (truth.occupancy == 0)] = np.nan
    m = map_metrics(RosMap(est, truth.grid), truth, views=[(x0, y0, 0.0, np.radians(30), 4.0)])
    assert m.free_coverage == 1.0 and m.free_precision == 1.0
    est[seen & (np.arange(240)[None, :] > 60)] = np.nan           # half of the view unknown
    half = map_metrics(RosMap(est, truth.grid), truth, views=[(x0, y0, 0.0, np.radians(30), 4.0)])
    assert 0.2 < half.free_coverage < 0.8
    est[25:28, 20:40] = 0.0                                       # cells mapped free behind a wall
    wrong = map_metrics(RosMap(est, truth.grid), truth)
    assert wrong.free_precision < 1.0 and np.isnan(wrong.free_coverage)
    with pytest.raises(ValueError, match="views"):
        cells_in_view(truth, [(0.0, 0.0, 0.0)])


def test_recall_in_view_counts_the_walls_some_frame_looked_at():
    truth = corridor()                                   # walls at rows 30 and 90, 240 columns
    x0, y0 = GridSpec().xy_from_cells(60, 20)
    view = [(x0, y0, 0.0, np.radians(60), 2.0)]          # sees the walls up to about column 55
    est = truth.occupancy.copy()
    est[[30, 90], 60:] = np.nan                          # walls beyond the view missing
    m = map_metrics(RosMap(est, truth.grid), truth, views=view)
    assert m.recall_in_view == 1.0 and m.recall == pytest.approx(122 / 480)   # (column 60 within tolerance)
    est[30, 30:45] = np.nan                              # 15 cells of a wall in view missing
    m = map_metrics(RosMap(est, truth.grid), truth, views=view)
    seen_surface = np.zeros(truth.grid.shape, bool)
    seen_surface[[30, 90]] = True
    seen_surface &= dilate_cells(cells_in_view(truth, view), 1)
    missed = seen_surface.copy()
    missed[30, 30 + 1:45 - 1] = False                    # the 1-cell tolerance keeps the two ends
    assert m.recall_in_view == pytest.approx(missed.sum() / seen_surface.sum())
    assert np.isnan(map_metrics(RosMap(est, truth.grid), truth).recall_in_view)
