"""The drop benchmark's diagnostic of missed edge cells (benchmarks/bench_drops.py, ``missed_causes``)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))


@pytest.fixture(scope="module")
def first_stop(tmp_path_factory):
    """Tuning seed 0's world with drops, the three views of its first stop, mapped with the drop test."""
    from bench_drops import paired_maps

    from mrstereo.world import read_manifest, write_synthetic_dataset

    ds = tmp_path_factory.mktemp("drops") / "seed0"
    write_synthetic_dataset(ds, seed=0, n_frames=3, progress=False, randomize=True, drops=True)
    manifest = read_manifest(ds)
    run, _ = paired_maps(manifest)
    return manifest, run


def test_missed_causes_tell_apart_cells_detected_unseen_and_plain_floor(first_stop):
    """Cells the map's drop layer holds were detected in a frame (d, or c for a confirmed candidate); a cell
    behind the robot is seen by no pixel (a); a floor cell 0.5 m ahead, far from any drop, was measured with
    nothing below the floor near it (b, floor only); every cell gets exactly one cause."""
    from bench_drops import CAUSES, missed_causes

    manifest, run = first_stop
    grid = run.grid.grid
    drop = run.grid.drop.copy()
    assert drop.sum() >= 5
    causes = missed_causes(manifest, grid, drop, run.range_m)
    assert sum(causes.values()) == drop.sum()
    assert causes["d: detected in a frame, lost in the map"] + causes["c: candidate not confirmed"] == drop.sum()
    x0, y0 = manifest.frames[0].pose[:2]
    for xy, cause in (((x0 - 1.5, y0), "a: no pixel sees it"),
                      ((x0 + 0.6, y0 + 0.3), "b: floor only, nothing below measured near")):
        one = np.zeros(grid.shape, bool)
        r, c = grid.cells_from_xy(np.array([xy]))
        one[r[0], c[0]] = True
        counts = missed_causes(manifest, grid, one, run.range_m)
        assert counts[cause] == 1, counts
    assert set(causes) == set(CAUSES)
