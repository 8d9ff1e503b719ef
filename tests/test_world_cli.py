"""``mrstereo synth`` and ``mrstereo demo`` on tiny outputs."""
from __future__ import annotations

import subprocess
import sys

from click.testing import CliRunner

from mrstereo.cli import entry, main
from mrstereo.world.dataset import read_manifest
from mrstereo.world.demo import write_world_demo


def test_synth_writes_a_readable_dataset(tmp_path):
    out = tmp_path / "ds"
    result = CliRunner().invoke(main, ["synth", "--out", str(out), "--frames", "2", "--width", "64",
                                       "--height", "48", "--seed", "1", "--quiet"])
    assert result.exit_code == 0, result.output
    assert "wrote 2 frames" in result.output
    m = read_manifest(out)
    assert len(m.frames) == 2 and m.calibration.size == (64, 48)


def test_synth_errors_are_one_line(tmp_path, capsys):
    (tmp_path / "full").mkdir()
    (tmp_path / "full" / "keep.txt").write_text("x")
    assert entry(["synth", "--out", str(tmp_path / "full"), "--frames", "1", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("mrstereo: error:") and "not empty" in err and err.count("\n") == 1
    assert (tmp_path / "full" / "keep.txt").read_text() == "x"


def test_synth_rejects_bad_options(tmp_path):
    result = CliRunner().invoke(main, ["synth", "--out", str(tmp_path / "x"), "--frames", "0"])
    assert result.exit_code != 0 and "frames" in result.output


def test_python_m_help():
    proc = subprocess.run([sys.executable, "-m", "mrstereo", "demo", "--help"], capture_output=True, text=True,
                          timeout=120)
    assert proc.returncode == 0 and "--out" in proc.stdout


def test_world_demo_writes_figures(tmp_path):
    written = write_world_demo(tmp_path / "demo", n_stops=1, width=64, height=48, progress=False)
    names = {p.name for p in written}
    assert {"gt_map.png", "frame_00_images.png", "frame_02_gt_disparity.png", "frame_01_left_raw.png"} <= names
    assert all(p.is_file() and p.stat().st_size > 0 for p in written)
    assert (tmp_path / "demo" / "gt_map.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
