"""Inputs that parse but make no sense: stamps that do not increase or do not fit, two videos that are no stereo
pair (sizes, rates, lengths), poses that are no poses. Nonsense is one line ``mrstereo: error: ...`` before any
work; what is suspicious but legal runs with one line ``mrstereo: warning: ...`` (docs/errors.md).
"""
from __future__ import annotations

import re
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from mrstereo.cli import entry


@pytest.fixture(scope="module")
def ds(synthetic_dataset) -> Path:
    return synthetic_dataset(seed=1, n_frames=3, width=160, height=120, supersample=1)


def _lines(capsys) -> tuple[list[str], str]:
    captured = capsys.readouterr()
    return [line for line in captured.err.splitlines() if line.strip()], captured.out


def _error(capsys, args, must: str) -> str:
    """Run the CLI in-process: exit 2 and one line ``mrstereo: error:`` holding ``must``."""
    code = entry([str(a) for a in args])
    err, _ = _lines(capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("mrstereo: error: "), err
    assert must in err[0], err[0]
    return err[0]


def _with_stamps(ds: Path, folder: Path, stamps_s) -> Path:
    """A copy of the dataset whose frames carry ``stamps_s``."""
    shutil.copytree(ds, folder)
    stamps = iter(stamps_s)
    text = re.sub(r"(  pose: .*\n)", lambda m: m.group(1) + f"  stamp_s: {next(stamps)!r}\n",
                  (folder / "manifest.yaml").read_text())
    (folder / "manifest.yaml").write_text(text)
    return folder


# ------------------------------------------------------------------------------------------ stamps

@pytest.mark.parametrize("stamps", [[5.0, 5.0, 5.0], [5.0, 4.9, 4.8]], ids=["equal", "going back"])
def test_stamps_that_do_not_increase_are_refused_by_every_command(ds, tmp_path, capsys, stamps):
    """Equal stamps were a ZeroDivisionError in ``info``, stamps going back a negative rate."""
    data = _with_stamps(ds, tmp_path / "D", stamps)
    for args in (["info", data], ["map", data, "-o", tmp_path / "m", "--quiet"],
                 ["odometry", data, "-o", tmp_path / "t.txt", "--quiet"]):
        _error(capsys, args, "frame 1 has the stamp")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["D"]
    good = _with_stamps(ds, tmp_path / "G", [5.0, 5.1, 5.2])
    assert entry(["info", str(good)]) == 0
    assert "rate:             10 Hz over 0.2 s" in capsys.readouterr().out


@pytest.mark.sample_data("euroc-asl-sample")
def test_euroc_stamps_beyond_int64_or_repeated_are_one_line(sample_data, tmp_path, capsys):
    for name, stamp, must in (("big", "99999999999999999999", "beyond the 2^63 ns"),
                              ("same", None, "the stamps must increase")):
        euroc = tmp_path / name
        shutil.copytree(sample_data("euroc-asl-sample"), euroc)
        for cam in ("cam0", "cam1"):
            csv = euroc / "mav0" / cam / "data.csv"
            rows = csv.read_text().splitlines()
            first = rows[1].split(",")[0]
            second = rows[2].split(",")[0]
            csv.write_text(csv.read_text().replace(f"{first},", f"{stamp}," if stamp else f"{second},", 1))
        _error(capsys, ["info", euroc], must)
