"""A long drive fits: the map that grows along an L-shaped 1 km and 10 km path stays sparse in memory (peak
resident memory measured in a subprocess) and on disk (tiles.npz, an overview map, a dense map.pgm of the
area around the last pose); an absurd resolution is refused when the map is made, before any frame."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from mrstereo.mapping import MappingConfig, read_ros_map
from mrstereo.mapping.fusion import FrameObservation, fuse
from mrstereo.mapping.tiles import DENSE_MAP_MAX_CELLS, TiledOccupancyGrid

SRC = Path(__file__).resolve().parents[1] / "src"


def l_drive(length_m: float, step_m: float = 2.5, seed: int = 0):
    """Frames of an L-shaped drive (half the length along +x, then half along +y), each seeing a corridor's two
    walls 2 m to its sides (0.5-4 m ahead, 0.1-1 m high) and the floor between: obstacle and floor points
    synthesized in the world frame, no rendering. A generator: the observations are not kept."""
    rng = np.random.default_rng(seed)
    half = length_m / 2.0
    for k, s in enumerate(np.arange(0.0, length_m, step_m)):
        x, y, yaw = (s, 0.0, 0.0) if s < half else (half, s - half, math.pi / 2)
        ahead = rng.uniform(0.5, 4.0, 1000)
        side = np.where(rng.random(1000) < 0.5, 2.0, -2.0) + rng.normal(0.0, 0.01, 1000)
        walls = np.column_stack([ahead, side, rng.uniform(0.1, 1.0, 1000)])
        floor = np.column_stack([rng.uniform(0.5, 4.0, 1000), rng.uniform(-1.9, 1.9, 1000), np.zeros(1000)])
        c, sn = math.cos(yaw), math.sin(yaw)
        to_world = lambda p: np.column_stack([x + c * p[:, 0] - sn * p[:, 1], y + sn * p[:, 0] + c * p[:, 1],
                                              p[:, 2]]).astype(np.float32)
        yield FrameObservation(index=k, pose=(x, y, yaw), pan_rad=0.0, obstacle_points_world=to_world(walls),
                               floor_points_world=to_world(floor), n_valid_disparity=2000, ground_message="",
                               sensor_height_m=0.4)


def map_long_drive(length_m: float, out: str) -> dict:
    """Fuse the drive into a map that grows and write what ``mrstereo map`` writes of it (the calls of
    :func:`mrstereo.evaluation.outputs.write_map_outputs`); returns figures and the peak resident memory."""
    import resource
    import warnings

    from mrstereo.mapping import write_ros_map

    out_dir = Path(out)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        tiles = fuse(l_drive(length_m), grid=None, config=MappingConfig(), view_reach_m=6.0)
        last = (length_m / 2.0, length_m / 2.0 - 2.5)
        window = tiles.map_window(last)
    grid = tiles.to_grid(window)
    write_ros_map(out_dir / "map.yaml", grid.to_ros_map())
    grid.save_log_odds(out_dir / "log_odds.npy")
    tiles.save(out_dir / "tiles.npz")
    tiles.write_overview(out_dir / "overview.yaml")
    x0, x1, y0, y1 = tiles.extent_m()
    return {"peak_bytes": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024, "n_tiles": tiles.n_tiles,
            "tile_bytes": tiles.nbytes, "bounds": [x0, y0, x1 - x0, y1 - y0],
            "window": [window.origin_x_m, window.origin_y_m, window.width_m, window.height_m],
            "warnings": [str(w.message) for w in caught], "n_updates": tiles.n_updates}


def _run_in_subprocess(length_m: float, out: Path) -> dict:
    code = (f"import json, sys; sys.path.insert(0, {str(Path(__file__).parent)!r}); "
            f"from test_mapping_long_drive import map_long_drive; "
            f"print(json.dumps(map_long_drive({length_m!r}, {str(out)!r})))")
    env = {"PYTHONPATH": str(SRC), "MPLBACKEND": "Agg", "PATH": "/usr/bin:/bin"}
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=False)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("length_m", [1000.0, pytest.param(10000.0, marks=pytest.mark.slow)])
def test_an_l_shaped_drive_maps_in_under_2_gb_as_tiles_and_an_overview(tmp_path, length_m):
    result = _run_in_subprocess(length_m, tmp_path)
    assert result["peak_bytes"] < 2 * 1024 ** 3, result
    half = length_m / 2.0
    x0, y0, w, h = result["bounds"]                          # the whole L: about half the length each way
    assert x0 < 0.0 and y0 < -1.9 and half + 2.0 < x0 + w < half + 6.0 and half - 1.0 < y0 + h < half + 6.0
    # the tiles hold the corridor along the path (two 4 m wide legs), not the square of the bounding box
    corridor_cells = length_m * 8.0 / 0.05 ** 2
    cell_bytes = 8 + 8 + 8 + 2               # log-odds, obstacle heights, the height layer, drop votes
    assert (result["tile_bytes"] < 2 * cell_bytes * corridor_cells
            and result["tile_bytes"] < 0.1 * cell_bytes * w * h / 0.05 ** 2)
    assert result["n_updates"] == len(np.arange(0.0, length_m, 2.5))
    # map.pgm: the 2048 x 2048 cells around the last pose, said in one warning
    wx, wy, ww, wh = result["window"]
    assert ww * wh / 0.05 ** 2 == pytest.approx(DENSE_MAP_MAX_CELLS)
    assert wx <= half <= wx + ww and wy <= half - 2.5 <= wy + wh
    assert len([m for m in result["warnings"] if "tiles.npz" in m]) == 1
    ros = read_ros_map(tmp_path / "map.yaml")
    assert ros.grid.shape == (2048, 2048) and ros.occupied.sum() > 1000 and ros.free.sum() > 10000
    # the overview: a map_server map of coarse cells covering the whole L, walls occupied along both legs
    overview = read_ros_map(tmp_path / "overview.yaml")
    assert max(overview.grid.shape) <= 4096 and overview.grid.width_m >= w and overview.grid.height_m >= h
    occupied_xy = overview.grid.xy_from_cells(*np.nonzero(overview.occupied))
    on_leg1 = occupied_xy[(np.abs(np.abs(occupied_xy[:, 1]) - 2.0) < 2 * overview.grid.resolution_m)]
    on_leg2 = occupied_xy[(np.abs(np.abs(occupied_xy[:, 0] - half) - 2.0) < 2 * overview.grid.resolution_m)]
    assert on_leg1[:, 0].max() - on_leg1[:, 0].min() > 0.9 * half
    assert on_leg2[:, 1].max() - on_leg2[:, 1].min() > 0.9 * half
    assert (tmp_path / "tiles.npz").stat().st_size < 0.2 * result["tile_bytes"]     # compressed, sparse


def test_tiles_round_trip_and_the_overview_is_the_block_reduced_map(tmp_path):
    tiles = fuse(l_drive(120.0), grid=None, config=MappingConfig(), view_reach_m=6.0)
    tiles.save(tmp_path / "t.npz")
    back = TiledOccupancyGrid.load(tmp_path / "t.npz")
    assert back.bounds() == tiles.bounds() and back.n_tiles == tiles.n_tiles and back.n_updates == tiles.n_updates
    np.testing.assert_array_equal(back.to_grid().log_odds, tiles.to_grid().log_odds)
    np.testing.assert_array_equal(back.to_grid()._z_range_m, tiles.to_grid()._z_range_m)
    dense = tiles.to_grid()
    for max_px in (4096, 100, 3):
        image, grid = tiles.overview(max_px=max_px)
        k = round(grid.resolution_m / 0.05)
        assert max(image.shape) <= max_px and k & (k - 1) == 0
        level = np.zeros(grid.shape, np.uint8)                    # the same reduction on the dense grid
        r0 = round((dense.grid.origin_y_m - grid.origin_y_m) / 0.05)
        c0 = round((dense.grid.origin_x_m - grid.origin_x_m) / 0.05)
        rr, cc = np.mgrid[0:dense.grid.shape[0], 0:dense.grid.shape[1]]
        np.maximum.at(level, ((rr + r0) // k, (cc + c0) // k), dense.free.astype(np.uint8) + 2 * dense.occupied)
        np.testing.assert_array_equal(image, np.choose(level, np.array([205, 254, 0], np.uint8)))
    assert tiles.map_window() == tiles.bounds()                  # a small map: the whole of it, no warning
    with pytest.raises(FileNotFoundError, match="tiles file not found"):
        TiledOccupancyGrid.load(tmp_path / "missing.npz")
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(ValueError, match="cannot read tiles file"):
        TiledOccupancyGrid.load(tmp_path / "bad.npz")


def test_an_absurd_resolution_is_refused_when_the_map_is_made():
    with pytest.raises(ValueError, match="resolution_m and view_reach_m: one view's window"):
        TiledOccupancyGrid(0.0001, view_reach_m=6.0)
    TiledOccupancyGrid(0.01, view_reach_m=6.0)                   # 1 cm: fits
