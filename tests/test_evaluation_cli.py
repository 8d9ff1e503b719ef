"""evaluate_scenes and the ``mrstereo evaluate`` command: report content, JSON/markdown files, errors."""
import json

import numpy as np
import pytest

from mrstereo.cli import entry
from mrstereo.evaluation.baselines import stereo_sgbm
from mrstereo.evaluation.datasets import load_scene
from mrstereo.evaluation.metrics import disparity_metrics
from mrstereo.evaluation.report import evaluate_scenes, run_method
from mrstereo.recordings.samples import local_path

TSUKUBA = local_path("tsukuba")
needs_data = pytest.mark.sample_data("tsukuba")
BASELINES = ("StereoBM", "StereoSGBM")


@needs_data
def test_evaluate_scenes_rows_match_direct_metrics():
    report = evaluate_scenes([TSUKUBA], methods=BASELINES, progress=False)
    assert report.methods == BASELINES and report.scenes == ("tsukuba",)
    assert [(r.scene, r.method) for r in report.rows] == [("tsukuba", "StereoBM"), ("tsukuba", "StereoSGBM")]
    scene = load_scene(TSUKUBA)
    direct = disparity_metrics(stereo_sgbm(scene.left, scene.right, max_disparity_px=16), scene.gt_disparity_px,
                               nonocc_mask=scene.nonocc_mask)
    row = report.row("tsukuba", "StereoSGBM")
    assert row.metrics == direct and row.seconds > 0 and row.max_disparity_px == 16
    assert report.mean("StereoSGBM")["bad_2_dense_pct"] == pytest.approx(direct.dense.bad_2_pct)
    with pytest.raises(KeyError, match="no row"):
        report.row("tsukuba", "mrstereo")


@needs_data
def test_cli_writes_json_and_markdown(tmp_path, capsys):
    out_json, out_md = tmp_path / "r.json", tmp_path / "sub" / "r.md"
    code = entry(["evaluate", str(TSUKUBA), str(TSUKUBA), "--methods", "StereoBM,StereoSGBM",
                  "--json", str(out_json), "--markdown", str(out_md), "--max-disparity", "32", "--quiet"])
    assert code == 0
    printed = capsys.readouterr().out
    assert printed == out_md.read_text()
    data = json.loads(out_json.read_text())
    assert data["methods"] == list(BASELINES)
    assert data["scenes"] == ["tsukuba", "middlebury2001/tsukuba"]  # a repeated name gets the layout prefix
    assert len(data["rows"]) == 4 and {r["max_disparity_px"] for r in data["rows"]} == {32}
    bm = data["rows"][0]
    assert bm["method"] == "StereoBM" and 0 < bm["metrics"]["dense"]["bad_2_pct"] < 30
    assert data["mean"]["StereoSGBM"]["density_pct"] > 90
    table = [line for line in printed.splitlines() if line.startswith("| tsukuba |")]
    assert len(table) == 3  # headline row + one detail row per method
    cells = table[0].split("|")
    assert cells[4].strip() == "32" and len(cells) == 2 + 4 + 2


def test_json_has_no_nan(tmp_path):
    rng = np.random.default_rng(0)
    from mrstereo.io import write_image, write_pfm
    img = rng.integers(0, 256, (20, 40), dtype=np.uint8)
    write_image(tmp_path / "im0.png", img)
    write_image(tmp_path / "im1.png", np.zeros_like(img))  # BM finds nothing: estimated stats are NaN
    write_pfm(tmp_path / "disp0.pfm", np.full((20, 40), 3.0, np.float32))
    report = evaluate_scenes([tmp_path], methods=["StereoBM"], progress=False)
    assert report.rows[0].metrics.density_pct == 0.0
    text = report.to_json()
    assert "NaN" not in text and json.loads(text)["rows"][0]["metrics"]["estimated"]["bad_2_pct"] is None
    assert "n/a" in report.to_markdown()


