"""Fault suite: bad inputs, kills, full disks.

Every case checks the four promises of the command line:
- no data loss: no input is changed, whatever the outputs are called;
- no traceback: every failure is one line ``mrstereo: error: ...`` (exit 2) or
  ``mrstereo: interrupted`` (exit 130);
- no silently accepted bad input: a bad value ends in an error, not exit 0;
- no partial output without a marker: a failed or killed run leaves the previous outputs
  or nothing (temporary names start with ``.`` and end in ``.tmp``).
"""
from __future__ import annotations

import errno
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from mrstereo import io
from mrstereo.cli import entry

SRC = Path(__file__).resolve().parents[1] / "src"


# ------------------------------------------------------------------------------------------ fixtures

@pytest.fixture(scope="module")
def ds(synthetic_dataset) -> Path:
    """A 3-frame synthetic dataset (160x120), shared with other modules: tests copy it before changing it."""
    return synthetic_dataset(seed=1, n_frames=3, width=160, height=120, supersample=1)


@pytest.fixture(scope="module")
def long_inputs(synthetic_dataset, tmp_path_factory) -> dict[str, Path]:
    """Inputs that keep the interrupted commands busy for several seconds on a fast machine (the
    signal must land during the work, not after it): a 40-frame dataset and a 2560x1920 pair."""
    ds = synthetic_dataset(n_frames=40, width=160, height=120, supersample=1)
    root = tmp_path_factory.mktemp("long")
    for side in ("left", "right"):
        image = cv2.imread(str(ds / f"{side}_rect" / "000000.png"), cv2.IMREAD_GRAYSCALE)
        cv2.imwrite(str(root / f"{side}_big.png"), cv2.resize(image, (2560, 1920)))
    return {"DS": ds, "L": root}


@pytest.fixture
def ds_copy(ds, tmp_path) -> Path:
    """A private copy whose ground-truth map is called map.yaml / map.pgm (the names ``map`` writes)."""
    out = tmp_path / "DM"
    shutil.copytree(ds, out)
    (out / "gt_map.yaml").rename(out / "map.yaml")
    (out / "gt_map.pgm").rename(out / "map.pgm")
    text = (out / "map.yaml").read_text().replace("gt_map.pgm", "map.pgm")
    (out / "map.yaml").write_text(text)
    manifest = (out / "manifest.yaml").read_text().replace("ground_truth_map: gt_map.yaml", "ground_truth_map: map.yaml")
    (out / "manifest.yaml").write_text(manifest)
    return out


def _digest(folder: Path) -> dict[str, str]:
    """sha256 of every file under ``folder`` (by relative path)."""
    return {str(p.relative_to(folder)): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


def _run(capsys, args, *, expect: int = 2, must: str | None = None) -> str:
    """Run the CLI in-process; check the exit code and that stderr is one line; return it."""
    code = entry([str(a) for a in args])
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip()]
    one_line = len(lines) == 1 and lines[0].startswith("mrstereo: error:") and "Traceback" not in err
    assert code == expect, err
    assert one_line, err
    if must is not None:
        assert must in lines[0], lines[0]
    return lines[0]


def _no_temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob(".*") if ".tmp" in p.name]


# ------------------------------------------------------------------------------------------ data loss

def test_map_never_replaces_the_datasets_own_map(ds_copy, capsys):
    before = _digest(ds_copy)
    _run(capsys, ["map", ds_copy, "-o", ds_copy, "--quiet"], must="would overwrite the input")
    assert _digest(ds_copy) == before


