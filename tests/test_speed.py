"""Speed plumbing: rectification maps built once per calibration, per-stage profiling (--profile)."""
from __future__ import annotations

import pickle

import cv2
import numpy as np

from mrstereo.camera import Camera, CameraInfo, CameraMount, StereoCamera
from mrstereo.camera import camera_info as camera_info_module
from mrstereo.cli import entry
from mrstereo.profiling import Profile, active, profiling, stage
from mrstereo.transforms import rotation_from_rpy

CAM = Camera(width=160, height=120, fx=101.0, fy=99.5, cx=81.3, cy=58.9, k1=-0.08, k2=0.01)


def _stereo(baseline_m=0.12):
    K_rect = np.array([[100.0, 0, 80.0], [0, 100.0, 60.0], [0, 0, 1]])
    P_left = np.hstack([K_rect, np.zeros((3, 1))])
    P_right = P_left.copy()
    P_right[0, 3] = -100.0 * baseline_m
    R_left = rotation_from_rpy(0.01, -0.005, 0.002)
    return StereoCamera(left=CameraInfo(CAM, R=R_left, P=P_left, name="left"),
                        right=CameraInfo(CAM, R=rotation_from_rpy(-0.004, 0.008, -0.01), P=P_right,
                                         name="right"),
                        mount=CameraMount.from_rig(0.45, 0.15, R_rect_from_cam=R_left))


def _images():
    rng = np.random.default_rng(3)
    return (rng.integers(0, 256, (120, 160), dtype=np.uint8), rng.integers(0, 256, (120, 160), dtype=np.uint8))


