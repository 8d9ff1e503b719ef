"""Calibration benchmark: accuracy and time of the paper's GA, GA + LM and LM against OpenCV.

Run:  python benchmarks/bench_calibration.py [--quick]

1. Paper single-view dot target (mrstereo.world.render_paper_dot_target, exact
   correspondences + 0.1 px noise): GA alone with Table 2 settings, several seeds.
2. Synthetic multi-view chessboards (world poses, exact corners + 0.1 px noise), random and
   grid coverage of the image: GA + LM recovery of focal length, principal point and the
   distortion field over 20 noise draws (3 with --quick), and which captures (board, number
   of views) reach issue #3's target (f 0.5 %, principal point 1 px, 0.05 px everywhere).
3. Rendered chessboard images through cv2.findChessboardCorners: stereo GA + LM.
4. OpenCV's real stereo set (13 pairs): GA + LM vs cv2.calibrateCamera /
   stereoCalibrate + stereoRectify on the same corners, with timings.
5. Every --model (k1k2, plumb_bob, rational, fisheye) on the same set with LM vs
   cv2.calibrateCamera (matching flags) + cv2.stereoCalibrate + cv2.stereoRectify, or their
   cv2.fisheye counterparts; and the set given swapped.

Run one section: python benchmarks/bench_calibration.py --section 5
"""
from __future__ import annotations

import argparse
import statistics
import time

import cv2
import numpy as np

from mrstereo.calibration import (CalibrationView, calibrate_camera, calibrate_stereo, chessboard_pairs,
                                  detect_chessboard, expand_glob, planar_grid)
from mrstereo.recordings import samples as sample_data

FLAGS = cv2.CALIB_FIX_K3 | cv2.CALIB_ZERO_TANGENT_DIST


def distortion_field_error(est, true) -> tuple[float, float]:
    u, v = np.meshgrid(np.linspace(0, true.width - 1, 41), np.linspace(0, true.height - 1, 31))
    uv = np.stack([u.ravel(), v.ravel()], 1)
    e = np.linalg.norm((est.undistort_pixels(uv) - uv) - (true.undistort_pixels(uv) - uv), axis=1)
    return float(np.sqrt(np.mean(e**2))), float(e.max())


def _cv_camera(views, width, height):
    from mrstereo.camera import Camera
    _, K, D, *_ = cv2.calibrateCamera([v.points_target.astype(np.float32) for v in views],
                                      [v.uv.astype(np.float32) for v in views], (width, height), None, None,
                                      flags=FLAGS)
    return Camera(width=width, height=height, fx=K[0, 0], fy=K[1, 1], cx=K[0, 2], cy=K[1, 2], k1=D.ravel()[0],
                  k2=D.ravel()[1])


def timed(fn, repeats):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return out, statistics.median(times)


def paper_dot_target(seeds):
    from mrstereo.world import default_stereo, render_paper_dot_target
    for width, height in ((320, 240), (640, 480)):
        cam = default_stereo(width, height).left.camera
        dots = render_paper_dot_target(cam, supersample=1)
        uv = dots.points_px + np.random.default_rng(0).normal(0, 0.1, dots.points_px.shape)
        view = CalibrationView(dots.points_target, uv, name="dots")
        print(f"\n[1] paper dot target {width}x{height}, {len(uv)} dots, 0.1 px noise, "
              "GA alone (N=100, pc=0.8, pm=0.1)")
        rms, times = [], []
        for seed in seeds:
            t0 = time.perf_counter()
            r = calibrate_camera(view, width=width, height=height, method="ga", rng=seed)
            times.append(time.perf_counter() - t0)
            rms.append(r.ga_rms_px)
            print(f"  seed {seed}: GA RMS {r.ga_rms_px:.3f} px, {r.generations} generations, {times[-1]:.2f} s, "
                  f"f = {r.camera.fx:.1f} px (true {cam.fx})")
        print(f"  median GA RMS {statistics.median(rms):.3f} px, max {max(rms):.3f} px; median time "
              f"{statistics.median(times):.2f} s")


def _noisy_views(rendered, seed):
    rng = np.random.default_rng(seed)
    return [CalibrationView(v.points_target, v.points_px + rng.normal(0, 0.1, v.points_px.shape)) for v in rendered]


