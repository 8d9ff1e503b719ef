"""Fault suite: bad inputs, kills, full disks.

Every case checks the four promises of the command line:
- no data loss: no input is changed, whatever the outputs are called;
- no traceback: every failure is one line ``mrstereo: error: ...`` (exit 2) or
  ``mrstereo: interrupted`` (exit 130);
- no silently accepted bad input: a bad value ends in an error, not exit 0;
- no partial output without a marker: a failed or killed run leaves the previous outputs
  or nothing (temporary names carry the marker ``.mrstereo-tmp-PID-XXXXXXXX.``).
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

import click
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
    return [p for p in folder.rglob(".*") if io.is_temporary(p)]


# ------------------------------------------------------------------------------------------ data loss

def test_map_never_replaces_the_datasets_own_map(ds_copy, capsys):
    before = _digest(ds_copy)
    _run(capsys, ["map", ds_copy, "-o", ds_copy, "--quiet"], must="is the dataset")
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
    "max-disparity 1e9": (["disparity", "{L}", "{R}", "--max-disparity", "1e9", "-o", "{T}/x.pfm"],
                          "'--max-disparity': 1e9 is not in the range [1, 4096] px"),
    "bands 0:1e9": (["disparity", "{L}", "{R}", "--bands", "0:1e9", "-o", "{T}/x.pfm"], "--bands need"),
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
                                  "--max-disparity", "1e9", "-o", "{T}/p.ply"], "--max-disparity"),
    "scan angle-increment 1e-9": (["scan", "{L}", "{R}", "--calib", "{DS}/calibration.yaml", "--rectified",
                                   "--angle-increment", "1e-9", "-o", "{T}/s.json"], "--angle-increment"),
    "scan plot suffix": (["scan", "{L}", "{R}", "--calib", "{DS}/calibration.yaml", "--rectified",
                          "--plot", "{T}/s.txt", "-o", "{T}/s.json"], "--plot must end in"),
    "synth 1e8 x 1e8": (["synth", "--out", "{T}/S", "--width", "100000000", "--height", "100000000"], "--width"),
    "synth 8192 x 8192 x 1e5 frames": (["synth", "--out", "{T}/S", "--width", "8192", "--height", "8192", "--frames",
                                        "100000"], "of disk"),
    "map resolution 0.0001": (["map", "{DS}", "-o", "{T}/m", "--resolution", "0.0001", "--quiet"], "--resolution"),
    "map size 1e5 x 1e5": (["map", "{DS}", "-o", "{T}/m", "--size", "100000,100000", "--origin", "0,0", "--quiet"],
                           "would need"),
    "plan bad start": (["plan", "{DS}/gt_map.yaml", "--start", "a", "--goal", "1,1", "-o", "{T}/p.json"], "--start"),
    "plan missing goal": (["plan", "{DS}/gt_map.yaml", "--start", "1,1", "-o", "{T}/p.json"], "Missing option"),
    "plan overwrites its map": (["plan", "{DS}/gt_map.yaml", "--start", "1,0", "--goal", "2,0", "-o", "{T}/p.json",
                                 "--plot", "{DS}/gt_map.pgm"], "--plot must end in"),
    "rectify into the input": (["rectify", "--calib", "{DS}/calibration.yaml", "{DS}/left/000000.png",
                                "{DS}/left_rect/000001.png", "-o", "{DS}/left"], "would overwrite the input"),
    "evaluate writes into its scene": (["evaluate", "{T}", "--json", "{T}/r.json"], "lies inside the scene"),
    "evaluate markdown suffix": (["evaluate", "{T}", "--markdown", "{DS}/../r.json"], "--markdown must end in"),
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


def test_a_pair_of_two_sizes_in_a_recording_is_named(ds, tmp_path, capsys):
    bad = tmp_path / "DS"
    shutil.copytree(ds, bad)
    right = bad / "right_rect" / "000001.png"
    cv2.imwrite(str(right), cv2.imread(str(right), cv2.IMREAD_UNCHANGED)[:100])
    _run(capsys, ["map", bad, "-o", tmp_path / "out", "--quiet"], must=f"{right} must have the same size")
    assert not (tmp_path / "out").exists()


def test_a_pair_of_two_sizes_given_to_the_mapper_names_the_frame():
    from mrstereo.recordings.sources import StereoFrame
    with pytest.raises(ValueError, match=r"frame 7 \(stamp 1.500 s\): left and right must have the same size, "
                                         r"got 160x120 and 160x100"):
        StereoFrame(index=7, stamp_s=1.5, left=np.zeros((120, 160), np.uint8), right=np.zeros((100, 160), np.uint8))


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
        for k, name in enumerate(("a.png", "b.png")):
            write_image(Path(tmp) / name, np.random.default_rng(k).integers(0, 255, (32, 48), dtype=np.uint8))
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

    with pytest.raises(ValueError, match="width_m, height_m and resolution_m: a grid of .* would need"):
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
    real = io.files._create_temporary

    def create(folder, name):
        path = real(folder, name)
        os.unlink(path)
        os.symlink("/dev/full", path)
        return path

    monkeypatch.setattr(io.files, "_create_temporary", create)


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
        _run(capsys, args, must="of disk" if command == "synth" else "no space left on device")
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
    import mrstereo.evaluation.outputs

    out = tmp_path / "m"
    out.mkdir()
    (out / "map.yaml").write_text("an older map\n")

    def fail(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device", "map.png")

    monkeypatch.setattr(mrstereo.evaluation.outputs, "plot_map", fail)
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
    stale_map = out / ds.name / f".mrstereo-tmp-{pid}-abcd1234.map"
    (stale_map / "map").mkdir(parents=True)
    (stale_map / "map" / "map.pgm").write_bytes(b"P5 half")
    stale_file = frames / f".mrstereo-tmp-{pid}-0123abcd.000002.pfm"
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

def _signalled(args: list, point: str, tmp_path: Path, signame: str = "SIGINT"):
    """``python -m mrstereo ARGS`` in a session of its own that signals its process group (as a terminal's
    Ctrl-C does) when the run reaches ``point`` (``MRSTEREO_SIGNAL_AT``, :mod:`mrstereo._interrupt`):
    ``(returncode, stderr, seconds from the signal to the end)``, once no process of the session is left."""
    import psutil

    sent_file, err_file = tmp_path / "signal-sent", tmp_path / "stderr"
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg",
               MRSTEREO_SIGNAL_AT=f"{point}:{signame}:{sent_file}")
    with open(err_file, "wb") as stderr:    # a file, not a pipe: the end of the run is its process's end
        proc = subprocess.Popen([sys.executable, "-m", "mrstereo", *map(str, args)], stdout=subprocess.DEVNULL,
                                stderr=stderr, env=env, start_new_session=True)
        proc.wait(timeout=300)
    ended = time.monotonic()
    err = err_file.read_bytes()
    assert sent_file.is_file(), f"the run never reached {point}: {err.decode()}"
    took = ended - float(sent_file.read_text())
    sent_file.unlink()
    err_file.unlink()

    def left() -> list:               # the session's other processes (Dask workers...)
        out = []
        for p in psutil.process_iter(["pid", "status", "cmdline"]):
            try:
                if os.getsid(p.pid) == proc.pid and p.info["status"] != psutil.STATUS_ZOMBIE:
                    out.append((p.pid, " ".join(p.info["cmdline"] or ())[:100]))
            except (ProcessLookupError, PermissionError):
                pass
        return out

    deadline = time.monotonic() + 5
    while left() and time.monotonic() < deadline:
        time.sleep(0.1)
    still = left()
    if still:
        os.killpg(proc.pid, signal.SIGKILL)
    assert not still, f"processes of the interrupted run still running 5 s after it: {still}"
    return proc.returncode, err, took


def _unwarned(err: bytes) -> str:
    """stderr without the ``mrstereo: warning:`` lines a run may print about its input before the signal."""
    return "".join(line for line in err.decode().splitlines(keepends=True)
                   if not line.startswith("mrstereo: warning: "))


@pytest.mark.extra("scale")
@pytest.mark.parametrize("point", ["start:1", "cluster:1", "frame:2"], ids=["start-up", "cluster start", "work"])
def test_ctrl_c_is_one_line_and_exit_130_within_seconds(ds, tmp_path, point):
    """SIGINT to the process group, as a terminal's Ctrl-C, during start-up, cluster start and work."""
    out = tmp_path / "m"
    code, err, took = _signalled(["map", ds, "-o", out, "--workers", "2", "--processes", "--quiet"], point, tmp_path)
    assert code == 130, err.decode()
    assert _unwarned(err) == "mrstereo: interrupted\n"
    assert took < 5.0
    if out.exists():                                    # all or nothing
        names = {p.name for p in out.iterdir() if not p.name.startswith(".")}
        assert names in (set(), {"map.yaml", "map.pgm", "map.png", "log_odds.npy", "metrics.json"})


