"""``mrstereo demo`` end to end on a short run: every stage against ground truth."""
import json

import pytest

from mrstereo.cli import entry
from mrstereo.demo import DEMO_STEPS, run_demo


@pytest.mark.slow
def test_demo_runs_the_whole_pipeline(tmp_path, capsys):
    result = run_demo(tmp_path / "demo", n_frames=6, n_calibration_views=6, progress=True)
    # the progress bar names the step that is running (before it finishes) and ends at 100 %
    bar = [line.strip() for line in capsys.readouterr().err.replace("\r", "\n").splitlines() if line.strip()]
    for k, name in enumerate(DEMO_STEPS):
        assert any(line.startswith(f"demo: {name}:") and f" {k}/{len(DEMO_STEPS)} " in line for line in bar), name
    assert bar[-1].startswith("demo: done: 100%") and f"{len(DEMO_STEPS)}/{len(DEMO_STEPS)}" in bar[-1]
    m = result.metrics
    c = m["calibration"]
    assert c["pairs_used"] >= 4
    assert abs(c["focal_error_pct"]) < 0.5 and c["principal_point_error_px"] < 2.0
    assert c["rectified_vertical_error_px"] < 0.5 and abs(c["baseline_m"] - c["true_baseline_m"]) < 0.002
    assert c["paper_ga_single_view_rms_px"] < 1.0
    assert m["frame0"]["matching_vs_gt"]["bad2_estimated"] < 0.05
    assert m["map"]["precision"] > 0.8 and m["map"]["recall"] > 0.3      # 2 stops see part of the corridor
    assert m["plan"]["success"]
    for name in ("report.md", "metrics.json", "disparity.png", "top_view.png", "world_frame0.png",
                 "calibration/stereo.yaml", "calibration/residuals_left.png", "map/map.png", "map/map.yaml",
                 "map/map.pgm", "map/log_odds.npy", "map/map_union.png"):
        assert (result.out_dir / name).is_file(), name
    assert json.loads((result.out_dir / "metrics.json").read_text())["plan"]["success"]
    assert "![map](map/map.png)" in result.report.read_text()


def test_demo_refuses_a_non_empty_directory(tmp_path, capsys):
    (tmp_path / "keep.txt").write_text("x")
    assert entry(["demo", "--out", str(tmp_path), "--quiet"]) == 2
    assert "not empty" in capsys.readouterr().err
    assert (tmp_path / "keep.txt").read_text() == "x"