def test_cli_errors(tmp_path, capsys):
    assert entry(["evaluate", str(tmp_path / "nope"), "--methods", "StereoBM"]) == 2
    assert "mrstereo: error: scene directory not found" in capsys.readouterr().err
    assert entry(["evaluate", str(tmp_path), "--methods", "StereoBM"]) == 2
    assert "matches no known stereo dataset layout" in capsys.readouterr().err
    assert entry(["evaluate", str(tmp_path), "--methods", "StereoBM,Census"]) == 2
    assert "unknown method(s) Census" in capsys.readouterr().err
    assert entry(["evaluate", str(tmp_path), "--max-disparity", "0", "--methods", "StereoBM"]) == 2
    assert "'--max-disparity': 0 is not in the range [1, 4096] px" in capsys.readouterr().err
    assert entry(["evaluate", str(tmp_path), "--json", str(tmp_path), "--methods", "StereoBM"]) == 2
    capsys.readouterr()
    (tmp_path / "disp0.md").write_text("keep")
    assert entry(["evaluate", str(tmp_path), "--markdown", str(tmp_path / "disp0.md"), "--methods", "StereoBM"]) == 2
    assert "lies inside the scene" in capsys.readouterr().err
    assert (tmp_path / "disp0.md").read_text() == "keep"


def test_library_errors():
    with pytest.raises(ValueError, match="unknown method"):
        evaluate_scenes([TSUKUBA], methods=["SAD"], progress=False)
    with pytest.raises(ValueError, match="at least one scene"):
        evaluate_scenes([], methods=BASELINES, progress=False)
    with pytest.raises(ValueError, match="duplicates"):
        evaluate_scenes([TSUKUBA], methods=["StereoBM", "StereoBM"], progress=False)
    with pytest.raises(ValueError, match="unknown method"):
        run_method("SAD", None)


@needs_data
def test_mrstereo_methods_are_wired_in(monkeypatch):
    """Both mrstereo methods call compute_disparity with the scene's range and their preset."""
    matching = pytest.importorskip("mrstereo.matching")
    if not hasattr(matching, "compute_disparity"):
        pytest.skip("mrstereo.matching.compute_disparity is not built yet")
    calls = []

    class Result:
        def __init__(self, disparity_px):
            self.disparity_px = disparity_px

    def fake(left, right, *, max_disparity_px=None, preset="robust", **kwargs):
        calls.append((left.shape, max_disparity_px, preset))
        return Result(np.full(left.shape[:2], 7.0, np.float32))

    monkeypatch.setattr(matching, "compute_disparity", fake)
    report = evaluate_scenes([TSUKUBA], methods=("mrstereo", "mrstereo-paper"), max_disparity_px=20, progress=False)
    assert calls[-2:] == [((288, 384, 3), 20, "robust"), ((288, 384, 3), 20, "paper")]
    scene = load_scene(TSUKUBA)
    expected = disparity_metrics(np.full(scene.shape, 7.0, np.float32), scene.gt_disparity_px,
                                 nonocc_mask=scene.nonocc_mask)
    assert report.row("tsukuba", "mrstereo-paper").metrics == expected


@needs_data
@pytest.mark.extra("scale")
def test_evaluate_on_a_dask_cluster_gives_the_same_rows():
    import distributed

    venus = local_path("venus")
    local = evaluate_scenes([TSUKUBA, venus], methods=BASELINES, progress=False)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=None) as cluster:
        remote = evaluate_scenes([TSUKUBA, venus], methods=BASELINES, progress=False,
                                 scheduler=cluster.scheduler_address)
    assert [(r.scene, r.method) for r in remote.rows] == [(r.scene, r.method) for r in local.rows]
    assert [r.metrics for r in remote.rows] == [r.metrics for r in local.rows]


def test_cli_evaluates_a_synth_dataset_frame_by_frame(tmp_path, capsys):
    """`mrstereo evaluate` on what `mrstereo synth` writes: one row per frame, scored against its PFM."""
    ds = tmp_path / "corridor"
    assert entry(["synth", "--out", str(ds), "--frames", "2", "--width", "160", "--height", "120",
                  "--quiet"]) == 0
    out = tmp_path / "r.json"
    code = entry(["evaluate", str(ds), "--methods", "StereoSGBM", "--json", str(out), "--quiet"])
    assert code == 0, capsys.readouterr().err
    report = json.loads(out.read_text())
    assert report["scenes"] == ["corridor/000000", "corridor/000001"]
    scene = load_scene(ds, frame="000001")
    direct = disparity_metrics(stereo_sgbm(scene.left, scene.right, max_disparity_px=scene.max_disparity_px),
                               scene.gt_disparity_px)
    row = report["rows"][1]
    assert row["layout"] == "mrstereo" and row["max_disparity_px"] == scene.max_disparity_px
    assert row["metrics"]["dense"]["bad_2_pct"] == pytest.approx(direct.dense.bad_2_pct)
    assert row["metrics"]["estimated"]["bad_2_pct"] < 25      # SGBM on the textured corridor