# Issue #3's target: focal length within 0.5 %, principal point within 1 px, distortion field within 0.05 px
# everywhere in the image. The chosen capture: a 25x18 board (10 mm squares), 54 grid views (six passes).
TARGET_CAPTURE = dict(board=(25, 18), spacing_m=0.01, n_views=54)
SHORT_GA = dict(generations=20, stall_generations=20)    # the GA only seeds LM; LM lands on the same camera


def _errors(c, true):
    f_pct = 100 * max(abs(c.fx / true.fx - 1), abs(c.fy / true.fy - 1))
    pp_px = max(abs(c.cx - true.cx), abs(c.cy - true.cy))
    d_rms, d_max = distortion_field_error(c, true)
    return f_pct, pp_px, d_rms, d_max


def _summary(label, rows):
    """rows: (f %, pp px, field RMS, field max[, seconds]) per noise draw."""
    a = np.array(rows)
    ok = (a[:, 3] < 0.05) & (a[:, 0] < 0.5) & (a[:, 1] < 1.0)
    time_text = f"; median time {np.median(a[:, 4]):.1f} s" if a.shape[1] > 4 else ""
    print(f"  {label}: target met in {ok.sum()}/{len(a)} draws; field max median {np.median(a[:, 3]):.3f}, "
          f"90th {np.percentile(a[:, 3], 90):.3f}, worst {a[:, 3].max():.3f} px; field RMS median "
          f"{np.median(a[:, 2]):.3f} px; f err max {a[:, 0].max():.3f} %; pp err max {a[:, 1].max():.2f} px"
          f"{time_text}", flush=True)


def synthetic_multiview(seeds, default_ga_timing=True):
    from mrstereo.calibration import GAConfig
    from mrstereo.world import default_stereo, render_calibration_views
    true = default_stereo(640, 480).left.camera
    print(f"\n[2] synthetic chessboard views 640x480, exact corners + 0.1 px noise, {len(seeds)} noise draws; "
          "distortion field error over the whole image (41x31 grid); target: f < 0.5 %, pp < 1 px, "
          "field max < 0.05 px", flush=True)
    captures = (("9x6 (30 mm), coverage='random', 15 views", dict(n_views=15, coverage="random"), None),
                ("9x6 (30 mm), coverage='grid', 18 views", dict(n_views=18, coverage="grid"), None),
                ("25x18 (10 mm), coverage='grid', 54 views", dict(TARGET_CAPTURE, coverage="grid"),
                 GAConfig(**SHORT_GA)))
    for label, kw, ga_config in captures:
        rendered = render_calibration_views(true, seed=1, supersample=1, **kw)
        n_points = sum(len(v.points_px) for v in rendered)
        ga_text = "default GA" if ga_config is None else f"GA {ga_config.generations} generations"
        print(f"  GA + LM ({ga_text}), {label}, {n_points} points:", flush=True)
        rows, cv_rows = [], []
        for seed in seeds:
            views = _noisy_views(rendered, seed)
            t0 = time.perf_counter()
            r = calibrate_camera(views, width=640, height=480, method="ga+lm", rng=seed, ga_config=ga_config)
            dt = time.perf_counter() - t0
            rows.append((*_errors(r.camera, true), dt))
            cv_rows.append(_errors(_cv_camera(views, 640, 480), true))
            f_pct, pp_px, d_rms, d_max, _ = rows[-1]
            print(f"    noise seed {seed}: f err {f_pct:.3f} %, pp err {pp_px:.2f} px, distortion field err RMS "
                  f"{d_rms:.3f} / max {d_max:.3f} px (cv2.calibrateCamera on the same points: {cv_rows[-1][2]:.3f} / "
                  f"{cv_rows[-1][3]:.3f}); GA {r.ga_rms_px:.3f} -> LM {r.lm_rms_px:.3f} px; {dt:.1f} s", flush=True)
        _summary("GA + LM", rows)
        _summary("cv2    ", cv_rows)
    if default_ga_timing:
        rendered = render_calibration_views(true, seed=1, supersample=1, coverage="grid", **TARGET_CAPTURE)
        t0 = time.perf_counter()
        r = calibrate_camera(_noisy_views(rendered, seeds[0]), width=640, height=480, method="ga+lm", rng=seeds[0])
        print(f"  the 54-view capture with the default GA ({r.generations} generations) + LM: "
              f"{time.perf_counter() - t0:.1f} s, field max {_errors(r.camera, true)[3]:.3f} px", flush=True)
    # Which captures reach the target: cv2.calibrateCamera (= GA + LM, see above) on the same noise draws.
    print("  captures, coverage='grid', cv2.calibrateCamera (CALIB_FIX_K3 | CALIB_ZERO_TANGENT_DIST):", flush=True)
    for board, spacing_m, counts in (((9, 6), 0.03, (18, 45)), ((17, 12), 0.015, (27, 54)),
                                     ((25, 18), 0.01, (27, 36, 45, 54, 63))):
        rendered = render_calibration_views(true, n_views=max(counts), seed=1, supersample=1, coverage="grid",
                                            board=board, spacing_m=spacing_m)
        for n_views in counts:
            rows = [_errors(_cv_camera(_noisy_views(rendered[:n_views], s), 640, 480), true) for s in seeds]
            _summary(f"{board[0]}x{board[1]} ({spacing_m * 1000:.0f} mm), {n_views} views", rows)


