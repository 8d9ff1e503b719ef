"""The stereo mapper that map, batch and live drive: one pair at a time into a growing map; live is map with
pacing (the same map.pgm byte for byte); the public API and its reference page."""
from __future__ import annotations

import doctest
import json
import re
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import mrstereo
from mrstereo.cli import entry
from mrstereo.pipeline.live import LiveConfig, run_live
from mrstereo.pipeline.mapper import PipelineConfig, StereoMapper
from mrstereo.pipeline.run import build_map
from mrstereo.recordings import read_recording
from mrstereo.recordings.samples import data_root
from mrstereo.recordings.sources import RecordingSource

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def small(synthetic_dataset):
    return synthetic_dataset(seed=5, n_frames=6, width=160, height=120, supersample=1)


def test_live_without_realtime_writes_the_map_of_map_byte_for_byte(small, tmp_path, capsys):
    assert entry(["map", str(small), "-o", str(tmp_path / "map"), "--quiet"]) == 0
    assert entry(["live", str(small), "-o", str(tmp_path / "live"), "--quiet"]) == 0
    a, b = (tmp_path / "map" / "map.pgm").read_bytes(), (tmp_path / "live" / "map.pgm").read_bytes()
    assert a == b and len(set(a[20:])) == 3                       # the same map: free, occupied and unknown
    assert (tmp_path / "map" / "map.yaml").read_text() == (tmp_path / "live" / "map.yaml").read_text()


def test_live_and_map_agree_on_the_real_euroc_sample_without_a_mount(tmp_path):
    root = data_root() / "euroc_asl_sample"
    if not (root / "mav0" / "cam0" / "sensor.yaml").is_file():
        pytest.skip(f"EuRoC sample not found under {root} (set MRSTEREO_DATA)")
    assert entry(["map", str(root), "-o", str(tmp_path / "map"), "--quiet"]) == 0
    assert entry(["live", str(root), "-o", str(tmp_path / "live"), "--quiet"]) == 0
    assert (tmp_path / "map" / "map.pgm").read_bytes() == (tmp_path / "live" / "map.pgm").read_bytes()
    live = json.loads((tmp_path / "live" / "metrics.json").read_text())
    assert live["frames_mapped"] == 5 and "median of 3 floor fit" in live["floor"]["message"]


def test_the_mapper_holds_the_first_frames_until_the_floor_is_known_then_maps_them_in_order(small):
    manifest = read_recording(small)
    stereo = manifest.calibration
    mapper = StereoMapper(stereo, None, PipelineConfig(grid=None), name="test")
    returned = []
    with RecordingSource(manifest) as source:
        for frame in source:
            done = mapper.step_frame(frame)
            returned.append([m.index for m in done])
    returned.append([m.index for m in mapper.finish()])
    # no mount: nothing until three confident floor fits, then the held frames and the new one, in order
    assert returned[0] == [] and [k for r in returned for k in r] == list(range(6))
    assert mapper.floor.method != "mount" and "median of" in mapper.floor.message
    run = build_map(replace(manifest, mount=None, ground_truth_map=None), progress=False)
    np.testing.assert_array_equal(mapper.occupancy().log_odds, run.grid.log_odds)


def test_a_live_map_grows_with_the_path_beyond_the_old_40_m_window(small, tmp_path):
    manifest = read_recording(small)
    far = tuple(replace(f, pose=(f.pose[0] + 60.0, f.pose[1] - 45.0, f.pose[2]), true_pose=None)
                for f in manifest.frames)
    moved = replace(manifest, frames=far, ground_truth_map=None)
    with RecordingSource(moved) as source:
        run = run_live(source, tmp_path / "out", live=LiveConfig(save_every_s=60.0))
    window = json.loads((tmp_path / "out" / "metrics.json").read_text())["map_window"]
    x0, y0 = window["origin_m"]
    assert x0 > 50.0 and y0 < -40.0 and window["points_outside"] == 0 and run.frames_mapped == 6


def test_live_checks_a_given_mount_against_the_floor_as_map_does(small, tmp_path):
    from mrstereo.camera import CameraMount

    manifest = read_recording(small)
    true = manifest.mount.T_base_from_cam
    wrong_T = true.copy()
    wrong_T[2, 3] += 0.6                                         # the camera said to be 0.6 m higher than it is
    wrong = CameraMount(wrong_T)
    with RecordingSource(replace(manifest, ground_truth_map=None)) as source:
        run = run_live(source, tmp_path / "out", mount=wrong)
    metrics = json.loads((tmp_path / "out" / "metrics.json").read_text())
    assert run.mount_warning and "height is off" in metrics["mount_warning"]
    assert abs(run.floor.height_m - true[2, 3]) < 0.05           # the floor seen is used, not the wrong mount


@pytest.mark.parametrize("command", ["map", "live"])
def test_an_upside_down_mount_is_replaced_by_the_floor_seen(small, tmp_path, capsys, command):
    """The right height and tilt, but the camera given upside down (roll pi): map and live both refuse it."""
    true = read_recording(small).mount
    x, y, z = true.T_base_from_cam[:3, 3]
    out = tmp_path / command
    assert entry([command, str(small), "-o", str(out), "--quiet", "--mount",
                  f"{x},{y},{z},3.14159,0.15,0"]) == 0
    metrics = json.loads((out / "metrics.json").read_text())
    assert re.search(r"roll is off by 1[78]\d deg", metrics["mount_warning"])
    assert "roll is off" in capsys.readouterr().err


def test_import_mrstereo_is_cheap_and_lists_its_public_objects():
    code = "import sys, mrstereo; print('numba' in sys.modules, 'cv2' in sys.modules); print(' '.join(dir(mrstereo)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.split("\n")
    assert out[0] == "False False"
    names = set(out[1].split())
    assert {"StereoMapper", "PipelineConfig", "StereoCamera", "read_stereo", "compute_disparity", "build_map",
            "obstacles_from_pair", "open_source", "open_recording", "run_live", "LiveConfig"} <= names
    for name in mrstereo.__all__:
        assert getattr(mrstereo, name) is not None


DOCTEST_MODULES = ["mrstereo.pipeline.mapper", "mrstereo.geometry.pair"]


@pytest.mark.parametrize("module", DOCTEST_MODULES)
def test_the_examples_of_the_headline_objects_run(module):
    import importlib

    result = doctest.testmod(importlib.import_module(module), optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0 and result.failed == 0


def test_the_api_reference_is_generated_from_the_docstrings_and_up_to_date():
    from mrstereo._apidoc import api_markdown

    text = api_markdown()
    assert "### `mrstereo.StereoMapper(" in text and ">>> mapper.step(" in text.replace("[frame] = ", "")
    assert (ROOT / "docs" / "api.md").read_text(encoding="utf-8") == text, \
        "docs/api.md is out of date: python -m mrstereo._apidoc > docs/api.md"


def test_live_names_a_duplicated_camera_stream_as_map_does(small, tmp_path, capsys):
    import shutil

    data = tmp_path / "DS"
    shutil.copytree(small, data)
    for side in ("", "_rect"):                                   # one camera recorded as left and right
        shutil.rmtree(data / f"right{side}")
        shutil.copytree(data / f"left{side}", data / f"right{side}")
    for command in ("map", "live"):
        entry([command, str(data), "-o", str(tmp_path / command), "--quiet"])
        warned = [line for line in capsys.readouterr().err.splitlines() if line.startswith("mrstereo: warning:")]
        assert any("identical left and right images" in line for line in warned), (command, warned)
