"""``mrstereo synth`` on tiny outputs."""
from __future__ import annotations

import subprocess
import sys

from click.testing import CliRunner

from mrstereo.cli import entry, main
from mrstereo.recordings.manifest import read_manifest


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