def rendered_images(n_views):
    from mrstereo.world import default_stereo, render_calibration_views
    truth = default_stereo(640, 480)
    rendered = render_calibration_views(truth, n_views=n_views, seed=2, supersample=2)
    left, right = [], []
    for v in rendered:
        a, b = detect_chessboard(v.image, v.board), detect_chessboard(v.image_right, v.board)
        if a is None or b is None:
            continue
        if np.dot(a[-1] - a[0], b[-1] - b[0]) < 0:
            b = b[::-1].copy()
        grid = planar_grid(v.board[0], v.board[1], v.spacing_m)
        left.append(CalibrationView(grid, a))
        right.append(CalibrationView(grid, b))
    t0 = time.perf_counter()
    r = calibrate_stereo(left, right, width=640, height=480, method="ga+lm", rng=0)
    dt = time.perf_counter() - t0
    print(f"\n[3] rendered 640x480 chessboard images: board found in {len(left)}/{n_views} pairs; "
          f"stereo GA + LM {dt:.1f} s")
    for side, est, true in (("left", r.stereo.left.camera, truth.left.camera),
                            ("right", r.stereo.right.camera, truth.right.camera)):
        d_rms, d_max = distortion_field_error(est, true)
        cv_rms, cv_max = distortion_field_error(_cv_camera(left if side == "left" else right, 640, 480), true)
        print(f"  {side}: fx err {100 * abs(est.fx / true.fx - 1):.2f} %, cx/cy err {abs(est.cx - true.cx):.2f}/"
              f"{abs(est.cy - true.cy):.2f} px, distortion field err RMS {d_rms:.3f} / max {d_max:.3f} px "
              f"(cv2: {cv_rms:.3f} / {cv_max:.3f})")
    print(f"  baseline {r.baseline_m:.4f} m (true {truth.baseline_m:.4f}); RMS {r.rms_px:.3f} px; rectified "
          f"vertical error {r.vertical_error_px:.3f} px")


def opencv_chessboard_corners(section: int):
    """OpenCV's real stereo set: ``(pairs, size, object points, left corners, right corners)`` as
    cv2 wants them, or None (printed as skipped) without the sample data."""
    try:
        DATA = sample_data.fetch("opencv-stereo-chessboard")   # $MRSTEREO_DATA or the download cache
    except (OSError, ValueError) as exc:
        print(f"\n[{section}] skipped: OpenCV's stereo chessboards not available ({exc})")
        return None
    pairs = chessboard_pairs(expand_glob(str(DATA / "left*.jpg")), expand_glob(str(DATA / "right*.jpg")),
                             (9, 6), 0.025)
    obj = [v.points_target.astype(np.float32) for v in pairs.left]
    il = [v.uv.astype(np.float32) for v in pairs.left]
    ir = [v.uv.astype(np.float32) for v in pairs.right]
    return pairs, pairs.size, obj, il, ir


