"""The drop benchmark's diagnostic of missed edge cells (benchmarks/bench_drops.py, ``missed_causes``)."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from mrstereo.geometry.drops import DropConfig

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))

FIXED = DropConfig(noise_from_floor=False, n_sigma=3.0)
"""The drop test with a fixed noise margin (3 sigma of 0.25 px): the diagnostic's cases below hold for it."""


@pytest.fixture(scope="module")
def first_stop(tmp_path_factory):
    """Tuning seed 0's world with drops, the three views of its first stop, mapped with the drop test (its noise
    margin fixed: :data:`FIXED`)."""
    from bench_drops import paired_maps

    from mrstereo.world import read_manifest, write_synthetic_dataset

    ds = tmp_path_factory.mktemp("drops") / "seed0"
    write_synthetic_dataset(ds, seed=0, n_frames=3, progress=False, randomize=True, drops=True)
    manifest = read_manifest(ds)
    run, _ = paired_maps(manifest, drops=FIXED)
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
    causes = missed_causes(manifest, grid, drop, run.range_m, drops=FIXED)
    assert sum(causes.values()) == drop.sum()
    detected = sum(causes[k] for k in causes if k.startswith("d: "))
    assert detected + causes["c: candidate not confirmed"] == drop.sum()
    assert causes["d: drop points in a frame, lost in the map"] > 0
    x0, y0 = manifest.frames[0].pose[:2]
    for xy, cause in (((x0 - 1.5, y0), "a: no pixel sees it"),
                      ((x0 + 0.6, y0 + 0.3), "b: floor only, nothing below measured near")):
        one = np.zeros(grid.shape, bool)
        r, c = grid.cells_from_xy(np.array([xy]))
        one[r[0], c[0]] = True
        counts = missed_causes(manifest, grid, one, run.range_m, drops=FIXED)
        assert counts[cause] == 1, counts
    assert set(causes) == set(CAUSES)


def test_oracle_disparity_feeds_the_chain_the_true_disparity(first_stop):
    """Inside ``oracle_disparity`` the chain's disparity before eq. (13) is the frame's true one wherever it is
    valid, NaN where the match falls outside the right image; outside it the matcher's again; an image of no
    frame of the recording raises."""
    from bench_drops import oracle_disparity

    from mrstereo.geometry.pair import obstacles_from_pair
    from mrstereo.io.images import read_pfm
    from mrstereo.recordings.manifest import frame_pair

    manifest, _ = first_stop
    record = manifest.frames[1]
    left, right, rectified = frame_pair(record)
    truth = read_pfm(record.gt_disparity)
    pair = lambda a, b: obstacles_from_pair(a, b, manifest.calibration, rectified=rectified,   # noqa: E731
                                            mount=manifest.mount, pan_rad=record.pan_rad)
    with oracle_disparity(manifest) as used:
        frame = pair(left, right)
        with pytest.raises(KeyError):
            pair(right, left)
    assert used == [1]
    raw = frame.raw_disparity_px
    valid = np.isfinite(raw)
    assert valid.mean() > 0.8
    np.testing.assert_array_equal(raw[valid], truth[valid])
    assert not valid[np.arange(truth.shape[1])[None, :] - truth < 0].any()
    assert np.isfinite(frame.disparity_px).sum() < valid.sum()          # eq. (13) still rejects
    matched = pair(left, right).raw_disparity_px
    both = np.isfinite(matched) & valid
    assert not np.array_equal(matched[both], truth[both])


@pytest.mark.parametrize("argv, name", [(["--drop-weak-share", "1.5"], "drop_weak_share"),
                                        (["--fattening-px", "-2"], "fattening_px"),
                                        (["--n-sigma", "nan"], "n_sigma")])
def test_a_bad_tuning_value_is_one_line_naming_it_and_exit_2(monkeypatch, capsys, argv, name):
    from bench_drops import main

    monkeypatch.setattr(sys, "argv", ["bench_drops.py", "--seeds", "0", *argv])
    with pytest.raises(SystemExit) as exit_:
        main()
    assert exit_.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("bench_drops.py: error: ") and name in err and "Traceback" not in err