def test_map_sees_through_hard_links_and_symlinks(ds_copy, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    os.link(ds_copy / "map.yaml", out / "map.yaml")                # the same file under another name
    (out / "map.pgm").symlink_to(ds_copy / "map.pgm")
    before = _digest(ds_copy)
    _run(capsys, ["map", ds_copy, "-o", out, "--quiet"], must="would overwrite the input")
    assert _digest(ds_copy) == before


@pytest.mark.parametrize("where", ["parent", "itself", "inside"])
def test_batch_refuses_an_output_folder_that_is_or_is_inside_the_dataset(ds, tmp_path, capsys, where):
    data = tmp_path / "data"
    dataset = data / "DS"
    shutil.copytree(ds, dataset)
    (dataset / "map").mkdir()
    (dataset / "map" / "notes.txt").write_text("a user's file")
    before = _digest(dataset)
    out = {"parent": data, "itself": dataset, "inside": dataset / "out"}[where]
    _run(capsys, ["batch", dataset, "-o", out, "--quiet"], must="choose a folder apart from it")
    assert _digest(dataset) == before
    assert not (dataset / "frames").exists() and not (dataset / "out").exists()


def test_two_outputs_of_one_run_must_differ(ds, tmp_path, capsys):
    left, right = ds / "left_rect" / "000000.png", ds / "right_rect" / "000000.png"
    d = tmp_path / "d.png"
    _run(capsys, ["disparity", left, right, "--max-disparity", "16", "-o", d, "--plot", d],
         must="are the same file")
    assert not d.exists()


@pytest.mark.parametrize("target", ["input", "symlink"])
def test_an_output_never_replaces_an_input(ds, tmp_path, capsys, target):
    left, right = tmp_path / "L.png", tmp_path / "R.png"
    shutil.copy(ds / "left_rect" / "000000.png", left)
    shutil.copy(ds / "right_rect" / "000000.png", right)
    before = _digest(tmp_path)
    output = left
    if target == "symlink":
        output = tmp_path / "link.png"
        output.symlink_to(right)
    _run(capsys, ["disparity", left, right, "--max-disparity", "16", "-o", output], must="would overwrite the input")
    assert {k: v for k, v in _digest(tmp_path).items() if k != "link.png"} == before


# ------------------------------------------------------------------------------------------ bad inputs: one line

def _fill(arg: str, values: dict[str, str]) -> str:
    """``arg`` with each placeholder of ``values`` (``{T}``, ``{DS}``, ...) replaced."""
    for key, value in values.items():
        arg = arg.replace(key, value)
    return arg


def _pair(ds):
    return ds / "left_rect" / "000000.png", ds / "right_rect" / "000000.png"


BAD_ARGS = {
    "max-disparity 1e9": (["disparity", "{L}", "{R}", "--max-disparity", "1e9", "-o", "{T}/x.pfm"], "would need"),
    "bands 0:1e9": (["disparity", "{L}", "{R}", "--bands", "0:1e9", "-o", "{T}/x.pfm"], "would need"),
    "depth-bands 1e-30,1": (["disparity", "{L}", "{R}", "--calib", "{DS}/calibration.yaml", "--rectified",
                             "--depth-bands", "1e-30,1", "-o", "{T}/x.pfm"], "would need"),
    "plot suffix": (["disparity", "{L}", "{R}", "--max-disparity", "16", "-o", "{T}/d.pfm", "--plot", "{T}/c.txt"],
                    "--plot must end in .png"),
    "output suffix": (["disparity", "{L}", "{R}", "--max-disparity", "16", "-o", "{T}/d.txt"], "--out must end"),
    "output folder is a file": (["disparity", "{L}", "{R}", "--max-disparity", "16", "-o", "{L}/d.pfm"],
                                "is a file, not a folder"),
    "max-disparity abc": (["disparity", "{L}", "{R}", "--max-disparity", "abc", "-o", "{T}/x.pfm"], "--max-disparity"),
    "missing option": (["disparity", "{L}", "{R}"], "Missing option"),
    "unknown option": (["disparity", "{L}", "{R}", "-o", "{T}/x.pfm", "--frobnicate"], "No such option"),
    "unknown command": (["frobnicate"], "No such command"),
    "points max-disparity 1e9": (["points", "{L}", "{R}", "--calib", "{DS}/calibration.yaml", "--rectified",
                                  "--max-disparity", "1e9", "-o", "{T}/p.ply"], "would need"),
    "scan angle-increment 1e-9": (["scan", "{L}", "{R}", "--calib", "{DS}/calibration.yaml", "--rectified",
                                   "--angle-increment", "1e-9", "-o", "{T}/s.json"], "would need"),
    "scan plot suffix": (["scan", "{L}", "{R}", "--calib", "{DS}/calibration.yaml", "--rectified",
                          "--plot", "{T}/s.txt", "-o", "{T}/s.json"], "--plot must end in"),
    "synth 1e8 x 1e8": (["synth", "--out", "{T}/S", "--width", "100000000", "--height", "100000000"], "would need"),
    "map resolution 0.0001": (["map", "{DS}", "-o", "{T}/m", "--resolution", "0.0001", "--quiet"], "would need"),
    "plan bad start": (["plan", "{DS}/gt_map.yaml", "--start", "a", "--goal", "1,1", "-o", "{T}/p.json"], "--start"),
    "plan missing goal": (["plan", "{DS}/gt_map.yaml", "--start", "1,1", "-o", "{T}/p.json"], "Missing option"),
    "plan overwrites its map": (["plan", "{DS}/gt_map.yaml", "--start", "1,0", "--goal", "2,0", "-o", "{T}/p.json",
                                 "--plot", "{DS}/gt_map.pgm"], "--plot must end in"),
    "rectify into the input": (["rectify", "--calib", "{DS}/calibration.yaml", "{DS}/left/000000.png",
                                "{DS}/left_rect/000001.png", "-o", "{DS}/left"], "would overwrite the input"),
    "evaluate json is the markdown": (["evaluate", "{T}", "--json", "{T}/r.txt", "--markdown", "{T}/r.txt"],
                                      "same file"),
    "export into the bag": (["export", "--bag", "{T}/x.bag", "--left-topic", "/l", "--right-topic", "/r", "-o",
                             "{T}"], "not empty"),
    "batch workers 0": (["batch", "{DS}", "-o", "{T}/b", "--workers", "0"], "--workers"),
    "calibrate overwrites its points": (["calibrate", "--points", "{T}/pts.yaml", "--image-size", "64x48", "-o",
                                         "{T}/pts.yaml"], "would overwrite the input"),
}


@pytest.mark.parametrize("case", sorted(BAD_ARGS))
def test_bad_inputs_are_one_line_errors(ds, tmp_path, capsys, case):
    args, must = BAD_ARGS[case]
    left, right = _pair(ds)
    (tmp_path / "x.bag").write_bytes(b"#ROSBAG V2.0\n")
    (tmp_path / "pts.yaml").write_text("0,0,0,1,1\n")
    before = _digest(ds)
    values = {"{L}": str(left), "{R}": str(right), "{T}": str(tmp_path), "{DS}": str(ds)}
    _run(capsys, [_fill(a, values) for a in args], must=must)
    assert _digest(ds) == before
    written = {p.name for p in tmp_path.iterdir()} - {"x.bag", "pts.yaml"}
    assert not written, f"outputs written by a refused run: {written}"


def test_no_args_shows_the_help(capsys):
    assert entry([]) == 0
    assert "Usage: mrstereo" in capsys.readouterr().out


def test_unexpected_errors_are_one_line_with_a_hint(monkeypatch, capsys):
    import mrstereo.matching

    def broken(*args, **kwargs):
        raise ZeroDivisionError("a bug")

    monkeypatch.setattr(mrstereo.matching, "preset_config", broken)
    monkeypatch.delenv("MRSTEREO_DEBUG", raising=False)
    args = ["disparity", "a.png", "b.png", "--max-disparity", "16", "-o", "x.pfm"]
    with tempfile.TemporaryDirectory() as tmp:
        from mrstereo.io import write_image
        for name in ("a.png", "b.png"):
            write_image(Path(tmp) / name, np.full((32, 48), 100, np.uint8))
        cwd = os.getcwd()
        os.chdir(tmp)
        try:
            assert entry(args) == 1
            err = capsys.readouterr().err
            assert err.count("\n") == 1 and "internal error ZeroDivisionError: a bug" in err and "report" in err
            monkeypatch.setenv("MRSTEREO_DEBUG", "1")
            with pytest.raises(ZeroDivisionError):
                entry(args)
        finally:
            os.chdir(cwd)


def test_python_m_and_the_console_script_agree(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(SRC))
    args = ["disparity", "a.png", "b.png", "--max-disparity", "abc", "-o", str(tmp_path / "x.pfm")]
    a = subprocess.run([sys.executable, "-m", "mrstereo", *args], capture_output=True, text=True, env=env)
    script = ("import sys; from mrstereo.cli import entry; sys.argv[0] = 'mrstereo'; sys.exit(entry())")
    b = subprocess.run([sys.executable, "-c", script, *args], capture_output=True, text=True, env=env)
    assert a.returncode == b.returncode == 2
    assert a.stderr == b.stderr and a.stderr.count("\n") == 1 and a.stderr.startswith("mrstereo: error: Invalid")


# ------------------------------------------------------------------------------------------ library entry points

def test_library_refuses_searches_that_do_not_fit_in_memory():
    from mrstereo.matching import compute_disparity

    img = np.zeros((48, 64), np.uint8)
    with pytest.raises(ValueError, match=r"max_disparity_px: .* would need .* of memory"):
        compute_disparity(img, img, max_disparity_px=1e9)
    with pytest.raises(ValueError, match=r"disparity_bands_px: .* would need"):
        compute_disparity(img, img, disparity_bands_px=[(0, 1e9)])
    assert compute_disparity(img, img, max_disparity_px=16).disparity_px.shape == (48, 64)


def test_library_size_checks_of_grids_scans_and_renders(tmp_path):
    from mrstereo.geometry.scan import laser_scan_from_points
    from mrstereo.mapping import GridSpec
    from mrstereo.world.dataset import write_synthetic_dataset

    with pytest.raises(ValueError, match="resolution_m: a grid of .* would need"):
        GridSpec(resolution_m=0.0001)
    with pytest.raises(ValueError, match="angle_increment_rad: a scan of .* would need"):
        laser_scan_from_points(np.zeros((1, 3)), angle_increment_rad=1e-13)
    with pytest.raises(ValueError, match="width and height: rendering .* would need"):
        write_synthetic_dataset(tmp_path / "S", width=100_000_000, height=100_000_000, progress=False)
    assert not (tmp_path / "S").exists()


@pytest.mark.parametrize("dtype", [np.int64, np.int32, np.bool_])
def test_rectify_names_an_unsupported_dtype(ds, dtype):
    from mrstereo.camera import read_stereo

    stereo = read_stereo(ds / "calibration.yaml")
    w, h = stereo.size
    good = np.zeros((h, w), np.uint8)
    with pytest.raises(TypeError, match="left must .*got( dtype)? " + np.dtype(dtype).name):
        stereo.rectify(np.zeros((h, w), dtype), good)
    for ok in (np.uint8, np.uint16, np.float32):
        assert stereo.rectify(np.zeros((h, w), ok), np.zeros((h, w), ok))[0].dtype == ok


# ------------------------------------------------------------------------------------------ unclear messages

def test_non_utf8_files_are_named(ds, tmp_path, capsys):
    png = (ds / "left" / "000000.png").read_bytes()
    (tmp_path / "pts.csv").write_bytes(png)
    line = _run(capsys, ["calibrate", "--points", tmp_path / "pts.csv", "--image-size", "64x48", "-o",
                         tmp_path / "c.yaml"])
    assert "pts.csv" in line and "not UTF-8" in line
    (tmp_path / "fake.bag").write_bytes(png)
    line = _run(capsys, ["export", "--bag", tmp_path / "fake.bag", "--left-topic", "/l", "--right-topic", "/r",
                         "-o", tmp_path / "ex"])
    assert "fake.bag" in line
    bad = tmp_path / "bad_ds"
    bad.mkdir()
    (bad / "manifest.yaml").write_bytes(png)
    line = _run(capsys, ["map", bad, "-o", tmp_path / "m", "--quiet"])
    assert "manifest.yaml" in line and "not UTF-8" in line


def _full_disk_tmp(monkeypatch):
    """Simulated full disk: every temporary file of atomic_write is /dev/full (writes fail with ENOSPC)."""
    real = tempfile.mkstemp

    def mkstemp(*args, **kwargs):
        fd, path = real(*args, **kwargs)
        os.close(fd)
        os.unlink(path)
        os.symlink("/dev/full", path)
        return os.open(path, os.O_WRONLY), path

    monkeypatch.setattr(io.files.tempfile, "mkstemp", mkstemp)


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
def test_a_full_disk_is_named(ds, tmp_path, capsys, monkeypatch):
    left, right = _pair(ds)
    _full_disk_tmp(monkeypatch)
    for args, out in ((["disparity", left, right, "--max-disparity", "16", "-o", tmp_path / "d.pfm"], "d.pfm"),
                      (["disparity", left, right, "--max-disparity", "16", "-o", tmp_path / "d.png"], "d.png"),
                      (["map", ds, "-o", tmp_path / "m", "--quiet"], "/m/map.")):
        line = _run(capsys, args, must="no space left on device")
        assert out in line
    assert not (tmp_path / "d.pfm").exists() and not (tmp_path / "d.png").exists()
    assert not (tmp_path / "m").exists() or not any((tmp_path / "m").iterdir())


def _tiny_tmpfs(path: Path, size: str) -> bool:
    if os.geteuid() != 0 or not shutil.which("mount"):
        return False
    path.mkdir(parents=True, exist_ok=True)
    return subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(path)],
                          capture_output=True).returncode == 0