def real_data(repeats):
    corners = opencv_chessboard_corners(4)
    if corners is None:
        return
    pairs, size, obj, il, ir = corners
    print(f"\n[4] OpenCV stereo set: {len(pairs.left)} pairs (skipped {pairs.skipped}), same corners for both")

    def cv_all():
        r1, K1, D1, *_ = cv2.calibrateCamera(obj, il, size, None, None, flags=FLAGS)
        r2, K2, D2, *_ = cv2.calibrateCamera(obj, ir, size, None, None, flags=FLAGS)
        rs, K1, D1, K2, D2, R, T, *_ = cv2.stereoCalibrate(obj, il, ir, K1, D1, K2, D2, size,
                                                          flags=FLAGS | cv2.CALIB_USE_INTRINSIC_GUESS)
        R1, R2, P1, P2, *_ = cv2.stereoRectify(K1, D1, K2, D2, size, R, T, alpha=0)
        return r1, r2, rs, K1, D1, K2, D2, R1, R2, P1, P2, T

    (r1, r2, rs, K1, D1, K2, D2, R1, R2, P1, P2, T), t_cv = timed(cv_all, repeats)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    cv_vert = np.mean([np.mean(np.abs(
        cv2.undistortPoints(a.reshape(-1, 1, 2), K1, D1, R=R1, P=P1, criteria=crit).reshape(-1, 2)[:, 1]
        - cv2.undistortPoints(b.reshape(-1, 1, 2), K2, D2, R=R2, P=P2, criteria=crit).reshape(-1, 2)[:, 1]))
        for a, b in zip(il, ir)])
    for method in ("ga+lm", "lm"):
        res, t = timed(lambda: calibrate_stereo(pairs.left, pairs.right, width=size[0], height=size[1],
                                                method=method, rng=0), repeats)
        print(f"  {method:5s}: stereo calibration + rectification median {t:.2f} s "
              f"(OpenCV, same pipeline: {t_cv:.2f} s)")
        for side, mono, rms_cv, K in (("left", res.left, r1, None), ("right", res.right, r2, None)):
            Kc = cv2.calibrateCamera(obj, il if side == "left" else ir, size, None, None, flags=FLAGS)[1]
            print(f"    {side}: RMS {mono.rms_px:.4f} px vs cv2 {rms_cv:.4f} (ratio {mono.rms_px / rms_cv:.4f}); "
                  f"fx {mono.camera.fx:.2f} vs {Kc[0, 0]:.2f} ({100 * (mono.camera.fx / Kc[0, 0] - 1):+.3f} %), "
                  f"fy {mono.camera.fy:.2f} vs {Kc[1, 1]:.2f} ({100 * (mono.camera.fy / Kc[1, 1] - 1):+.3f} %)"
                  + (f"; GA alone {mono.ga_rms_px:.3f} px after {mono.generations} gen" if method == "ga+lm" else ""))
        print(f"    joint RMS {res.rms_px:.4f} px vs cv2.stereoCalibrate {rs:.4f}; |T| {res.baseline_m:.5f} vs "
              f"{np.linalg.norm(T):.5f} m; rectified mean |y_l - y_r| {res.vertical_error_px:.4f} px vs "
              f"cv2.stereoRectify {cv_vert:.4f} px")


MODEL_FLAGS = {"k1k2": FLAGS, "plumb_bob": 0, "rational": cv2.CALIB_RATIONAL_MODEL}