@pytest.mark.parametrize("args", [["map", "{DS}", "-o", "{T}/m", "--workers", "2", "--processes", "--quiet"],
                                  ["batch", "{DS}", "-o", "{T}/b", "--scheduler", "tcp://127.0.0.1:8786", "--quiet"]],
                         ids=["processes", "scheduler"])
def test_without_dask_processes_and_schedulers_are_one_line_naming_the_extra(ds, tmp_path, capsys, monkeypatch, args):
    monkeypatch.setitem(sys.modules, "distributed", None)          # as if the scale extra were not installed
    values = {"{T}": str(tmp_path), "{DS}": str(ds)}
    _run(capsys, [_fill(a, values) for a in args], must='need Dask (dask, distributed): pip install "mrstereo[scale]"')
    assert not list(tmp_path.iterdir())                             # refused before any work


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


LONG_COMMANDS = {       # the point where the signal lands: after a frame, with frames still to do
    "synth": (["synth", "--out", "{T}/S", "--frames", "3", "--width", "160", "--height", "120", "--quiet"],
              "frame:2", None),
    "map (threads)": (["map", "{DS}", "-o", "{T}/m", "--workers", "2", "--quiet"], "frame:1", None),
    "odometry": (["odometry", "{DS}", "-o", "{T}/t.txt", "--quiet"], "frame:1", None),
    "batch (processes)": (["batch", "{DS}", "-o", "{T}/b", "--workers", "2", "--processes", "--quiet"], "frame:1",
                          "scale"),
    "disparity": (["disparity", "{DS}/left_rect/000000.png", "{DS}/right_rect/000000.png", "--max-disparity", "16",
                   "--single-range", "-o", "{T}/d.pfm"], "frame:1", None),
}


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("command", [pytest.param(name, marks=[pytest.mark.extra(extra)] if extra else [])
                                     for name, (_, _, extra) in sorted(LONG_COMMANDS.items())])
def test_every_long_command_stops_with_one_line(ds, tmp_path, command, signame):
    values = {"{T}": str(tmp_path), "{DS}": str(ds)}
    args, point, _ = LONG_COMMANDS[command]
    code, err, took = _signalled([_fill(a, values) for a in args], point, tmp_path, signame)
    assert (code, _unwarned(err)) == (130, "mrstereo: interrupted\n")
    assert took < 5.0
    visible = [p.name for p in tmp_path.rglob("*") if p.is_file() and not any(
        part.startswith(".") for part in p.relative_to(tmp_path).parts)]
    partial = [v for v in visible if v not in ("d.pfm",)] if command != "batch (processes)" else []
    assert not partial, partial


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("point", ["import:1", "start:1"], ids=["while loading", "handlers installed"])
def test_a_signal_in_the_first_milliseconds_is_one_line_and_130(ds, tmp_path, point, signame):
    """``import``: the first statement of the command line, before its imports (Python's own start-up comes
    before it); ``start``: its handlers installed, before the command's imports."""
    code, err, _ = _signalled(["info", ds], point, tmp_path, signame)
    assert (code, err.decode()) == (130, "mrstereo: interrupted\n")