@pytest.mark.parametrize("command", ["synth", "map", "batch"])
def test_a_really_full_disk(ds, tmp_path, capsys, command):
    disk = tmp_path / "disk"
    if not _tiny_tmpfs(disk, "96k"):
        pytest.skip("cannot mount a tiny tmpfs here (needs root); the simulated full disk test covers it")
    try:
        args = {"synth": ["synth", "--out", disk / "S", "--frames", "1", "--width", "160", "--height", "120",
                          "--quiet"],
                "map": ["map", ds, "-o", disk / "m", "--quiet"],
                "batch": ["batch", ds, "-o", disk / "b", "--quiet"]}[command]
        _run(capsys, args, must="no space left on device")
        assert not _no_temporaries(disk)
        if command == "map":
            assert not (disk / "m").exists() or not any((disk / "m").iterdir())
        if command == "batch":
            maps = list(disk.rglob("map.yaml"))
            assert all((p.parent / "batch.json").exists() for p in maps)
    finally:
        subprocess.run(["umount", "-l", str(disk)], capture_output=True)


# ------------------------------------------------------------------------------------------ partial outputs

def test_map_writes_all_files_or_none(ds, tmp_path, capsys, monkeypatch):
    import mrstereo.pipeline.run

    out = tmp_path / "m"
    out.mkdir()
    (out / "map.yaml").write_text("an older map\n")

    def fail(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", "map.png")

    monkeypatch.setattr(mrstereo.pipeline.run, "plot_map", fail)
    _run(capsys, ["map", ds, "-o", out, "--quiet"], must="no space left on device")
    assert sorted(p.name for p in out.iterdir()) == ["map.yaml"]           # the old set, nothing new, no temp
    assert (out / "map.yaml").read_text() == "an older map\n"


def _dead_pid() -> int:
    p = subprocess.Popen([sys.executable, "-c", "pass"])
    p.wait()
    return p.pid


def test_batch_resume_cleans_a_killed_runs_temporaries_and_redoes_corrupt_frames(ds, tmp_path, capsys):
    out = tmp_path / "out"
    assert entry(["batch", str(ds), "-o", str(out), "--quiet"]) == 0
    capsys.readouterr()
    frames = out / ds.name / "frames"
    good = io.read_pfm(frames / "000001.pfm")
    # what SIGKILL leaves: a map folder being written, an atomic_write temporary
    pid = _dead_pid()
    stale_map = out / ds.name / f".map.{pid}.abcd1234.tmp"
    (stale_map / "map").mkdir(parents=True)
    (stale_map / "map" / "map.pgm").write_bytes(b"P5 half")
    stale_file = frames / f".000002.{pid}.xyz.tmp.pfm"
    stale_file.write_bytes(b"Pf\n")
    # and a damaged output
    data = (frames / "000001.pfm").read_bytes()
    (frames / "000001.pfm").write_bytes(data[: len(data) // 2])
    assert entry(["batch", str(ds), "-o", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["datasets"][0]["computed"] == 1 and summary["datasets"][0]["skipped"] == 2
    np.testing.assert_array_equal(io.read_pfm(frames / "000001.pfm"), good)
    assert not stale_map.exists() and not stale_file.exists()
    assert not _no_temporaries(out)


def test_temporaries_of_live_processes_are_kept(tmp_path):
    mine = tmp_path / f".map.{os.getpid()}.abc.tmp"
    mine.mkdir()
    assert io.remove_stale_temporaries(tmp_path) == [] and mine.exists()


# ------------------------------------------------------------------------------------------ kills

def _children(pid: int) -> list[int]:
    import psutil

    try:
        return [c.pid for c in psutil.Process(pid).children(recursive=True)]
    except psutil.NoSuchProcess:
        return []


@pytest.mark.slow
@pytest.mark.parametrize("delay_s", [0.7, 2.5, 4.0])
def test_ctrl_c_is_one_line_and_exit_130_within_seconds(long_inputs, tmp_path, delay_s):
    """SIGINT to the process group, as a terminal's Ctrl-C, during start-up, cluster start and work."""
    import psutil

    out = tmp_path / "m"
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    proc = subprocess.Popen([sys.executable, "-m", "mrstereo", "map", str(long_inputs["DS"]), "-o", str(out),
                             "--workers", "2", "--processes", "--quiet"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, start_new_session=True)
    time.sleep(delay_s)
    children = _children(proc.pid)
    if proc.poll() is not None:
        pytest.skip("the run ended before the signal")
    os.killpg(proc.pid, signal.SIGINT)
    sent = time.monotonic()
    _, err = proc.communicate(timeout=30)
    took = time.monotonic() - sent
    assert proc.returncode == 130, err.decode()
    assert err.decode() == "mrstereo: interrupted\n"
    assert took < 5.0
    deadline = time.monotonic() + 5
    while any(psutil.pid_exists(c) and psutil.Process(c).status() != psutil.STATUS_ZOMBIE for c in children) \
            and time.monotonic() < deadline:
        time.sleep(0.2)
    assert not [c for c in children if psutil.pid_exists(c) and psutil.Process(c).status() != psutil.STATUS_ZOMBIE]
    if out.exists():                                    # all or nothing
        names = {p.name for p in out.iterdir() if not p.name.startswith(".")}
        assert names in (set(), {"map.yaml", "map.pgm", "map.png", "log_odds.npy", "metrics.json"})


def test_ctrl_c_after_the_command_finished_is_still_one_line_and_130():
    """A signal after the command's work, before the process has ended: one line, exit 130, no
    traceback (the handler entry() leaves in place for mrstereo's own process)."""
    script = ("import os, signal, sys, time; from mrstereo.cli import _Interrupts; i = _Interrupts(); "
              "i.install(); i.linger(); os.kill(os.getpid(), signal.SIGINT); time.sleep(10); sys.exit(0)")
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, env=env, timeout=60)
    assert proc.returncode == 130, proc.stderr.decode()
    assert proc.stderr.decode() == "mrstereo: interrupted\n"


def test_console_run_ends_with_its_exit_code_and_output():
    """``python -m mrstereo`` ends right after the command (no interpreter teardown) with all its output."""
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    ok = subprocess.run([sys.executable, "-m", "mrstereo", "data", "list"], capture_output=True, env=env, timeout=60)
    assert ok.returncode == 0 and b"openloris-sample" in ok.stdout and ok.stderr == b""
    bad = subprocess.run([sys.executable, "-m", "mrstereo", "data", "path", "nope"], capture_output=True, env=env,
                         timeout=60)
    assert bad.returncode == 2 and bad.stderr.decode().startswith("mrstereo: error: ")


LONG_COMMANDS = {
    "synth": ["synth", "--out", "{T}/S", "--frames", "40", "--width", "320", "--height", "240", "--quiet"],
    "map (threads)": ["map", "{DS}", "-o", "{T}/m", "--workers", "2", "--quiet"],
    "batch (processes)": ["batch", "{DS}", "-o", "{T}/b", "--workers", "2", "--processes", "--quiet"],
    "disparity": ["disparity", "{L}/left_big.png", "{L}/right_big.png", "--max-disparity", "512",
                  "--single-range", "-o", "{T}/d.pfm"],
}


@pytest.mark.slow
@pytest.mark.parametrize("signum", [signal.SIGINT, signal.SIGTERM])
@pytest.mark.parametrize("command", sorted(LONG_COMMANDS))
def test_every_long_command_stops_with_one_line(long_inputs, tmp_path, command, signum):
    values = {"{T}": str(tmp_path), "{DS}": str(long_inputs["DS"]), "{L}": str(long_inputs["L"])}
    args = [_fill(a, values) for a in LONG_COMMANDS[command]]
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    proc = subprocess.Popen([sys.executable, "-m", "mrstereo", *args], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, env=env, start_new_session=True)
    time.sleep(2.0)
    if proc.poll() is not None:
        pytest.skip("the run ended before the signal")
    os.killpg(proc.pid, signum)
    sent = time.monotonic()
    _, err = proc.communicate(timeout=30)
    assert (proc.returncode, err.decode()) == (130, "mrstereo: interrupted\n")
    assert time.monotonic() - sent < 5.0
    visible = [p.name for p in tmp_path.rglob("*") if p.is_file() and not any(
        part.startswith(".") for part in p.relative_to(tmp_path).parts)]
    partial = [v for v in visible if v not in ("d.pfm",)] if command != "batch (processes)" else []
    assert not partial, partial


def test_sigkill_during_synth_leaves_only_a_marked_temporary(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    proc = subprocess.Popen([sys.executable, "-m", "mrstereo", "synth", "--out", str(tmp_path / "S"), "--frames", "3",
                             "--width", "160", "--height", "120", "--quiet"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".S.*.tmp/left/*.png")) and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    assert not (tmp_path / "S").exists()
    assert all(p.name.startswith(".") and p.name.endswith(".tmp") for p in tmp_path.iterdir())


def test_sigkill_during_batch_then_resume_gives_the_same_files(ds, tmp_path):
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    ref, out = tmp_path / "ref", tmp_path / "out"
    assert entry(["batch", str(ds), "-o", str(ref), "--quiet"]) == 0
    proc = subprocess.Popen([sys.executable, "-m", "mrstereo", "batch", str(ds), "-o", str(out), "--quiet"],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=env)
    deadline = time.monotonic() + 60
    while not list(out.glob(f"{ds.name}/frames/*.obs.npz")) and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    assert entry(["batch", str(ds), "-o", str(out), "--quiet"]) == 0
    assert not _no_temporaries(out)
    for name in ("000000.pfm", "000001.pfm", "000002.pfm"):
        np.testing.assert_array_equal(io.read_pfm(out / ds.name / "frames" / name),
                                      io.read_pfm(ref / ds.name / "frames" / name))
    assert (out / ds.name / "map" / "map.pgm").read_bytes() == (ref / ds.name / "map" / "map.pgm").read_bytes()