def real_models():
    corners = opencv_chessboard_corners(5)
    if corners is None:
        return
    pairs, size, obj, il, ir = corners
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 100, 1e-12)
    print(f"\n[5] every --model, LM, OpenCV stereo set ({len(il)} pairs), same corners")
    for model in ("k1k2", "plumb_bob", "rational", "fisheye"):
        t0 = time.perf_counter()
        res = calibrate_stereo(pairs.left, pairs.right, width=size[0], height=size[1], method="lm", model=model)
        dt = time.perf_counter() - t0
        if model == "fisheye":
            o3 = [o.reshape(1, -1, 3).astype(np.float64) for o in obj]
            l2, r2_ = ([i.reshape(1, -1, 2).astype(np.float64) for i in img] for img in (il, ir))
            fl = cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW
            r1, K1, D1, *_ = cv2.fisheye.calibrate(o3, l2, size, np.eye(3), np.zeros(4), flags=fl, criteria=crit)
            r2, K2, D2, *_ = cv2.fisheye.calibrate(o3, r2_, size, np.eye(3), np.zeros(4), flags=fl, criteria=crit)
            rs, K1, D1, K2, D2, R, T, *_ = cv2.fisheye.stereoCalibrate(
                o3, l2, r2_, K1, D1, K2, D2, size, flags=fl | cv2.CALIB_USE_INTRINSIC_GUESS, criteria=crit)
            R1, R2, P1, P2, _ = cv2.fisheye.stereoRectify(K1, D1, K2, D2, size, R, T, cv2.CALIB_ZERO_DISPARITY)
            dy = np.mean([np.mean(np.abs(
                cv2.fisheye.undistortPoints(a, K1, D1, R=R1, P=P1, criteria=crit)[0, :, 1]
                - cv2.fisheye.undistortPoints(b, K2, D2, R=R2, P=P2, criteria=crit)[0, :, 1]))
                for a, b in zip(l2, r2_)])
        else:
            flags = MODEL_FLAGS[model]
            r1, K1, D1, *_ = cv2.calibrateCamera(obj, il, size, None, None, flags=flags)
            r2, K2, D2, *_ = cv2.calibrateCamera(obj, ir, size, None, None, flags=flags)
            rs, K1, D1, K2, D2, R, T, *_ = cv2.stereoCalibrate(obj, il, ir, K1, D1, K2, D2, size,
                                                              flags=flags | cv2.CALIB_USE_INTRINSIC_GUESS)
            R1, R2, P1, P2, *_ = cv2.stereoRectify(K1, D1, K2, D2, size, R, T, alpha=0)
            dy = np.mean([np.mean(np.abs(
                cv2.undistortPoints(a.reshape(-1, 1, 2), K1, D1, R=R1, P=P1, criteria=crit)[:, 0, 1]
                - cv2.undistortPoints(b.reshape(-1, 1, 2), K2, D2, R=R2, P=P2, criteria=crit)[:, 0, 1]))
                for a, b in zip(il, ir)])
        dy_f = res.vertical_error_px / res.stereo.focal_px          # in radians: independent of the zoom
        print(f"  {model:9s}: left RMS {res.left.rms_px:.4f} vs cv2 {r1:.4f}, right {res.right.rms_px:.4f} vs "
              f"{r2:.4f}; joint RMS {res.rms_px:.4f} vs cv2.stereoCalibrate {rs:.4f} "
              f"({100 * (res.rms_px / rs - 1):+.2f} %); rectified mean |dy| {res.vertical_error_px:.4f} vs "
              f"cv2.stereoRectify {dy:.4f} px ({100 * (res.vertical_error_px / dy - 1):+.2f} %) at rectified focal "
              f"lengths {res.stereo.focal_px:.1f} vs {P1[0, 0]:.1f} px, |dy| / f {100 * (dy_f / (dy / P1[0, 0]) - 1):+.2f} "
              f"%; {dt:.1f} s")
    try:
        calibrate_stereo(pairs.right, pairs.left, width=size[0], height=size[1], method="lm")
        print("  swapped: NOT refused")
    except ValueError as exc:
        print(f"  swapped (right images as left): {exc}")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="fewer seeds and repeats")
    ap.add_argument("--section", type=int, choices=range(1, 6), help="run only this section")
    args = ap.parse_args()
    seeds = [0, 1] if args.quick else [0, 1, 2, 3, 4]
    repeats = 1 if args.quick else 2
    run = (lambda k: args.section in (None, k))
    if run(1):
        paper_dot_target(seeds)
    if run(2):
        synthetic_multiview([0, 1, 2] if args.quick else list(range(20)), default_ga_timing=not args.quick)
    if run(3):
        rendered_images(12)
    if run(4):
        real_data(repeats)
    if run(5):
        real_models()


if __name__ == "__main__":
    main()
