"""Mapping resumed from a saved map (``map --resume-from map.yaml``, ``StereoMapper(prior=...)``): the first half
of a drive saved, the second half mapped on it, compared with the whole drive mapped at once."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.mapping import GridSpec, MappingConfig, RosMap
from mrstereo.mapping.prior import prior_grid, prior_log_odds
from mrstereo.mapping.rosmap import array_on_grid, read_ros_map, write_ros_map
from mrstereo.pipeline.run import build_map
from mrstereo.recordings.manifest import read_manifest


@pytest.fixture(scope="module")
def drive(synthetic_dataset):
    return read_manifest(synthetic_dataset(seed=5, n_frames=16, width=160, height=120, supersample=1))


def _halves(manifest):
    h = len(manifest.frames) // 2
    return (dataclasses.replace(manifest, frames=manifest.frames[:h]),
            dataclasses.replace(manifest, frames=manifest.frames[h:]))


def _classes(grid):
    """-1 unknown, 0 free, 1 occupied."""
    return np.where(grid.unknown, -1, np.where(grid.occupied, 1, 0))


def _map(manifest, **kw):
    return build_map(manifest, progress=False, check_mount=False, **kw).grid


def test_the_second_half_on_the_saved_first_half_is_the_whole_drive(drive, tmp_path):
    """On the ground-truth map's window: the saved PGM as the prior agrees with mapping the whole drive on 97 %
    of the cells either knows (measured 98.9 %: a saved cell keeps its class, not its count of views); the first
    half's grid itself as the prior gives the whole drive's log-odds exactly."""
    first, second = _halves(drive)
    whole, a = _map(drive), _map(first)
    write_ros_map(tmp_path / "a.yaml", a.to_ros_map())
    resumed = _map(second, prior=tmp_path / "a.yaml")
    assert resumed.grid == whole.grid
    W, R = _classes(whole), _classes(resumed)
    known = (W >= 0) | (R >= 0)
    assert known.sum() > 5000 and (W == R)[known].mean() > 0.97
    exact = _map(second, prior=a)
    np.testing.assert_allclose(np.nan_to_num(exact.log_odds, nan=99.0), np.nan_to_num(whole.log_odds, nan=99.0),
                               atol=1e-9)


def test_a_resumed_map_keeps_what_only_the_first_half_saw_and_covers_both(drive, tmp_path, capsys):
    """A map that grows (no fixed window): the obstacles only the first half saw stay, the map covers both."""
    first, second = (dataclasses.replace(m, ground_truth_map=None) for m in _halves(drive))
    a, b = _map(first), _map(second)
    write_ros_map(tmp_path / "a.yaml", a.to_ros_map())
    resumed = _map(second, prior=tmp_path / "a.yaml")
    A, B = _classes(a), _classes(b)
    B_on_a = np.nan_to_num(array_on_grid(B.astype(float), b.grid, a.grid), nan=-1)
    only_first = (A == 1) & (B_on_a == -1)             # occupied in the first half, never seen by the second
    assert only_first.sum() > 100
    R_on_a = array_on_grid(_classes(resumed).astype(float), resumed.grid, a.grid)
    R_on_b = array_on_grid(_classes(resumed).astype(float), resumed.grid, b.grid)
    assert (R_on_a[only_first] == 1).all()
    # it covers both: every cell the first half knows, and the second half's (but for a few behind the walls the
    # prior holds: map_occlusion_p makes them solid for the second half's rays)
    assert not np.isnan(R_on_a[A >= 0]).any()
    assert np.mean(~np.isnan(R_on_b[B >= 0])) > 0.95
    # the command line: the same, and another resolution refused in one line
    out = tmp_path / "out"
    assert entry(["map", str(drive.root), "-o", str(out), "--resume-from", str(tmp_path / "a.yaml"), "--quiet"]) == 0
    assert read_ros_map(out / "map.yaml").occupied.sum() > 0
    capsys.readouterr()
    assert entry(["map", str(drive.root), "-o", str(tmp_path / "r2"), "--resume-from", str(tmp_path / "a.yaml"),
                  "--resolution", "0.1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "a.yaml has cells of 0.05 m" in err and "--resolution 0.05" in err
    assert not (tmp_path / "r2" / "map.yaml").exists()


def test_the_log_odds_a_saved_cell_gets(tmp_path):
    config = MappingConfig()
    grid = GridSpec(width_m=0.2, height_m=0.1, resolution_m=0.05, origin_x_m=-0.1, origin_y_m=0.0)
    occupancy = np.array([[1.0, 0.0, np.nan, 0.8], [0.3, 0.1, 0.5, 0.99]])
    log_odds = prior_log_odds(RosMap(occupancy=occupancy, grid=grid), config)
    logit = lambda p: math.log(p / (1 - p))                                         # noqa: E731
    expected = [[config.l_max, config.l_min, np.nan, logit(0.8)],                   # above 0.65: occupied
                [np.nan, config.l_min, np.nan, config.l_max]]                     # 0.3, 0.5: unknown (map_server)
    np.testing.assert_allclose(log_odds, expected)
    seeded = prior_grid(RosMap(occupancy=occupancy, grid=grid), config=config, resolution_m=0.05,
                        grid=GridSpec(width_m=0.3, height_m=0.1, resolution_m=0.05, origin_x_m=-0.15, origin_y_m=0.0))
    np.testing.assert_allclose(seeded.log_odds[:, 1:5], expected)
    assert np.isnan(seeded.log_odds[:, [0, 5]]).all()
    with pytest.raises(ValueError, match="origin .* is not a whole number of 0.05 m cells"):
        prior_grid(RosMap(occupancy=occupancy, grid=grid), config=config, resolution_m=0.05,
                   grid=GridSpec(width_m=0.3, height_m=0.1, resolution_m=0.05, origin_x_m=-0.13, origin_y_m=0.0))
    with pytest.raises(ValueError, match="cells of 0.05 m, the map is made of 0.1 m cells"):
        prior_grid(RosMap(occupancy=occupancy, grid=grid), config=config, resolution_m=0.1)
