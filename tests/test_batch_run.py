"""mrstereo batch: per-frame files and maps of several datasets, resumable, failures listed, on Dask."""
from __future__ import annotations

import json
import math
import shutil

import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.geometry import read_ply, read_scan_json
from mrstereo.io import read_disparity, read_image, write_disparity
from mrstereo.mapping.fusion import fuse
from mrstereo.pipeline.batch import SUMMARY_NAME, frame_outputs, run_batch
from mrstereo.geometry.pair import scan_from_pair
from mrstereo.pipeline.run import PipelineConfig, build_map
from mrstereo.recordings.manifest import read_manifest


@pytest.fixture(scope="module")
def datasets(synthetic_dataset):
    """Two datasets, folders ``corridor1`` and ``corridor2`` (their names in the batch's output)."""
    return [synthetic_dataset(seed=seed, n_frames=3, width=160, height=120, supersample=1) for seed in (1, 2)]


def _tree(path):
    return {p.relative_to(path): p.stat().st_mtime_ns for p in path.rglob("*") if p.is_file()}


def test_batch_writes_frames_and_maps_equal_to_the_single_commands(datasets, tmp_path):
    out = tmp_path / "out"
    summary = run_batch(datasets, out, progress=False)
    assert [d.name for d in summary.datasets] == ["corridor1", "corridor2"]
    assert all(d.n_computed == 3 and d.n_failed == 0 and d.map_status == "written" for d in summary.datasets)
    m = read_manifest(datasets[0])
    files = frame_outputs(out / "corridor1" / "frames", 1)
    rec = m.frames[1]
    ref = scan_from_pair(read_image(rec.left_rect), read_image(rec.right_rect), m.calibration, rectified=True,
                         mount=m.mount, pan_rad=rec.pan_rad, config=PipelineConfig().for_rig(m.calibration).obstacles)
    assert np.array_equal(read_disparity(files["disparity"]), ref.frame.disparity_px, equal_nan=True)
    assert np.allclose(read_scan_json(files["scan"]).ranges_m, ref.scan.ranges_m, equal_nan=True)
    cloud = read_ply(files["cloud"])
    assert cloud.points.shape == ref.frame.obstacles.points_robot.shape and cloud.intensity is not None
    for name, path in zip(("corridor1", "corridor2"), datasets):
        expected = build_map(path, progress=False).grid.log_odds
        assert np.array_equal(np.load(out / name / "map" / "log_odds.npy"), expected, equal_nan=True)
        assert (out / name / "map" / "map.yaml").is_file()
    data = json.loads((out / SUMMARY_NAME).read_text())
    assert data["failures"] == [] and data["datasets"][1]["frames"] == 3
    assert not [p for p in out.rglob("*") if ".tmp" in p.name]                # no temporary leftovers


def test_rerun_skips_finished_outputs_and_redoes_missing_ones(datasets, tmp_path):
    out = tmp_path / "out"
    run_batch(datasets, out, progress=False)
    before = _tree(out)
    again = run_batch(datasets, out, progress=False)
    assert all(d.n_computed == 0 and d.n_skipped == 3 and d.map_status == "kept" for d in again.datasets)
    after = _tree(out)
    assert {k: v for k, v in after.items() if k.name != SUMMARY_NAME} == \
        {k: v for k, v in before.items() if k.name != SUMMARY_NAME}
    frame_outputs(out / "corridor2" / "frames", 2)["cloud"].unlink()            # an interrupted frame
    third = run_batch(datasets, out, progress=False)
    beta = third.datasets[1]
    assert (beta.n_computed, beta.n_skipped, beta.map_status) == (1, 2, "written")
    assert third.datasets[0].map_status == "kept"
    expected = build_map(datasets[1], progress=False).grid.log_odds
    assert np.array_equal(np.load(out / "corridor2" / "map" / "log_odds.npy"), expected, equal_nan=True)
    unchanged = frame_outputs(out / "corridor2" / "frames", 0)["disparity"].relative_to(out)
    assert _tree(out)[unchanged] == before[unchanged]