def test_ctrl_c_during_a_slow_realtime_replay_stops_at_once(ds, tmp_path):
    """``live --realtime`` on a video of a frame every 20 s: Ctrl-C after the first frame ends the wait for the
    next one, and the run writes its outputs (the first Ctrl-C of live stops it: exit 0)."""
    for side in ("left", "right"):
        writer = cv2.VideoWriter(str(tmp_path / f"{side}.mkv"), cv2.VideoWriter_fourcc(*"FFV1"), 0.05, (160, 120),
                                 isColor=False)
        for k in range(3):
            writer.write(cv2.imread(str(ds / side / f"{k:06d}.png"), cv2.IMREAD_GRAYSCALE))
        writer.release()
    out = tmp_path / "o"
    code, err, took = _signalled(["live", tmp_path / "left.mkv", tmp_path / "right.mkv", "--calib",
                                  ds / "calibration.yaml", "--realtime", "-o", out, "--quiet"], "frame:1", tmp_path)
    assert code == 0 and "Traceback" not in err.decode(), err.decode()
    assert took < 5.0
    assert json.loads((out / "metrics.json").read_text())["frames_in"] == 1


@pytest.mark.parametrize("signame", ["SIGINT", "SIGTERM"])
def test_export_stops_with_one_line_and_leaves_no_dataset(ds, tmp_path, signame):
    bag = _bag_of(ds, tmp_path / "b2", ros1=False)
    out = tmp_path / "x"
    code, err, took = _signalled(["export", "--bag", bag, "-o", out, "--quiet"], "frame:1", tmp_path, signame)
    assert (code, _unwarned(err)) == (130, "mrstereo: interrupted\n")
    assert took < 5.0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["b2"]           # no dataset, no temporary