def test_rectification_maps_are_built_once_per_calibration(monkeypatch):
    camera_info_module._MAPS_CACHE.clear()
    built = []
    original = Camera.undistort_rectify_maps

    def counting(self, **kw):
        built.append(self)
        return original(self, **kw)

    monkeypatch.setattr(Camera, "undistort_rectify_maps", counting)
    stereo, (left, right) = _stereo(), _images()
    first = stereo.rectify(left, right)
    assert len(built) == 2                       # one map pair per camera
    second = stereo.rectify(left, right)
    copy = pickle.loads(pickle.dumps(stereo))    # a worker's copy of the same calibration
    third = copy.rectify(left, right)
    assert len(built) == 2                       # not rebuilt
    # the same output as the maps a user builds with OpenCV
    for info, img, a, b, c in zip((stereo.left, stereo.right), (left, right), first, second, third):
        mx, my = cv2.initUndistortRectifyMap(CAM.K, CAM.dist_coeffs, info.R, info.P, (160, 120), cv2.CV_32FC1)
        ref = cv2.remap(img, mx, my, cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        assert np.array_equal(a, ref) and np.array_equal(b, ref) and np.array_equal(c, ref)
    # another baseline: the left camera's maps are shared, the right camera's are new
    _stereo(baseline_m=0.2).rectify(left, right)
    assert len(built) == 3
    maps = stereo.rectification_maps()[0][0]
    assert not maps.flags.writeable


def test_profile_accumulates_named_stages_and_is_off_by_default():
    assert active() is None
    with stage("match"):                  # no profile: nothing recorded, nothing raised
        pass
    with profiling() as prof:
        assert isinstance(prof, Profile) and active() is prof
        for _ in range(3):
            with stage("match"):
                sum(range(1000))
            with stage("reject"):
                pass
    assert active() is None
    assert prof.calls == {"match": 3, "reject": 3}
    assert prof.seconds["match"] > 0
    table = prof.table()
    assert "3 frames" in table and "match" in table and "reject" in table


def test_profile_times_the_stages_of_a_pair(tmp_path):
    from mrstereo.geometry.pair import obstacles_from_pair

    stereo, (left, right) = _stereo(), _images()
    with profiling() as prof:
        obstacles_from_pair(left, right, stereo, max_disparity_px=16)
    assert {name for name in prof.calls if "." not in name} == {"rectify", "match", "reject", "3-D"}
    assert all(prof.calls[name] == 1 for name in ("rectify", "match", "reject", "3-D"))
    # the matcher's parts, each its own time, together within the match stage
    parts = {name for name in prof.calls if name.startswith("match.")}
    assert {"match.prepare", "match.search", "match.post"} <= parts
    assert 0 < sum(prof.seconds[name] for name in parts) <= prof.seconds["match"]
    assert "  .search" in prof.table() and "  .other" in prof.table()


def test_cli_profile_prints_a_stage_table(tmp_path, capsys):
    stereo, (left, right) = _stereo(), _images()
    from mrstereo.camera import write_stereo

    write_stereo(tmp_path / "stereo.yaml", stereo)
    cv2.imwrite(str(tmp_path / "l.png"), left)
    cv2.imwrite(str(tmp_path / "r.png"), right)
    args = [str(tmp_path / "l.png"), str(tmp_path / "r.png"), "--calib", str(tmp_path / "stereo.yaml")]
    assert entry(["disparity", *args, "--max-disparity", "16", "-o", str(tmp_path / "d.pfm"), "--profile"]) == 0
    err = capsys.readouterr().err
    assert "profile (1 frame" in err
    assert all(f"\n{name} " in err for name in ("read", "rectify", "match"))
    assert entry(["disparity", *args, "--max-disparity", "16", "-o", str(tmp_path / "e.pfm")]) == 0
    assert "ms/frame" not in capsys.readouterr().err


def _textures():
    """uint8 gray images with plain, weakly and strongly textured areas, saturated spots and a ramp."""
    rng = np.random.default_rng(7)
    plain = np.full((90, 130), 117, np.uint8)
    plain[:, 60:] = np.clip(117 + rng.normal(0, 2.5, (90, 70)), 0, 255).astype(np.uint8)      # sigma near T
    noise = rng.integers(0, 256, (90, 130), dtype=np.uint8)
    noise[10:30, 10:40] = 255
    noise[50:70, 80:120] = 0
    ramp = np.tile(np.linspace(0, 255, 130).astype(np.uint8), (90, 1))
    return [plain, noise, ramp, cv2.GaussianBlur(noise, (0, 0), 3.0)]


def test_uint8_patch_statistics_are_bit_identical_to_the_float64_filters():
    """Integer window sums (cv2.boxFilter / sqrBoxFilter of the uint8 image) give the same bits as the
    float64 path (taken for float images), for windows held in float32 (<= 15 px) and beyond."""
    from mrstereo.rejection import RejectionConfig, patch_statistics, reject_uniform

    for image in _textures():
        for w in (3, 5, 9, 15, 17, 31):
            fast = patch_statistics(image, window_px=w)
            ref = patch_statistics(image.astype(np.float32), window_px=w)      # float64 filters
            assert fast.mean.dtype == np.float32 and fast.std.dtype == np.float32
            assert np.array_equal(fast.mean, ref.mean) and np.array_equal(fast.std, ref.std), w
        # and against numpy in float64, independent of OpenCV's filters
        pad = np.pad(image.astype(np.float64), 4, mode="reflect")
        windows = np.lib.stride_tricks.sliding_window_view(pad, (9, 9))
        std = np.sqrt(np.maximum((windows ** 2).mean(axis=(2, 3)) - windows.mean(axis=(2, 3)) ** 2, 0))
        np.testing.assert_allclose(patch_statistics(image).std, std, atol=1e-3)
        d = np.full(image.shape, 5.0, np.float32)
        a = reject_uniform(d, image, config=RejectionConfig())
        b = reject_uniform(d, image.astype(np.float32), config=RejectionConfig())
        assert np.array_equal(a.uniform, b.uniform) and np.array_equal(a.disparity_px, b.disparity_px,
                                                                      equal_nan=True)


def test_uint8_patch_statistics_on_real_scenes(sample_data):
    from mrstereo.evaluation import load_scene
    from mrstereo.rejection import patch_statistics

    for name in ("teddy", "kitti2012-000070"):
        scene = load_scene(sample_data(name))
        gray = scene.left if scene.left.ndim == 2 else cv2.cvtColor(scene.left, cv2.COLOR_BGR2GRAY)
        fast, ref = patch_statistics(gray), patch_statistics(gray.astype(np.float32))
        assert np.array_equal(fast.std, ref.std) and np.array_equal(fast.mean, ref.mean)


def test_cli_commands_load_on_demand_and_the_table_lists_every_command():
    """``mrstereo map`` imports only its own command module; the name -> module table matches every
    module's COMMANDS, and the group lists all of them."""
    import importlib
    import subprocess
    import sys

    from mrstereo.cli._main import COMMAND_MODULES, main

    for module in set(COMMAND_MODULES.values()):
        names = {c.name for c in importlib.import_module(f"mrstereo.cli.{module}").COMMANDS}
        assert names == {n for n, m in COMMAND_MODULES.items() if m == module}, module
    assert sorted(main.commands) == sorted(COMMAND_MODULES)
    code = ("import sys; from mrstereo.cli import entry; entry(['map', '--help']); "
            "print(sorted(m for m in sys.modules if m.startswith('mrstereo.cli.')))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    loaded = eval(out.strip().splitlines()[-1])
    assert "mrstereo.cli._pipeline" in loaded
    assert not {"mrstereo.cli._calibration", "mrstereo.cli._evaluation", "mrstereo.cli._odometry"} & set(loaded)


def test_texture_rejection_of_a_uint8_image_equals_that_of_the_float_image():
    """Eq. (13) on a uint8 image (integer window sums): the same disparity, rejected and uniform masks,
    bit for bit, as on the float image (float64 filters), for thresholds at which many patches have sigma
    within float32 rounding of T; the statistics are the same."""
    from mrstereo.rejection import RejectionConfig, reject_uniform

    rng = np.random.default_rng(5)
    for image in _textures():
        d = rng.uniform(-1, 40, image.shape).astype(np.float32)
        d[rng.random(image.shape) < 0.2] = np.nan
        ref_stats = reject_uniform(d, image.astype(np.float32)).stats
        near = np.unique(ref_stats.std[(ref_stats.std > 0.5) & (ref_stats.std < 12)])
        exact = rng.choice(near, 3).tolist() if near.size else []
        for t in (3.0, 2.5, 0.7, 10.0, *exact):          # and T equal to some patches' sigma
            for w in (5, 9, 17):
                config = RejectionConfig(texture_threshold=t, window_px=w)
                fast = reject_uniform(d, image, config=config)
                ref = reject_uniform(d, image.astype(np.float32), config=config)
                assert np.array_equal(fast.disparity_px, ref.disparity_px, equal_nan=True), (t, w)
                assert np.array_equal(fast.uniform, ref.uniform) and np.array_equal(fast.rejected, ref.rejected)
                assert fast.disparity_px.dtype == np.float32
        assert np.array_equal(reject_uniform(d, image).stats.std, ref_stats.std)


def test_profile_clock_is_a_parameter():
    import time

    ticks = iter(range(100))
    with profiling(Profile(clock=lambda: float(next(ticks)))) as prof:
        with stage("match"):
            pass
        with stage("match"):
            pass
    assert prof.seconds == {"match": 2.0} and prof.calls == {"match": 2}
    assert Profile().clock is time.perf_counter


def test_profile_parts_count_their_own_time_and_the_parent_the_whole():
    ticks = iter(range(100))
    with profiling(Profile(clock=lambda: float(next(ticks)))) as prof:
        with stage("match"):                      # 0 .. 9
            with stage("match.search"):           # 1 .. 6, of which 2 .. 5 is prepare (nested)
                with stage("match.prepare"):
                    with stage("other"):          # a plain stage inside a part is not a part: 3 .. 4
                        pass
            with stage("match.post"):             # 7 .. 8
                pass
    assert prof.seconds == {"other": 1.0, "match.prepare": 3.0, "match.search": 2.0, "match.post": 1.0,
                            "match": 9.0}
    table = prof.table(1)
    lines = table.splitlines()
    assert lines[-1].split()[:2] == ["sum", "10000.00"]          # match + other, not the parts
    assert any(line.split() == [".other", "3000.00", "3.000"] for line in lines)    # 9 - (3 + 2 + 1)


# ------------------------------------------------------------------------------------------ first run
def _signature_counts(modules) -> dict:
    return {(module.__name__, name): len(value.signatures) for module in modules
            for name, value in vars(module).items() if hasattr(value, "signatures")}


def test_the_matcher_warm_up_compiles_what_a_real_frame_runs(tmp_path):
    """After warm_up, matching real-looking frames (a rendered corridor, both presets, with a
    calibration) and a too-near box compiles no further kernel variant: the first frame is not
    held up by a compile."""
    from mrstereo.matching import compute_disparity
    from mrstereo.matching.warmup import KERNEL_MODULES, cache_is_cold, warm_up

    results = warm_up()
    assert any(result.too_near.sum() > 500 for result in results)        # the near guard's whole path ran
    assert all(np.isfinite(result.disparity_px).mean() > 0.3 for result in results)
    assert not cache_is_cold()                                            # written to numba's cache
    assert cache_is_cold((pickle,))                                       # a module without kernels: nothing cached
    before = _signature_counts(KERNEL_MODULES)
    assert sum(before.values()) > 20
    stereo = StereoCamera.ideal(Camera(width=160, height=120, fx=100.0, fy=100.0, cx=80.0, cy=60.0), 0.12)
    left, right = _images()
    left[30:90, 40:100] = np.roll(right, 30, axis=1)[30:90, 40:100]       # a box at 30 px, past the near limit
    for preset in ("robust", "mapping"):
        compute_disparity(left, right, calibration=stereo, preset=preset)
        compute_disparity(left.astype(np.float32), right, max_disparity_px=20, preset=preset)
    assert _signature_counts(KERNEL_MODULES) == before


def test_warm_up_covers_the_chain_and_says_compiling_only_when_cold(capsys, monkeypatch):
    """After mrstereo._warmup.warm_up, a whole frame (rectify, match, reject, 3-D, free space, scan, grid)
    compiles no further kernel variant; the command says it compiles only when numba's cache is cold."""
    from mrstereo import _warmup
    from mrstereo.mapping import OccupancyGrid
    from mrstereo.matching import warmup
    from mrstereo.geometry.pair import scan_from_pair
    from mrstereo.geometry import FreeSpaceConfig

    _warmup.warm_up()
    modules = _warmup.chain_kernel_modules()
    before = _signature_counts(modules)
    stereo, (left, right) = _stereo(), _images()
    frame = scan_from_pair(left, right, stereo, max_disparity_px=16, preset="mapping", free_space=FreeSpaceConfig())
    grid = OccupancyGrid()
    obstacles = frame.frame.obstacles
    grid.update(obstacles.obstacle_points_robot.astype(np.float32), obstacles.floor_points_robot.astype(np.float32),
                (0.0, 0.0, 0.45), baseline_focal_m_px=12.0)
    assert _signature_counts(modules) == before

    assert entry(["warm-up"]) == 0
    captured = capsys.readouterr()
    assert "kernels ready" in captured.out and _warmup.COLD_MESSAGE not in captured.err     # (warm: loaded)
    monkeypatch.setattr(warmup, "cache_is_cold", lambda modules=None: True)
    said = []
    assert _warmup.warm_up(say=said.append) > 0
    assert said == [_warmup.COLD_MESSAGE]