def test_failed_frame_is_listed_the_rest_goes_on_and_a_rerun_retries_it(datasets, tmp_path, capsys):
    broken = tmp_path / "gamma"
    shutil.copytree(datasets[0], broken)
    image = read_manifest(broken).frames[1].left_rect
    good = image.read_bytes()
    image.write_bytes(b"not a png")
    out = tmp_path / "out"
    code = entry(["batch", str(broken), str(datasets[1]), "-o", str(out), "--quiet"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1
    assert err[0].startswith("mrstereo: error: 1 frame(s) failed") and "gamma frame 1" in err[0]
    data = json.loads((out / SUMMARY_NAME).read_text())
    assert data["failures"][0]["frame"] == 1 and "cannot decode image" in data["failures"][0]["error"]
    assert data["datasets"][0]["map"] == "written from 2 of 3 frames" and data["datasets"][1]["failed"] == 0
    assert not frame_outputs(out / "gamma" / "frames", 1)["disparity"].exists()
    assert frame_outputs(out / "gamma" / "frames", 2)["disparity"].exists()
    image.write_bytes(good)
    summary = run_batch([broken, datasets[1]], out, progress=False)
    assert (summary.datasets[0].n_computed, summary.datasets[0].map_status) == (1, "written")
    assert summary.failures == ()
    expected = build_map(broken, progress=False).grid.log_odds
    assert np.array_equal(np.load(out / "gamma" / "map" / "log_odds.npy"), expected, equal_nan=True)


@pytest.mark.filterwarnings("ignore:no metrics")                 # (the ground truth is on 5 cm cells)
def test_a_rerun_with_another_resolution_writes_the_map_again(datasets, tmp_path):
    out = tmp_path / "out"
    run_batch(datasets[:1], out, progress=False)
    summary = run_batch(datasets[:1], out, config=PipelineConfig(resolution_m=0.1), progress=False)
    assert (summary.datasets[0].n_computed, summary.datasets[0].map_status) == (0, "written")   # frames kept
    assert "resolution: 0.1" in (out / "corridor1" / "map" / "map.yaml").read_text()
    expected = build_map(datasets[0], config=PipelineConfig(resolution_m=0.1), progress=False).grid.log_odds
    assert np.array_equal(np.load(out / "corridor1" / "map" / "log_odds.npy"), expected, equal_nan=True)


def test_an_edited_map_or_frame_file_is_written_again(datasets, tmp_path):
    out = tmp_path / "out"
    run_batch(datasets[:1], out, progress=False)
    pgm = out / "corridor1" / "map" / "map.pgm"
    disparity = frame_outputs(out / "corridor1" / "frames", 1)["disparity"]
    originals = {path: path.read_bytes() for path in (pgm, disparity)}
    data = bytearray(originals[pgm])
    data[-1] ^= 0xFF                                        # one cell changed, the file still a valid image
    pgm.write_bytes(bytes(data))
    edited = read_disparity(disparity)
    edited[edited == edited] += 1.0                         # still a valid PFM, every disparity off by 1 px
    write_disparity(disparity, edited)
    summary = run_batch(datasets[:1], out, progress=False)
    assert (summary.datasets[0].n_computed, summary.datasets[0].map_status) == (1, "written")
    assert all(path.read_bytes() == data for path, data in originals.items())
    again = run_batch(datasets[:1], out, progress=False)
    assert (again.datasets[0].n_computed, again.datasets[0].map_status) == (0, "kept")


def test_the_files_of_frames_that_left_the_recording_are_removed(datasets, tmp_path):
    import yaml

    ds = tmp_path / "corridor1"
    shutil.copytree(datasets[0], ds)
    out = tmp_path / "out"
    run_batch([ds], out, progress=False)
    frames_dir = out / "corridor1" / "frames"
    (frames_dir / "notes.txt").write_text("mine\n")                   # not mrstereo's: stays
    data = yaml.safe_load((ds / "manifest.yaml").read_text())
    data["frames"] = data["frames"][:2]
    (ds / "manifest.yaml").write_text(yaml.safe_dump(data))
    summary = run_batch([ds], out, progress=False)
    assert (summary.datasets[0].n_frames, summary.datasets[0].map_status) == (2, "written")
    assert sorted(p.name for p in frames_dir.iterdir()) == sorted(
        [p.name for k in (0, 1) for p in frame_outputs(frames_dir, k).values()] + ["notes.txt"])
    expected = build_map(ds, progress=False).grid.log_odds
    assert np.array_equal(np.load(out / "corridor1" / "map" / "log_odds.npy"), expected, equal_nan=True)


@pytest.mark.extra("scale")
def test_batch_on_a_dask_cluster_gives_the_same_files(datasets, tmp_path):
    import distributed
    local = tmp_path / "local"
    run_batch(datasets[:1], local, progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=":0") as cluster:
        summary = run_batch(datasets[:1], tmp_path / "dask", scheduler=cluster.scheduler_address, progress=False)
    assert summary.datasets[0].n_computed == 3
    for k in range(3):
        a = frame_outputs(local / "corridor1" / "frames", k)
        b = frame_outputs(tmp_path / "dask" / "corridor1" / "frames", k)
        for key in ("disparity", "cloud", "scan"):
            assert a[key].read_bytes() == b[key].read_bytes(), (k, key)
    assert np.array_equal(np.load(local / "corridor1" / "map" / "log_odds.npy"),
                          np.load(tmp_path / "dask" / "corridor1" / "map" / "log_odds.npy"), equal_nan=True)


def test_map_command_build_map_fuse_and_batch_give_one_map_and_one_set_of_metrics(synthetic_dataset, tmp_path, capsys):
    """Library defaults are the CLI's: ``mrstereo map``, ``build_map`` and ``fuse`` of its observations (default
    configs) give the same map, bit for bit; ``batch`` gives that map and the same metrics (along the true path,
    with the fields of view), also when it rebuilds the map from the observations it saved."""
    ds = synthetic_dataset(seed=3, n_frames=6, width=160, height=120, supersample=1,
                           odometry_noise=(0.05, math.radians(4.0)))
    manifest = read_manifest(ds)
    assert any(f.pose != f.true_pose for f in manifest.frames)          # metrics follow the true path
    assert entry(["map", str(ds), "-o", str(tmp_path / "map"), "--quiet"]) == 0
    log_odds = np.load(tmp_path / "map" / "log_odds.npy")
    run = build_map(ds, progress=False)
    assert np.array_equal(run.grid.log_odds, log_odds, equal_nan=True)
    assert np.array_equal(fuse(run.observations, grid=run.grid.grid).log_odds, log_odds, equal_nan=True)
    assert any(o.boundary_points for o in run.observations)
    metrics = json.loads((tmp_path / "map" / "metrics.json").read_text())
    assert metrics["free_coverage"] is not None and metrics["recall_in_view"] is not None
    for attempt in ("computed", "rebuilt from the saved observations"):
        if attempt != "computed":
            shutil.rmtree(tmp_path / "batch" / ds.name / "map")
        assert entry(["batch", str(ds), "-o", str(tmp_path / "batch"), "--quiet"]) == 0, attempt
        assert np.array_equal(np.load(tmp_path / "batch" / ds.name / "map" / "log_odds.npy"), log_odds,
                              equal_nan=True), attempt
        assert json.loads((tmp_path / "batch" / ds.name / "map" / "metrics.json").read_text()) == metrics, attempt
    for obs in run.observations:                                   # the saved observations keep the boundary rows
        with np.load(frame_outputs(tmp_path / "batch" / ds.name / "frames", obs.index)["observation"]) as saved:
            assert int(saved["boundary_points"]) == obs.boundary_points
            assert np.array_equal(saved["obstacle_points_world"], obs.obstacle_points_world)
    capsys.readouterr()


def test_bad_batch_input(datasets, tmp_path, capsys):
    with pytest.raises(FileNotFoundError, match="recording not found"):
        run_batch([datasets[0], tmp_path / "nothing"], tmp_path / "o", progress=False)
    assert not (tmp_path / "o").exists()                    # validated before any work
    with pytest.raises(ValueError, match="is the dataset"):
        run_batch([datasets[0]], datasets[0], progress=False)
    code = entry(["batch", str(datasets[0]), "-o", str(tmp_path / "o2"), "--workers", "0"])
    assert code == 2 and "--workers" in capsys.readouterr().err