def test_sigkill_during_synth_leaves_only_a_marked_temporary(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    proc = subprocess.Popen([sys.executable, "-m", "mrstereo", "synth", "--out", str(tmp_path / "S"), "--frames", "3",
                             "--width", "160", "--height", "120", "--quiet"], env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 60
    while not list(tmp_path.glob(".mrstereo-tmp-*.S/left/*.png")) and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.kill()
    proc.wait()
    assert not (tmp_path / "S").exists()
    assert all(io.is_temporary(p) for p in tmp_path.iterdir())


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


# ------------------------------------------------------------------------------------------ every input protected

def _bag_of(ds, path: Path, *, ros1: bool) -> Path:
    from _bags import write_bag

    from mrstereo.recordings.manifest import read_manifest
    return write_bag(path, read_manifest(ds), ros1=ros1, odom=True)


BAG = ["--left-topic", "/stereo/left/image_raw", "--right-topic", "/stereo/right/image_raw", "--odom-topic", "/odom",
       "--quiet"]


def test_a_bags_files_are_inputs_named_or_not(ds, tmp_path, capsys):
    bag = _bag_of(ds, tmp_path / "r2", ros1=False)
    before = _digest(bag)
    storage = next(p for p in bag.iterdir() if p.suffix == ".db3")
    for target in (storage, bag / "metadata.yaml", bag / "trajectory.txt"):
        _run(capsys, ["odometry", "--bag", bag, *BAG, "-o", target.with_suffix(".txt")], must="the bag")
    _run(capsys, ["map", "--bag", bag, *BAG, "-o", bag], must="is the bag")
    _run(capsys, ["map", "--bag", storage, *BAG, "-o", bag / "m"], must="is inside the bag")
    assert _digest(bag) == before


def test_a_datasets_files_are_inputs_wherever_they_lie(ds, tmp_path, capsys):
    data = tmp_path / "DS"
    shutil.copytree(ds, data)
    calib = tmp_path / "calib" / "stereo.yaml"             # referenced from outside the dataset folder
    calib.parent.mkdir()
    shutil.move(data / "calibration.yaml", calib)
    (data / "manifest.yaml").write_text((data / "manifest.yaml").read_text().replace(
        "calibration: calibration.yaml", f"calibration: {calib}"))
    before, before_calib = _digest(data), calib.read_bytes()
    for args, must in (
            (["odometry", data, "-o", data / "left" / "000001.png"], "--out must end in .txt or .tum"),
            (["odometry", data, "-o", data / "left" / "000001.txt"], "lies inside the dataset"),
            (["odometry", data, "-o", tmp_path / "t.txt", "--metrics", data / "calibration.json"],
             "lies inside the dataset"),
            (["odometry", data, "-o", tmp_path / "t.txt", "--metrics", calib], "--metrics must end in .json"),
            (["odometry", data, "-o", tmp_path / "t.txt", "--metrics", calib.with_suffix(".json")], None),
            (["odometry", data, "-o", calib.with_suffix(".txt"), "--plot", calib], "--plot must end in"),
            (["evaluate", data, "--markdown", calib.with_suffix(".md")], None),
            (["map", data, "-o", calib.parent, "--quiet"], None)):
        code = entry([str(a) for a in args])
        err = capsys.readouterr().err
        if must is None:              # outputs beside (not onto) the calibration are fine
            assert code == 0, err
        else:
            assert code == 2 and must in err, err
    link = tmp_path / "evil.md"
    link.symlink_to(calib)
    _run(capsys, ["evaluate", data, "--markdown", link], must=f"would overwrite the input {calib}")
    os.link(calib, tmp_path / "hard.txt")
    _run(capsys, ["odometry", data, "-o", tmp_path / "hard.txt", "--quiet"], must="would overwrite the input")
    assert _digest(data) == before and calib.read_bytes() == before_calib


@pytest.mark.sample_data("euroc-asl-sample")
def test_a_euroc_recordings_files_are_inputs_for_every_command(sample_data, tmp_path, capsys):
    """One rule for map, odometry, batch and live: no output over a frame (wherever data.csv puts it), none
    inside the folder named as the recording (EuRoC's above mav0/) or inside mav0/."""
    euroc = tmp_path / "euroc"
    shutil.copytree(sample_data("euroc-asl-sample"), euroc)
    out = tmp_path / "out"
    out.mkdir()
    csv = euroc / "mav0" / "cam0" / "data.csv"
    first = csv.read_text().splitlines()[1].split(",")
    shutil.copy(euroc / "mav0" / "cam0" / "data" / first[1], out / "map.png")      # a frame lying in -o
    csv.write_text(csv.read_text().replace(f"{first[0]},{first[1]}", f"{first[0]},../../../../out/map.png"))
    before, frame = _digest(euroc), (out / "map.png").read_bytes()
    for args, must in ((["map", euroc, "-o", out], "would overwrite the input"),
                       (["map", euroc, "-o", euroc / "out"], "is inside the EuRoC/ASL recording"),
                       (["map", euroc, "-o", euroc], "is the EuRoC/ASL recording"),
                       (["odometry", euroc, "-o", euroc / "mav0" / "t.txt"], "lies inside the EuRoC/ASL recording"),
                       (["odometry", euroc, "-o", out / "t.txt", "--plot", out / "map.png"],
                        "would overwrite the input"),
                       (["batch", euroc, "-o", euroc / "out"], "choose a folder apart from it"),
                       (["live", euroc, "-o", euroc / "out"], "choose a folder apart from it")):
        _run(capsys, [*args, "--quiet"], must=must)
    assert _digest(euroc) == before and (out / "map.png").read_bytes() == frame and not (euroc / "out").exists()


def test_an_image_folder_recordings_frames_are_inputs(ds, tmp_path, capsys):
    rec = tmp_path / "rec"
    (rec / "left").mkdir(parents=True)
    (rec / "right").mkdir()
    for k in range(3):
        shutil.copy(ds / "left" / f"{k:06d}.png", rec / "left" / f"{k:06d}.png")
        shutil.copy(ds / "right" / f"{k:06d}.png", rec / "right" / f"{k:06d}.png")
    shutil.copy(ds / "calibration.yaml", rec / "stereo.yaml")
    os.link(rec / "left" / "000000.png", tmp_path / "map.png")      # the first frame, also named map.png
    before = _digest(rec)
    _run(capsys, ["map", rec, "-o", rec / "left", "--quiet"], must="is inside the image folders recording")
    _run(capsys, ["map", rec, "-o", tmp_path, "--quiet"], must="would overwrite the input")
    assert _digest(rec) == before


def test_record_bag_removes_only_its_own_temporary(ds, tmp_path):
    """The bag is built in a marked temporary: a user's folder named as the old temporary (.NAME.PID.tmp) stays."""
    out = tmp_path / "m"
    theirs = tmp_path / f".rbx.{os.getpid()}.tmp"
    theirs.mkdir()
    (theirs / "precious.txt").write_text("keep")
    assert entry(["map", str(ds), "-o", str(out), "--record-bag", str(tmp_path / "rbx"), "--quiet"]) == 0
    assert (theirs / "precious.txt").read_text() == "keep"
    assert (tmp_path / "rbx" / "metadata.yaml").is_file() and not _no_temporaries(tmp_path)


@pytest.mark.sample_data("openloris-sample")
def test_calib_convert_never_overwrites_a_sibling_it_read(sample_data, tmp_path, capsys):
    folder = tmp_path / "loris"
    shutil.copytree(sample_data("openloris-sample"), folder, ignore=shutil.ignore_patterns("fisheye*"))
    before = _digest(folder)
    _run(capsys, ["calib", "convert", folder / "sensors.yaml", "-o", folder / "trans_matrix.yaml"],
         must="would overwrite the input")
    assert _digest(folder) == before
    assert entry(["calib", "convert", str(folder / "sensors.yaml"), "-o", str(tmp_path / "stereo.yaml")]) == 0


def test_only_mrstereos_own_temporaries_are_ever_removed(ds, tmp_path):
    out = tmp_path / "m"
    out.mkdir()
    dead = _dead_pid()
    theirs = [out / ".backup.99999.tmp", out / f".notes.{dead}.tmp.txt", out / f".map.{dead}.abcd.tmp",
              out / f".mrstereo-tmp-{dead}-xyz.map", out / "mrstereo-tmp-1-abcdef01.map"]
    theirs[0].mkdir()
    (theirs[0] / "precious.txt").write_text("keep")
    for path in theirs[1:]:
        path.write_text("keep")
    ours = out / f".mrstereo-tmp-{dead}-0123abcd.map.pgm"
    ours.write_bytes(b"half")
    assert entry(["map", str(ds), "-o", str(out), "--quiet"]) == 0
    assert all(p.exists() for p in theirs) and (theirs[0] / "precious.txt").read_text() == "keep"
    assert not ours.exists()


def test_a_killed_runs_folder_is_removed_by_the_next_run(tmp_path):
    """What SIGKILL leaves of synth, export and demo (their staged new folder beside the output) goes with the
    next run into the same place; a live process's temporary stays."""
    dead = _dead_pid()
    stale = tmp_path / f".mrstereo-tmp-{dead}-0123abcd.S"
    (stale / "left").mkdir(parents=True)
    (stale / "left" / "000000.png").write_bytes(b"half")
    live = tmp_path / f".mrstereo-tmp-{os.getpid()}-0123abcd.S"
    live.mkdir()
    assert entry(["synth", "--out", str(tmp_path / "S"), "--frames", "1", "--width", "64", "--height", "48",
                  "--quiet"]) == 0
    assert not stale.exists() and live.exists() and (tmp_path / "S" / "manifest.yaml").is_file()
    stale.mkdir()
    with io.staged_new_dir(tmp_path / "D") as tmp:          # (the demo's report folder)
        (tmp / "report.md").write_text("done")
    assert not stale.exists() and (tmp_path / "D" / "report.md").read_text() == "done"


def test_synth_into_the_empty_working_directory(tmp_path):
    cwd = os.getcwd()
    os.chdir(tmp_path)
    try:
        assert entry(["synth", "--out", ".", "--frames", "1", "--width", "64", "--height", "48", "--quiet"]) == 0
        assert (tmp_path / "manifest.yaml").is_file() and Path.cwd() == tmp_path
        assert entry(["synth", "--out", ".", "--frames", "1", "--quiet"]) == 2        # not empty any more
    finally:
        os.chdir(cwd)


# ------------------------------------------------------------------------------------------ resume knows what changed

def _summary(out: Path) -> dict:
    return {d["name"]: d for d in json.loads((out / "summary.json").read_text())["datasets"]}


def test_batch_recomputes_what_changed_and_says_so(ds, tmp_path, capsys):
    data = tmp_path / "a" / "DS"
    shutil.copytree(ds, data)
    out = tmp_path / "out"
    run = lambda *extra: entry(["batch", str(data), "-o", str(out), "--quiet", *extra])      # noqa: E731
    assert run() == 0
    assert _summary(out)["DS"]["computed"] == 3
    assert run() == 0 and _summary(out)["DS"]["computed"] == 0 and _summary(out)["DS"]["map"] == "kept"
    image = data / "left_rect" / "000001.png"                 # one image of the dataset changed
    pixels = cv2.imread(str(image), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(image), np.flipud(pixels))
    assert run() == 0
    assert (_summary(out)["DS"]["computed"], _summary(out)["DS"]["map"]) == (1, "written")
    for option in (["--fusion", "union"], ["--preset", "robust"], ["--mount", "0,0,0.45,0,0.15,0"]):
        assert run(*option) == 0, option
        assert _summary(out)["DS"]["map"] == "written", option
        if option[0] != "--fusion":
            assert _summary(out)["DS"]["computed"] == 3, option
    assert json.loads((out / "summary.json").read_text())["config"]["preset"] == "mapping"
    (out / "DS" / "map" / "map.pgm").unlink()
    assert run("--mount", "0,0,0.45,0,0.15,0") == 0
    assert _summary(out)["DS"]["map"] == "written" and (out / "DS" / "map" / "map.pgm").is_file()
    capsys.readouterr()


def test_two_datasets_never_share_an_output_folder(ds, tmp_path, capsys):
    a, b, c = tmp_path / "a" / "ds", tmp_path / "b" / "ds", tmp_path / "ds_2"
    for folder, seed in ((a, 0), (b, 1), (c, 2)):
        shutil.copytree(ds, folder)
    cv2.imwrite(str(b / "left_rect" / "000000.png"), np.zeros((120, 160), np.uint8))
    out = tmp_path / "out"
    assert entry(["batch", str(a), str(b), str(c), "-o", str(out), "--quiet"]) == 0
    summary = json.loads((out / "summary.json").read_text())["datasets"]
    folders = [d["out_dir"] for d in summary]
    assert len(set(folders)) == 3 and Path(summary[2]["out_dir"]).name == "ds_2"
    for d in summary:
        assert json.loads((Path(d["out_dir"]) / "dataset.json").read_text())["root"] == str(Path(
            d["manifest"]).parent)
    # the same names in another order: the same folders (deterministic)
    assert entry(["batch", str(c), str(b), str(a), "-o", str(out), "--quiet"]) == 0
    again = {d["manifest"]: d for d in json.loads((out / "summary.json").read_text())["datasets"]}
    assert all(again[d["manifest"]]["out_dir"] == d["out_dir"] and again[d["manifest"]]["computed"] == 0
               for d in summary)
    # another dataset of an already used name: a folder of its own, the first one's results untouched
    other = tmp_path / "c" / "ds_2"
    shutil.copytree(ds, other)
    before = _digest(out / "ds_2")
    assert entry(["batch", str(other), "-o", str(out), "--quiet"]) == 0
    assert _digest(out / "ds_2") == before
    assert _summary(out)[next(iter(_summary(out)))]["computed"] == 3
    capsys.readouterr()


_INTERRUPT = """
import os, signal, sys
from pathlib import Path
import mrstereo.io.files as files
target = Path(sys.argv[1]).resolve()
real_replace, real_exchange = files.os.replace, files._exchange
fired = []

def interrupt():
    if not fired:
        fired.append(1)
        os.kill(os.getpid(), signal.SIGINT)          # Ctrl-C in the middle of the swap or the moves

def replace(src, dst, *args, **kwargs):
    src, dst = Path(src).resolve(), Path(dst).resolve()
    if target in (src, dst, dst.parent):
        interrupt()
    return real_replace(src, dst, *args, **kwargs)

def exchange(a, b):
    interrupt()
    return real_exchange(a, b) if sys.argv[2] == "exchange" else False

files.os.replace, files._exchange = replace, exchange
from mrstereo.cli import entry
code = entry(sys.argv[3:])
print("fired" if fired else "not fired", code)
"""


def _interrupted_run(target: Path, mode: str, args) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-c", _INTERRUPT, str(target), mode, *map(str, args)],
                          capture_output=True, text=True, env=env, timeout=120)


@pytest.mark.parametrize("mode", ["exchange", "no-exchange"])
def test_ctrl_c_during_batchs_map_swap_leaves_one_whole_map(ds, tmp_path, mode):
    out = tmp_path / "out"
    assert entry(["batch", str(ds), "-o", str(out), "--quiet"]) == 0
    map_dir = out / ds.name / "map"
    old = _digest(map_dir)
    proc = _interrupted_run(map_dir, mode, ["batch", ds, "-o", out, "--quiet", "--fusion", "union"])
    assert proc.returncode == 130 and proc.stderr == "mrstereo: interrupted\n", proc.stderr
    new = _digest(map_dir)
    assert set(new) == set(old)                        # whole: every file of a map
    record = json.loads((map_dir / "batch.json").read_text())
    assert new == old or new["map.pgm"] != old["map.pgm"] and record["fingerprint"] != json.loads(
        (out / "summary.json").read_text())["datasets"][0]["fingerprint"]
    assert not _no_temporaries(out)


def test_ctrl_c_during_maps_moves_leaves_the_old_or_the_new_set(ds, tmp_path):
    out = tmp_path / "m"
    assert entry(["map", str(ds), "-o", str(out), "--quiet"]) == 0
    old = _digest(out)
    proc = _interrupted_run(out, "exchange", ["map", ds, "-o", out, "--quiet", "--fusion", "union"])
    assert proc.returncode == 130 and proc.stderr == "mrstereo: interrupted\n", proc.stderr
    assert entry(["map", str(ds), "-o", str(tmp_path / "ref"), "--quiet", "--fusion", "union"]) == 0
    assert _digest(out) in (old, _digest(tmp_path / "ref"))          # the old set or the new one, never a mix
    assert not _no_temporaries(out)


# ------------------------------------------------------------------------------------------ suspicious input named

def test_map_thresholds_that_turn_walls_free_are_refused(ds, tmp_path, capsys):
    from mrstereo.mapping.rosmap import RosMap, read_ros_map

    for occupied, free in ((5, -3), (0.2, 0.6), (0.65, 0.65), (1.5, 0.1)):
        yaml_path = tmp_path / f"m{occupied}_{free}.yaml"
        yaml_path.write_text((ds / "gt_map.yaml").read_text().replace("gt_map.pgm", str(ds / "gt_map.pgm"))
                             .replace("occupied_thresh: 0.65", f"occupied_thresh: {occupied}")
                             .replace("free_thresh: 0.196", f"free_thresh: {free}"))
        _run(capsys, ["plan", yaml_path, "--start", "1,0", "--goal", "2,0", "-o", tmp_path / "p.json"],
             must="thresh")
    ros_map = read_ros_map(ds / "gt_map.yaml")
    with pytest.raises(ValueError, match="free_thresh"):
        RosMap(ros_map.occupancy, ros_map.grid, occupied_thresh=0.5, free_thresh=0.7)
    with pytest.raises(ValueError, match="occupancy has shape"):
        RosMap(ros_map.occupancy[:, :-1], ros_map.grid)


@pytest.mark.parametrize("case", ["identical", "swapped"])
def test_duplicated_or_swapped_streams_are_named(ds, tmp_path, capsys, case):
    data = tmp_path / "DS"
    shutil.copytree(ds, data)
    for side in ("", "_rect"):
        left, right = data / f"left{side}", data / f"right{side}"
        if case == "identical":
            shutil.rmtree(right)
            shutil.copytree(left, right)
        else:
            left.rename(data / "tmp")
            right.rename(left)
            (data / "tmp").rename(right)
    for args in (["map", data, "-o", tmp_path / "m", "--quiet"], ["batch", data, "-o", tmp_path / "b", "--quiet"],
                 ["live", data, "-o", tmp_path / "l", "--quiet"],        # live and map: one check
                 ["disparity", data / "left_rect" / "000000.png", data / "right_rect" / "000000.png",
                  "--max-disparity", "32", "-o", tmp_path / "d.pfm"]):
        entry([str(a) for a in args])
        err = capsys.readouterr().err
        warnings = [line for line in err.splitlines() if line.startswith("mrstereo: warning:")]
        assert any(case in w for w in warnings), err
        assert "Traceback" not in err


def test_real_streams_are_not_named_suspicious(ds, tmp_path, capsys):
    assert entry(["map", str(ds), "-o", str(tmp_path / "m"), "--quiet"]) == 0
    assert "warning" not in capsys.readouterr().err


def test_a_calibration_that_did_not_converge_is_not_written_unless_forced(tmp_path, capsys):
    from mrstereo.calibration import planar_grid

    rng = np.random.default_rng(0)
    grid = planar_grid(6, 5, 0.05)                      # one fronto-parallel planar view: focal and distance trade
    K = np.array([[300.0, 0, 160], [0, 300.0, 120], [0, 0, 1]])
    uv = (grid + [-0.12, -0.1, 1.0]) @ K.T
    uv = uv[:, :2] / uv[:, 2:] + rng.normal(0, 0.3, (len(grid), 2))
    points = tmp_path / "pts.csv"
    points.write_text("X,Y,Z,u,v\n" + "\n".join(",".join(f"{v:.6f}" for v in (*p, *q)) for p, q in zip(grid, uv)))
    out = tmp_path / "cam.yaml"
    # LM cannot converge here whatever the GA's start: a short GA is enough
    code = entry(["calibrate", "--points", str(points), "--image-size", "320x240", "--generations", "100", "-o",
                  str(out), "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and "did not converge" in err and "--force" in err and err.count("\n") == 1
    assert not out.exists()
    assert entry(["calibrate", "--points", str(points), "--image-size", "320x240", "--generations", "100", "-o",
                  str(out), "--quiet", "--force"]) == 0
    assert out.exists() and "mrstereo: warning: the calibration did not converge" in capsys.readouterr().err


def test_a_nan_pose_in_a_bag_is_refused_with_its_message_index(ds, tmp_path, capsys):
    from _bags import T0_NS, DT_NS, BagWriter

    from mrstereo.recordings.manifest import read_manifest
    manifest = read_manifest(ds)
    topics = {"/l": "sensor_msgs/msg/Image", "/r": "sensor_msgs/msg/Image", "/odom": "nav_msgs/msg/Odometry"}
    bag = tmp_path / "nan.bag"
    with BagWriter(bag, True, topics) as w:
        for k, rec in enumerate(manifest.frames):
            t = T0_NS + k * DT_NS
            w.put("/l", w.msgs.image(cv2.imread(str(rec.left_rect), 0), t, "l"), t)
            w.put("/r", w.msgs.image(cv2.imread(str(rec.right_rect), 0), t, "r"), t)
            w.put("/odom", w.msgs.planar_odometry((float("nan") if k == 2 else 0.0, 0.0, 0.0), t), t)
    _run(capsys, ["export", "--bag", bag, "--left-topic", "/l", "--right-topic", "/r", "--odom-topic", "/odom",
                  "--calib", ds / "calibration.yaml", "--rectified-images", "-o", tmp_path / "x", "--quiet"],
         must="bag topic /odom: message 2 has a non-finite pose")
    assert not (tmp_path / "x").exists()


def test_frames_outside_the_map_are_named(ds, tmp_path, capsys):
    assert entry(["map", str(ds), "-o", str(tmp_path / "m"), "--origin", "100,100", "--size", "12,6", "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "mrstereo: warning: 3 of 3 frames were taken outside the map [100, 112] x [100, 106] m" in err
    assert "the map observed no cell" in err


def test_map_origin_on_a_dataset_with_a_ground_truth_map_compares_the_overlap(ds, tmp_path, capsys):
    assert entry(["map", str(ds), "-o", str(tmp_path / "a"), "--quiet"]) == 0
    assert entry(["map", str(ds), "-o", str(tmp_path / "b"), "--origin", "-2,-3", "--size", "14,6", "--quiet"]) == 0
    a, b = (json.loads((tmp_path / n / "metrics.json").read_text()) for n in "ab")
    assert a["precision"] == pytest.approx(b["precision"], abs=0.02) and a["recall"] == pytest.approx(
        b["recall"], abs=0.02)
    assert entry(["map", str(ds), "-o", str(tmp_path / "c"), "--resolution", "0.07", "--quiet"]) == 0
    assert "no metrics: the ground-truth map" in capsys.readouterr().err


ABSURD = {
    "--max-disparity 100000": ["disparity", "{L}", "{R}", "--max-disparity", "100000", "-o", "{T}/d.pfm"],
    "--max-disparity 0.001": ["disparity", "{L}", "{R}", "--max-disparity", "0.001", "-o", "{T}/d.pfm"],
    "--max-disparity nan": ["disparity", "{L}", "{R}", "--max-disparity", "nan", "-o", "{T}/d.pfm"],
    "--angle-increment 720": ["scan", "{L}", "{R}", "--calib", "{DS}/calibration.yaml", "--rectified",
                              "--angle-increment", "720", "-o", "{T}/s.json"],
    "--pan 1e300": ["points", "{L}", "{R}", "--calib", "{DS}/calibration.yaml", "--rectified", "--pan", "1e300",
                    "-o", "{T}/p.ply"],
    "--height -1": ["points", "{L}", "{R}", "--calib", "{DS}/calibration.yaml", "--rectified", "--height", "-1",
                    "-o", "{T}/p.ply"],
    "--mount 1e9": ["map", "{DS}", "-o", "{T}/m", "--mount", "1e9,0,0,0,0,0"],
    "--size -1": ["map", "{DS}", "-o", "{T}/m", "--size", "-1,5", "--origin", "0,0"],
    "--origin inf": ["map", "{DS}", "-o", "{T}/m", "--origin", "inf,0", "--size", "5,5"],
    "--radius 1e9": ["plan", "{DS}/gt_map.yaml", "--start", "1,0", "--goal", "2,0", "--radius", "1e9", "-o",
                     "{T}/p.json"],
    "--start 1e300": ["plan", "{DS}/gt_map.yaml", "--start", "1e300,0", "--goal", "2,0", "-o", "{T}/p.json"],
    "--sync-tolerance 1e9": ["export", "--bag", "{T}/x.bag", "--left-topic", "/l", "--right-topic", "/r",
                             "--sync-tolerance", "1e9", "-o", "{T}/e"],
    "--square 0": ["stereo-calibrate", "--left", "{T}/*.png", "--right", "{T}/*.png", "--square", "0", "-o",
                   "{T}/s.yaml"],
    "--generations 1e12": ["calibrate", "--points", "{T}/p.csv", "--image-size", "64x48", "--generations",
                           "1000000000000", "-o", "{T}/c.yaml"],
    "--image-size 0x0": ["calibrate", "--points", "{T}/p.csv", "--image-size", "0x0", "-o", "{T}/c.yaml"],
    "--alpha 2": ["calib", "convert", "{DS}/calibration.yaml", "--alpha", "2", "-o", "{T}/s.yaml"],
    "--seed -1": ["synth", "--out", "{T}/S", "--seed", "-1"],
    "--step 1e9": ["synth", "--out", "{T}/S", "--step", "1e9"],
    "--odometry-noise 5,0": ["synth", "--out", "{T}/S", "--odometry-noise", "5,0"],
    "--workers 10000": ["batch", "{DS}", "-o", "{T}/b", "--workers", "10000", "--processes"],
    "--resolution 1e-9": ["map", "{DS}", "-o", "{T}/m", "--resolution", "1e-9"],
    "evaluate --max-disparity 1e9": ["evaluate", "{DS}", "--max-disparity", "1000000000"],
}


@pytest.mark.parametrize("case", sorted(ABSURD))
def test_absurd_option_values_are_refused_with_their_range(ds, tmp_path, capsys, case):
    left, right = _pair(ds)
    values = {"{L}": str(left), "{R}": str(right), "{T}": str(tmp_path), "{DS}": str(ds)}
    line = _run(capsys, [_fill(a, values) for a in ABSURD[case]])
    option = case.split()[0] if case.startswith("--") else case.split()[1]
    assert option in line, line
    assert not [p for p in tmp_path.iterdir()], "a refused run wrote something"


def test_every_numeric_option_has_a_range():
    from mrstereo.cli._main import main
    from mrstereo.cli._options import Number

    def walk(group, prefix=""):
        for name, command in group.commands.items():
            if hasattr(command, "commands"):
                yield from walk(command, f"{prefix}{name} ")
            else:
                yield f"{prefix}{name}", command

    unchecked = [f"{name} {param.opts[0]}" for name, command in walk(main) for param in command.params
                 if isinstance(param.type, (click.types.IntParamType, click.types.FloatParamType))
                 and not isinstance(param.type, Number)]
    assert not unchecked, unchecked


# ------------------------------------------------------------------------------------------ 16-bit images

def test_a_16_bit_copy_of_an_8_bit_pair_matches_bit_for_bit(ds, tmp_path, capsys):
    left, right = _pair(ds)
    wide = []
    for path in (left, right):
        target = tmp_path / f"{path.parent.name}16.png"
        cv2.imwrite(str(target), cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.uint16) * 257)
        wide.append(target)
    for images, out in (((left, right), "d8.pfm"), (wide, "d16.pfm")):
        assert entry(["disparity", *map(str, images), "--max-disparity", "32", "-o", str(tmp_path / out)]) == 0
    a, b = io.read_pfm(tmp_path / "d8.pfm"), io.read_pfm(tmp_path / "d16.pfm")
    assert np.array_equal(a, b, equal_nan=True) and np.isfinite(a).mean() > 0.3
    # genuine 16-bit data (the 8-bit levels with 8 more bits of detail) matches about as densely
    rng = np.random.default_rng(0)
    for path, target in zip((left, right), wide):
        base = cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.int32) * 257
        cv2.imwrite(str(target), np.clip(base + rng.integers(-128, 128, base.shape), 0, 65535).astype(np.uint16))
    assert entry(["disparity", *map(str, wide), "--max-disparity", "32", "-o", str(tmp_path / "g16.pfm")]) == 0
    c = io.read_pfm(tmp_path / "g16.pfm")
    assert abs(np.isfinite(c).mean() - np.isfinite(a).mean()) < 0.05
    capsys.readouterr()


def test_a_raw_mono16_dataset_maps_like_its_8_bit_copy(ds, tmp_path, capsys):
    wide = tmp_path / "W"
    shutil.copytree(ds, wide)
    for path in list((wide / "left").glob("*.png")) + list((wide / "right").glob("*.png")):
        cv2.imwrite(str(path), cv2.imread(str(path), cv2.IMREAD_UNCHANGED).astype(np.uint16) * 257)
    for folder in ("left_rect", "right_rect"):           # the raw pairs are rectified (OpenCV remap) here
        shutil.rmtree(wide / folder)
    text = "\n".join(line for line in (wide / "manifest.yaml").read_text().splitlines() if "_rect:" not in line)
    (wide / "manifest.yaml").write_text(text + "\n")
    narrow = tmp_path / "N"
    shutil.copytree(ds, narrow)
    for folder in ("left_rect", "right_rect"):
        shutil.rmtree(narrow / folder)
    (narrow / "manifest.yaml").write_text(text.replace(str(wide), str(narrow)) + "\n")
    for folder, out in ((narrow, "m8"), (wide, "m16")):
        assert entry(["map", str(folder), "-o", str(tmp_path / out), "--quiet"]) == 0
    assert np.array_equal(np.load(tmp_path / "m8" / "log_odds.npy"), np.load(tmp_path / "m16" / "log_odds.npy"),
                          equal_nan=True)
    capsys.readouterr()


# ------------------------------------------------------------------------------------------ the API's boundary

def _python(code: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, timeout=timeout)


def test_occupancy_grid_apply_refuses_cells_outside_the_grid():
    code = """
import numpy as np
from mrstereo.mapping import GridSpec, OccupancyGrid
from mrstereo.mapping.occupancy import view_cells
grid = OccupancyGrid(GridSpec())
cells = view_cells(np.array([[2.0, 0.0, 0.3]] * 10), None, (0.0, 0.0, 0.45), grid=grid.grid, config=grid.config)
for bad in ([10 ** 9], [-5], np.array([1.5]), np.zeros((2, 2), np.int64)):
    try:
        grid.apply(cells._replace(hit=np.asarray(bad), hit_z_m=None))
    except (ValueError, TypeError) as exc:
        print(type(exc).__name__, str(exc).split(",")[0])
"""
    proc = _python(code)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert len(lines) == 4 and all("cells.hit" in line for line in lines), proc.stdout


def test_plan_path_refuses_a_map_whose_occupancy_and_grid_differ():
    code = """
import dataclasses, numpy as np
from mrstereo.mapping import GridSpec
from mrstereo.mapping.planning import plan_path
from mrstereo.mapping.rosmap import RosMap
ok = RosMap(np.zeros((40, 60)), GridSpec(width_m=3.0, height_m=2.0, resolution_m=0.05, origin_y_m=-1.0))
bad = object.__new__(RosMap)
for field in dataclasses.fields(RosMap):
    object.__setattr__(bad, field.name, getattr(ok, field.name))
object.__setattr__(bad, "occupancy", np.zeros((20, 60)))
try:
    plan_path(bad, (0.5, 0.0), (2.5, 0.0))
except ValueError as exc:
    print("ValueError", exc)
print(plan_path(ok, (0.5, 0.0), (2.5, 0.0)).success)
"""
    proc = _python(code, timeout=60)
    assert proc.returncode == 0, proc.stderr
    assert "ValueError ros_map.occupancy has shape (20, 60)" in proc.stdout and proc.stdout.endswith("True\n")


# ------------------------------------------------------------------------------------------ pipes

def test_a_closed_pipe_ends_quietly(tmp_path):
    env = dict(os.environ, PYTHONPATH=str(SRC), MPLBACKEND="Agg")
    proc = subprocess.run(f"{sys.executable} -m mrstereo data list | head -1", shell=True, capture_output=True,
                          text=True, env=env, timeout=60, executable="/bin/bash")
    assert proc.stderr == "" and proc.stdout.count("\n") == 1
    status = subprocess.run(f"set -o pipefail; {sys.executable} -m mrstereo data list | head -1 >/dev/null",
                            shell=True, env=env, timeout=60, executable="/bin/bash")
    assert status.returncode == 0
