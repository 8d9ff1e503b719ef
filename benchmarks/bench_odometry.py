"""Visual odometry and drift-robust mapping on real and synthetic sequences (docs/odometry.md).

    python benchmarks/bench_odometry.py --suite [--suite-only TEXT] [--set NAME=VALUE ...] [--data DIR]
                                                                 # every set in one table, tuning sets marked
    python benchmarks/bench_odometry.py --learner [--suite-only TEXT] [--data DIR]
                                                                 # what the disparity correction reads
    python benchmarks/bench_odometry.py --kitti [PATH] [--kitti-every 2 3]   # KITTI odometry 06 and 01
    python benchmarks/bench_odometry.py --held-out [PATH]        # a KITTI raw drive (the shared sample)
    python benchmarks/bench_odometry.py --kitti-scale [PATH ...] # where 01's and 06's error comes from
    python benchmarks/bench_odometry.py --street [--street-seeds 100 101 102]
    python benchmarks/bench_odometry.py [--seeds 0 1 2] [--frames 91] [--data DIR]
    python benchmarks/bench_odometry.py --vo-only [--random-seeds 0 1 2]
    python benchmarks/bench_odometry.py --speed [--speed-frames 30]
    python benchmarks/bench_odometry.py --maps-randomized 100-119     # maps with drifted odometry

Every odometry row gives mrstereo's visual odometry beside a frame-to-frame baseline assembled
from OpenCV in the same run (``baseline_odometry``: ORB features of consecutive left images
matched by Hamming distance with a ratio test, their depth from ``cv2.StereoSGBM``, the motion by
``cv2.solvePnPRansac``; what a user writes in an afternoon), with the time per frame of both.

``--kitti``: the real KITTI odometry sequence (``mrstereo.recordings.kitti``; default
``$MRSTEREO_DATA/kitti_odometry_06``): the whole sample and its halves. ``--street``: the street
world (``mrstereo synth --path street``) at 0.5, 1.0 and 1.5 m per frame at 10 Hz, from a
standstill, turning up to 3 degrees per frame, 60 frames, on seeds not used to choose the
defaults (those were chosen on street seeds 0-2 and the corridor sequences).

Per seed: an S-curve sequence (front view, 0.1 m steps, 320x240) is rendered with drifted
odometry (3 % scale error, 2 deg/m heading drift) beside the true poses (``mrstereo synth
--path s-curve --step 0.1 --odometry-noise 0.03,2``). Printed:

- visual odometry against the true poses: ATE RMSE (SE(3)-aligned, as ``evo_ape -a``, and
  unaligned from the common start), the estimated path's length over the true one (``path x``:
  its scale), RPE per metre, end-point error, in % of the distance;
- occupancy-map precision / recall against the ground-truth map with the true poses, the drifted
  odometry, ``map --align`` (the drifted odometry fused with visual odometry) and
  ``map --odometry visual``. The frames are matched once; each run re-poses their robot-frame
  points (what ``mrstereo map`` does with the same poses) and fuses them in order.

Then visual odometry alone on the straight ``front`` path (seed 0) and on randomized worlds
(``mrstereo synth --randomize --path front``: the world's own path, 6 m, 61 frames) of
``--random-seeds``. ``--vo-only`` skips the maps. ``--maps-randomized SEEDS``: the maps of
randomized worlds with the drifted odometry (``map --align`` and ``--odometry visual`` against the
true poses; mrstereo's settings are chosen on seeds 0-9, reported on 100-119).

``--suite``: mrstereo's visual odometry alone on every evaluation set (KITTI 06 and 01 with their halves and
every 2nd and 3rd frame, the KITTI raw sample against both OXTS truths, street seeds 210-219 at 1.0 and 2.7 m
per frame and 230-239 at 1.0 m turning 8 deg and 2.5 m turning 4 deg per frame), one line per set, the
tuning sets (``SUITE_TUNING``) marked ``*``.

``--speed``: the odometry stage alone at 640x480 on one thread (CPU time of the thread, and
wall time), with the depth from the stereo search and from a given disparity map (the mapping
pipeline has one); the KITTI sample gives the time at 1226x370.
"""
from __future__ import annotations

import argparse
import math
import os
import time
from dataclasses import replace
from pathlib import Path

import cv2
import numpy as np

from mrstereo.camera import CameraMount
from mrstereo.mapping import read_ros_map
from mrstereo.mapping.fusion import fuse
from mrstereo.mapping.metrics import map_metrics
from mrstereo.odometry.fusion import fuse_odometry
from mrstereo.odometry.trajectory import path_length_m, trajectory_metrics
from mrstereo.pipeline.run import PipelineConfig, build_map
from mrstereo.recordings.layouts import read_recording
from mrstereo.recordings.manifest import frame_pair, read_manifest
from mrstereo.transforms import T_from_planar, T_from_rvec_t, rotation_angle_rad, transform_points
from mrstereo.world.dataset import write_synthetic_dataset

NOISE = (0.03, math.radians(2.0))


def baseline_odometry(pairs, stereo, T_world_from_cam0) -> tuple[np.ndarray, np.ndarray, int]:
    """Frame-to-frame stereo odometry from OpenCV parts: ORB + SGBM depth + PnP-RANSAC.

    Returns the camera poses (N, 4, 4), the CPU time per frame and the frames it could not solve
    (they keep the previous motion).
    """
    fb = stereo.focal_px * stereo.baseline_m
    n_disp = int(min(128, max(16, 16 * math.ceil(fb / 1.0 / 16))))           # depths from 1 m
    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=n_disp, blockSize=5, P1=8 * 25, P2=32 * 25,
                                 uniquenessRatio=10, speckleWindowSize=100, speckleRange=2,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    orb = cv2.ORB_create(nfeatures=2000)
    matcher = cv2.BFMatcher(cv2.NORM_HAMMING)
    P = stereo.left.P
    K = np.array([[P[0, 0], 0, P[0, 2]], [0, P[1, 1], P[1, 2]], [0, 0, 1.0]])
    poses, times, failed = [np.asarray(T_world_from_cam0, float)], [], 0
    step = np.eye(4)
    prev = None
    for left, right in pairs:
        t0 = time.thread_time()
        left = left if left.ndim == 2 else cv2.cvtColor(left, cv2.COLOR_BGR2GRAY)
        right = right if right.ndim == 2 else cv2.cvtColor(right, cv2.COLOR_BGR2GRAY)
        kp, des = orb.detectAndCompute(left, None)
        if prev is not None:
            pkp, pdes, pdisp = prev
            ok = False
            if des is not None and pdes is not None and len(kp) >= 8:
                good = [m[0] for m in matcher.knnMatch(pdes, des, k=2)
                        if len(m) == 2 and m[0].distance < 0.8 * m[1].distance]
                if len(good) >= 8:
                    uv0 = np.float32([pkp[m.queryIdx].pt for m in good])
                    uv1 = np.float32([kp[m.trainIdx].pt for m in good])
                    d = pdisp[np.clip(np.rint(uv0[:, 1]).astype(int), 0, left.shape[0] - 1),
                              np.clip(np.rint(uv0[:, 0]).astype(int), 0, left.shape[1] - 1)]
                    use = d > 0.5
                    z = fb / np.maximum(d[use], 1e-6)
                    X = np.column_stack([(uv0[use, 0] - K[0, 2]) * z / K[0, 0],
                                         (uv0[use, 1] - K[1, 2]) * z / K[1, 1], z])
                    if len(X) >= 6:
                        found, rvec, tvec, inl = cv2.solvePnPRansac(X, uv1[use], K, None, iterationsCount=200,
                                                                     reprojectionError=1.5, confidence=0.999)
                        if found and inl is not None and len(inl) >= 6:
                            step = np.linalg.inv(T_from_rvec_t(rvec, tvec))         # T_prev_from_cur
                            ok = True
            failed += not ok
            poses.append(poses[-1] @ step)
        disp = sgbm.compute(left, right).astype(np.float32) / 16.0
        prev = (kp, des, disp)
        times.append(time.thread_time() - t0)
    return np.stack(poses), np.array(times), failed


def _odometry_pairs(manifest):
    out = []
    for f in manifest.frames:
        left, right, rectified = frame_pair(f)
        if not rectified and not manifest.calibration.is_rectified:
            left, right = manifest.calibration.rectify(left, right)
        out.append((left, right))
    return out


def compare(manifest, frames: slice = slice(None)) -> dict:
    """mrstereo's visual odometry and the frame-to-frame baseline on a recording, against its truth."""
    records = manifest.frames[frames]
    pairs = _odometry_pairs(replace(manifest, frames=records))
    truth = np.stack([f.T_world_from_base_true if f.true_pose is not None else f.T_world_from_base for f in records])
    mount = manifest.mount or CameraMount.from_xyz_rpy((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
    mounts = np.stack([mount.T_base_from_rectified(manifest.calibration.left.R, f.pan_rad) for f in records])
    stamps = [f.stamp_s for f in records]
    return compare_pairs(pairs, manifest.calibration, truth, mounts, None if None in stamps else stamps)


def compare_pairs(pairs, stereo, truth, mounts, stamps, config=None) -> dict:
    """mrstereo's visual odometry (``config``: the defaults) and the frame-to-frame baseline on
    rectified pairs, against the true base poses."""
    from mrstereo.odometry import OdometryConfig, visual_odometry

    visual_odometry(pairs[:4], stereo, T_base_from_cam=mounts[:4])          # numba's cached kernels loaded
    t0 = time.perf_counter()
    vo = visual_odometry(pairs, stereo, T_base_from_cam=mounts, T_world_from_base0=truth[0], stamps_s=stamps,
                         config=config or OdometryConfig())
    wall = (time.perf_counter() - t0) / len(pairs)
    T_cam, base_times, failed = baseline_odometry(pairs, stereo, truth[0] @ mounts[0])
    T_base = np.stack([T @ np.linalg.inv(M) for T, M in zip(T_cam, mounts)])
    return {"vo": trajectory_metrics(vo.T_world_from_base, truth), "vo_lost": vo.n_lost,
            "vo_path_m": path_length_m(vo.T_world_from_base),
            "vo_ms": 1000 * float(np.mean(vo.time_s)), "vo_ms_median": 1000 * float(np.median(vo.time_s)),
            "vo_wall_ms": 1000 * wall, "keyframes": vo.status.count("keyframe"),
            "vo_online": trajectory_metrics(vo.T_world_from_base_online, truth),
            "base": trajectory_metrics(T_base, truth), "base_failed": failed, "base_poses": T_base,
            "base_ms": 1000 * float(np.mean(base_times)), "size": stereo.size, "result": vo}


def _compare_line(label: str, r: dict) -> str:
    v, b = r["vo"], r["base"]
    return (f"{label}: {v.path_length_m:.1f} m, {v.n_poses} frames {r['size'][0]}x{r['size'][1]} | mrstereo: ATE "
            f"{v.ate_percent:.2f} % ({100 * v.ate_rmse_m:.1f} cm; online {r['vo_online'].ate_percent:.2f} %; path "
            f"x{r['vo_path_m'] / v.path_length_m:.3f}), "
            f"end {v.end_point_percent:.2f} %, RPE {100 * v.rpe_translation_per_m:.2f} % "
            f"{v.rpe_rotation_deg_per_m:.3f} deg/m, per frame {v.rpe_frame_percent:.1f} % of the step "
            f"{v.rpe_rotation_deg_per_frame:.3f} deg, lost {r['vo_lost']}, {r['keyframes']} keyframes, "
            f"{r['vo_ms']:.1f} ms/frame CPU (median {r['vo_ms_median']:.1f}) | baseline ORB+SGBM+PnP: ATE "
            f"{b.ate_percent:.2f} %, end {b.end_point_percent:.2f} %, RPE {100 * b.rpe_translation_per_m:.2f} % "
            f"{b.rpe_rotation_deg_per_m:.3f} deg/m, per frame {b.rpe_frame_percent:.1f} % {b.rpe_rotation_deg_per_frame:.3f} deg, failed {r['base_failed']}, {r['base_ms']:.1f} ms/frame CPU")


def kitti(path: Path, every: list[int] = ()) -> None:
    """KITTI 06 (the sequence the defaults were chosen on: all and halves) and 01 (a highway curve); with
    ``every``, also every n-th frame from frames 0 and 1 (the real stamps: n times the speed per frame)."""
    paths = [path] if path.name != "kitti_odometry_06" else [path, path.with_name("kitti_odometry_01")]
    for root in paths:
        if not root.is_dir():
            print(f"{root}: not found, skipped")
            continue
        manifest = read_recording(root)
        n = len(manifest.frames)
        print(f"KITTI odometry {manifest.root}: {n} frames")
        runs = [(f"frames 0-{n - 1}", slice(None)), (f"frames 0-{n // 2}", slice(0, n // 2 + 1)),
                (f"frames {n // 2}-{n - 1}", slice(n // 2, None))]
        runs += [(f"every {k}th frame from {start}", slice(start, None, k)) for k in every for start in (0, 1)]
        for label, frames in runs:
            r = compare(manifest, frames)
            print(_compare_line(label, r))
            lost = np.flatnonzero(~r["result"].tracked)
            if len(lost):
                print(f"    lost frames: {lost.tolist()}")


def _disparity_fit(manifest, stereo_d, gap: int = 2):
    """The affine disparity error ``a + b (v - cy) / 100 + c (u - cx) / 100`` [px] (and ``a`` alone) that
    best explains the true motion: keyframe-like corners with their stereo disparity, tracked ``gap``
    frames on, projected with the true relative pose (truncated squared reprojection errors)."""
    from scipy.optimize import minimize

    st = manifest.calibration
    K = np.array([[st.left.P[0, 0], 0, st.left.P[0, 2]], [0, st.left.P[1, 1], st.left.P[1, 2]], [0, 0, 1.0]])
    fb = st.focal_px * st.baseline_m
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.003)
    pairs = _odometry_pairs(manifest)
    truth = [f.T_world_from_base_true @ CameraMount.from_xyz_rpy((0, 0, 0), (0, 0, 0)).T_base_from_rectified(
        st.left.R) for f in manifest.frames]
    data = []
    for a in range(0, len(pairs) - gap, 2):
        uv, d = stereo_d(*pairs[a])
        cur, ok = uv.copy(), np.isfinite(d)
        for j in range(a + 1, a + gap + 1):
            nxt, found, _ = cv2.calcOpticalFlowPyrLK(pairs[j - 1][0], pairs[j][0], cur.reshape(-1, 1, 2), None,
                                                     winSize=(11, 11), maxLevel=3, criteria=crit)
            ok &= found.ravel() == 1
            cur = nxt.reshape(-1, 2)
        data.append((uv[ok], d[ok], cur[ok], np.linalg.inv(truth[a + gap]) @ truth[a]))

    def cost(p):
        total = 0.0
        for uv, d, cur, T in data:
            z = fb / (d + p[0] + sum(q * (uv[:, k] - K[k, 2]) / 100.0 for k, q in zip((1, 0), p[1:])))
            X = np.column_stack([(uv[:, 0] - K[0, 2]) * z / K[0, 0], (uv[:, 1] - K[1, 2]) * z / K[1, 1], z])
            Xb = X @ T[:3, :3].T + T[:3, 3]
            err2 = np.sum((Xb[:, :2] / Xb[:, 2:3] * [K[0, 0], K[1, 1]] + K[:2, 2] - cur) ** 2, axis=1)
            total += np.minimum(np.where((z > 0) & (Xb[:, 2] > 0), err2, 9.0), 4.0).sum()
        return total

    return [minimize(cost, np.r_[0.5, np.zeros(n)], method="Nelder-Mead") for n in (0, 2)]


def kitti_scale(path: Path) -> None:
    """Where a KITTI sequence's error comes from: the path's length, the learnt disparity offset, the
    tracker's stereo disparities against ``cv2.StereoSGBM``'s, the disparity error the true motion
    asks for, and the stereo matches' row error across the image (docs/odometry.md, Measured)."""
    from mrstereo.odometry import OdometryConfig, StereoOdometry

    manifest = read_recording(path)
    r = compare(manifest)
    vo, truth_len = r["result"], r["vo"].path_length_m
    print(f"{manifest.root}: ATE {r['vo'].ate_percent:.2f} %, path {r['vo_path_m']:.2f} m for {truth_len:.2f} m "
          f"(x{r['vo_path_m'] / truth_len:.3f})")
    P, Q = vo.T_world_from_base, np.stack([f.T_world_from_base_true for f in manifest.frames])
    p, q = P[:, :3, 3] - P[:, :3, 3].mean(0), Q[:, :3, 3] - Q[:, :3, 3].mean(0)
    U, S, Vt = np.linalg.svd(q.T @ p / len(p))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U) * np.linalg.det(Vt))])
    scale = np.trace(np.diag(S) @ D) / np.mean(np.sum(p * p, axis=1))               # Umeyama with scale
    sim3 = np.sqrt(np.mean(np.sum((scale * p @ (U @ D @ Vt).T - q) ** 2, axis=1)))
    E = np.linalg.inv(np.linalg.inv(Q[0]) @ Q[-1]) @ np.linalg.inv(P[0]) @ P[-1]
    print(f"  with scale (Sim(3)) aligned: ATE {100 * sim3 / truth_len:.2f} % (scale {scale:.3f}); rotation drift "
          f"over the run {math.degrees(rotation_angle_rad(E[:3, :3])):.2f} deg")
    tracker = StereoOdometry(manifest.calibration, config=OdometryConfig())
    mounts = CameraMount.from_xyz_rpy((0, 0, 0), (0, 0, 0)).T_base_from_rectified(manifest.calibration.left.R)
    for left, right in _odometry_pairs(manifest):
        tracker.step(left, right, T_base_from_cam=mounts)
    a, b, c = tracker._correction_mean
    print(f"  learnt disparity correction {a:+.2f} {b:+.3f} (v - cy)/100 {c:+.3f} (u - cx)/100 px (used "
          f"{tracker._offset_px:+.2f} {tracker._slopes_px[0]:+.3f} {tracker._slopes_px[1]:+.3f})")

    def stereo_d(left, right):
        uv = tracker._corners(left, 300, np.empty((0, 2), np.float32))
        return uv, uv[:, 0] - tracker._right_columns(left, right, None, uv, np.full(len(uv), np.nan))

    sgbm = cv2.StereoSGBM_create(minDisparity=0, numDisparities=128, blockSize=5, P1=200, P2=800, uniquenessRatio=10,
                                 mode=cv2.STEREO_SGBM_MODE_SGBM_3WAY)
    diff, rows, disps = [], [], []
    for left, right in _odometry_pairs(manifest)[::5]:
        uv, d = stereo_d(left, right)
        ds = sgbm.compute(left, right).astype(np.float32)[np.rint(uv[:, 1]).astype(int), np.rint(uv[:, 0]).astype(int)]
        ok = np.isfinite(d) & (ds > 0)
        diff.append(ds[ok] / 16.0 - d[ok])
        disps.append(d[ok])
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 30, 0.003)
        q, found, _ = cv2.calcOpticalFlowPyrLK(left, right, uv.reshape(-1, 1, 2), None, winSize=(21, 21), maxLevel=4,
                                               criteria=crit)
        back, found2, _ = cv2.calcOpticalFlowPyrLK(right, left, q, None, winSize=(21, 21), maxLevel=4, criteria=crit)
        q = q.reshape(-1, 2)
        good = (found.ravel() == 1) & (found2.ravel() == 1) & (np.linalg.norm(back.reshape(-1, 2) - uv, axis=1) < 0.2)
        rows.append(np.column_stack([uv[good], q[good, 1] - uv[good, 1]]))
    print(f"  cv2.StereoSGBM minus the tracker's disparity at the corners: median "
          f"{np.median(np.concatenate(diff)):+.3f} px"
          f" (the tracker's median disparity {np.median(np.concatenate(disps)):.1f} px)")
    rows = np.concatenate(rows)
    cx, cy = manifest.calibration.left.P[0, 2], manifest.calibration.left.P[1, 2]
    A = np.column_stack([np.ones(len(rows)), (rows[:, 0] - cx) / 100, (rows[:, 1] - cy) / 100])
    coef = np.linalg.lstsq(A, rows[:, 2], rcond=None)[0]
    print(f"  stereo row error dy = {coef[0]:+.2f} {coef[1]:+.3f} (u - cx)/100 {coef[2]:+.3f} (v - cy)/100 px")
    offset, affine = _disparity_fit(manifest, stereo_d)
    print(f"  with the true motion: offset {offset.x[0]:+.2f} px; affine {affine.x[0]:+.2f} {affine.x[1]:+.3f} "
          f"(v - cy)/100 {affine.x[2]:+.3f} (u - cx)/100 px, cost {affine.fun / offset.fun:.2f} of the offset's")


def kitti_raw(path: Path) -> None:
    """A KITTI raw drive read by ``mrstereo.recordings.kitti_raw`` (the library's reader): against its truth
    (the OXTS positions at the images' stamps) and against the OXTS records' velocities integrated over
    the same stamps (the attitudes the same): the two truths' own difference is the truth's noise."""
    from mrstereo.recordings.kitti_raw import OXTS_HEIGHT_M, _oxts_records, oxts_velocity_positions

    manifest = read_recording(path)
    r = compare(manifest)
    print(f"KITTI raw {manifest.root.name} (held out; the library's reader, truth from OXTS):")
    print(_compare_line(f"frames 0-{len(manifest.frames) - 1}", r))
    for note in manifest.notes:
        print(f"    {note}")
    records = _oxts_records(manifest.root, [f.left_rect.stem for f in manifest.frames])
    B = T_from_planar(0.0, 0.0, 0.0)
    B[2, 3] = OXTS_HEIGHT_M                                              # T_base_from_imu
    truth = np.stack([f.T_world_from_base_true for f in manifest.frames])
    T_imu = np.linalg.inv(B) @ truth @ B
    T_imu[:, :3, 3] = oxts_velocity_positions(records, manifest.stamps_s)
    by_velocity = B @ T_imu @ np.linalg.inv(B)
    M = manifest.mount.T_base_from_rectified(manifest.calibration.left.R)
    tracks = {"mrstereo": r["result"].T_world_from_base, "baseline": r["base_poses"], "OXTS positions": truth,
              "OXTS velocities": by_velocity}
    print("    per step, the left camera's motion: length [m], angle of its direction off the optical axis "
          "(left +) [deg], rotation about the camera's y (yaw, left +) and x (pitch, down +) [deg]")
    for name, T in tracks.items():
        cam = T @ M
        rows = []
        for a, b in zip(cam[:-1], cam[1:]):
            step = np.linalg.inv(a) @ b
            t, rvec = step[:3, 3], cv2.Rodrigues(step[:3, :3])[0].ravel()
            rows.append(f"{np.linalg.norm(t):.3f} {math.degrees(math.atan2(-t[0], t[2])):+.1f} "
                        f"{math.degrees(-rvec[1]):+.2f} {math.degrees(rvec[0]):+.2f}")
        print(f"    {name:16s} " + " | ".join(rows))
    for name, T in (("mrstereo", r["result"].T_world_from_base), ("baseline", r["base_poses"]), ("OXTS positions", truth)):
        m = trajectory_metrics(T, by_velocity)
        print(f"    {name} against the OXTS velocities integrated ({m.path_length_m:.3f} m): ATE {m.ate_percent:.2f} % "
              f"({100 * m.ate_rmse_m:.1f} cm), per frame {100 * m.rpe_translation_per_frame_m:.2f} cm "
              f"({m.rpe_frame_percent:.1f} % of the step) {m.rpe_rotation_deg_per_frame:.3f} deg, end "
              f"{100 * m.end_point_error_m:.1f} cm")
    # can the truth decide the scale? the same drive with the rig's disparity moved by a px (the right principal
    # point, as the learnt correction moves it; the learner is off), against both truths
    from mrstereo.odometry import OdometryConfig, visual_odometry

    stereo, pairs = manifest.calibration, _odometry_pairs(manifest)
    mounts = np.stack([M] * len(pairs))
    for a in (0.0, 0.5, 1.0, 1.35):
        P = stereo.right.P.copy()
        P[0, 2] += a
        moved = replace(stereo, right=replace(stereo.right, P=P))
        vo = visual_odometry(pairs, moved, T_base_from_cam=mounts, T_world_from_base0=truth[0],
                             stamps_s=manifest.stamps_s, config=OdometryConfig(calibrate_disparity_offset=False))
        on_p, on_v = trajectory_metrics(vo.T_world_from_base, truth), trajectory_metrics(vo.T_world_from_base, by_velocity)
        print(f"    disparity {a:+.2f} px: path {path_length_m(vo.T_world_from_base):.3f} m (OXTS positions "
              f"{on_p.path_length_m:.3f}, velocities {on_v.path_length_m:.3f}); ATE {on_p.ate_percent:.2f} % against the "
              f"positions, {on_v.ate_percent:.2f} % against the velocities")


SUITE_TUNING = ("KITTI 06 0-50", "street 210-219")
"""The sets the settings are chosen on (``--suite`` marks them); every other set is reported only."""


def _suite_sets(data: Path, street_root: Path, only: str | None = None):
    """``(name, manifest, frames, truth)`` of every set of ``--suite``: KITTI 06 and 01 (frames 0-50, the halves,
    every 2nd and 3rd frame from 0 and 1), the KITTI raw sample (against the OXTS positions and the OXTS
    velocities integrated), the street world seeds 210-219 at 1.0 and 2.7 m/frame (3 deg/frame) and seeds
    230-239 at 1.0 m/frame turning up to 8 deg/frame and at 2.5 m/frame up to 4 deg/frame; with ``only``, the
    sets whose name holds it."""
    from mrstereo.recordings.kitti_raw import OXTS_HEIGHT_M, _oxts_records, oxts_velocity_positions

    for seq in ("06", "01"):
        root = data / f"kitti_odometry_{seq}"
        if only and only not in f"KITTI {seq}":
            continue
        if not root.is_dir():
            print(f"{root}: not found, skipped")
            continue
        manifest = read_recording(root)
        n = len(manifest.frames)
        yield f"KITTI {seq} 0-{n - 1}", manifest, slice(None), None
        yield f"KITTI {seq} 0-{n // 2}", manifest, slice(0, n // 2 + 1), None
        yield f"KITTI {seq} {n // 2}-{n - 1}", manifest, slice(n // 2, None), None
        for k in (2, 3):
            for start in (0, 1):
                yield f"KITTI {seq} every {k}th from {start}", manifest, slice(start, None, k), None
    raw = data / "kitti_raw_sample" / "2011_09_26"
    if raw.is_dir() and (not only or only in "KITTI raw"):
        manifest = read_recording(raw)
        yield "KITTI raw 0005, OXTS positions", manifest, slice(None), None
        records = _oxts_records(manifest.root, [f.left_rect.stem for f in manifest.frames])
        B = np.eye(4)
        B[2, 3] = OXTS_HEIGHT_M
        truth = np.stack([f.T_world_from_base_true for f in manifest.frames])
        T_imu = np.linalg.inv(B) @ truth @ B
        T_imu[:, :3, 3] = oxts_velocity_positions(records, manifest.stamps_s)
        yield "KITTI raw 0005, OXTS velocities", manifest, slice(None), B @ T_imu @ np.linalg.inv(B)
    for seeds, step, turn in ((range(210, 220), 1.0, 3.0), (range(210, 220), 2.7, 3.0), (range(230, 240), 1.0, 8.0),
                              (range(230, 240), 2.5, 4.0)):
        label = f"street {seeds[0]}-{seeds[-1]}" + ("" if turn == 3.0 else f", {turn:g} deg") + f", {step} m"
        if only and only not in label:
            continue
        for seed in seeds:
            out = street_root / f"street-seed{seed}-step{step}{'' if turn == 3.0 else f'-turn{turn:g}'}-60"
            if not (out / "manifest.yaml").is_file():
                write_synthetic_dataset(out, seed=seed, n_frames=60, path="street", step_m=step, progress=False,
                                        turn_rad_per_frame=math.radians(turn))
            yield f"{label}|{seed}", read_manifest(out), slice(None), None


def suite(data: Path, street_root: Path, config=None, only: str | None = None) -> None:
    """mrstereo's visual odometry (``config``: the defaults) on every set of :func:`_suite_sets`, one line each
    (the street seeds summed up per set: ATE mean and largest, lost frames); the tuning sets marked ``*``."""
    from mrstereo.odometry import OdometryConfig, visual_odometry

    config = config or OdometryConfig()
    groups: dict[str, list] = {}
    for name, manifest, frames, truth in _suite_sets(data, street_root, only):
        records = manifest.frames[frames]
        pairs = _odometry_pairs(replace(manifest, frames=records))
        if truth is None:
            truth = np.stack([f.T_world_from_base_true if f.true_pose is not None else f.T_world_from_base
                              for f in records])
        mount = manifest.mount or CameraMount.from_xyz_rpy((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        mounts = np.stack([mount.T_base_from_rectified(manifest.calibration.left.R, f.pan_rad) for f in records])
        stamps = [f.stamp_s for f in records]
        vo = visual_odometry(pairs, manifest.calibration, T_base_from_cam=mounts, T_world_from_base0=truth[0],
                             stamps_s=None if None in stamps else stamps, config=config)
        m = trajectory_metrics(vo.T_world_from_base, truth)
        group, _, seed = name.partition("|")
        groups.setdefault(group, []).append((seed, m, vo))
        if not seed:
            lost = np.flatnonzero(~vo.tracked).tolist()
            mark = "*" if group in SUITE_TUNING else " "
            print(f"{mark} {group:34s} ATE {m.ate_percent:5.2f} % ({100 * m.ate_rmse_m:5.1f} cm of {m.path_length_m:5.1f} m)"
                  f"  path x{path_length_m(vo.T_world_from_base) / m.path_length_m:.3f}  lost {len(lost)}"
                  + (f" {lost}" if lost else ""), flush=True)
    for group, rows in groups.items():
        if rows[0][0]:
            ate = np.array([r[1].ate_percent for r in rows])
            lost = {r[0]: np.flatnonzero(~r[2].tracked).tolist() for r in rows if r[2].n_lost}
            mark = "*" if group in SUITE_TUNING else " "
            print(f"{mark} {group:34s} ATE mean {ate.mean():.2f} %, max {ate.max():.2f} % (seed "
                  f"{rows[int(ate.argmax())][0]}); " + " ".join(f"{v:.2f}" for v in ate)
                  + f"; lost {sum(len(v) for v in lost.values())}" + (f" {lost}" if lost else ""), flush=True)


def learner(street_root: Path, only: str | None = None) -> None:
    """The disparity correction's offset on the street sets of ``--suite`` (rigs whose true offset is 0 px):
    per keyframe pair its estimate as the tracker makes it, again with the pair's tracks replaced by the true
    image of each keyframe feature (its true depth from the rendered disparity, the true poses), and with the
    keyframe's stereo matches replaced by the rendered disparity, with both, and with both and 0.3 px of Gaussian
    noise added to the disparities (seed 0); per sequence the means over its pairs and the
    offset the run ends with. The tracker itself runs unchanged: each variant is solved from the tracker's state
    before the pair and the state restored."""
    from mrstereo.io.images import read_pfm
    from mrstereo.odometry import tracker as tracker_module
    from mrstereo.odometry import visual_odometry

    Odometry = tracker_module.StereoOdometry
    learn = Odometry._learn_offset
    state = ("_correction_sum", "_correction_info", "_correction_mean", "_offset_px", "_slopes_px")

    def pair_offset(self, kf, tracked, T_world_from_cam) -> float:
        saved = [np.copy(getattr(self, k)) for k in state] + [self._map.cx_right_px]
        info0 = self._correction_info.copy()
        learn(self, kf, tracked, T_world_from_cam)
        dH = self._correction_info - info0
        est = np.linalg.solve(dH, self._correction_sum - saved[0])[0] if np.abs(dH).sum() else np.nan
        for k, v in zip(state, saved):
            setattr(self, k, v if k != "_offset_px" else float(v))
        self._map.cx_right_px = saved[-1]
        return est

    def instrumented(self, kf, tracked, T_world_from_cam):
        ids, uv_now = tracked
        order = np.argsort(kf.landmark)
        j = order[np.searchsorted(kf.landmark[order], ids)]
        uv = kf.uv[j].astype(np.float64)
        gt = run["gt"][kf.frame]
        col, row = (np.clip(np.rint(uv[:, i]).astype(int), 0, gt.shape[1 - i] - 1) for i in (0, 1))
        near = np.stack([gt[np.clip(row + a, 0, gt.shape[0] - 1), np.clip(col + b, 0, gt.shape[1] - 1)]
                         for a in (-1, 0, 1) for b in (-1, 0, 1)])
        d_true = np.where(np.ptp(near, axis=0) < 0.5, gt[row, col], np.nan)     # off depth edges only
        points = self._backproject(uv, d_true, 0.0)
        T_now_from_key = np.linalg.inv(run["cam"][self._n_frames]) @ run["cam"][kf.frame]
        X = transform_points(T_now_from_key, points)
        uv_true = X[:, :2] / X[:, 2:3] * np.diag(self._K)[:2] + self._K[:2, 2]
        ok = np.isfinite(uv_true).all(axis=1)
        u_right = kf.u_right.copy()
        u_right[j] = np.where(ok & np.isfinite(kf.u_right[j]), uv[:, 0] - d_true
                              + self._disparity_slopes(uv, kf.disparity_slopes_px), np.nan)
        tracks_true = (ids, np.where(ok[:, None], uv_true, uv_now).astype(np.float32))
        noisy = u_right.copy()
        noisy[j] -= 0.3 * run["rng"].standard_normal(len(j))
        run["pairs"].append((pair_offset(self, kf, tracked, T_world_from_cam),
                             pair_offset(self, kf, tracks_true, T_world_from_cam),
                             pair_offset(self, replace(kf, u_right=u_right), tracked, T_world_from_cam),
                             pair_offset(self, replace(kf, u_right=u_right), tracks_true, T_world_from_cam),
                             pair_offset(self, replace(kf, u_right=noisy), tracks_true, T_world_from_cam)))
        learn(self, kf, tracked, T_world_from_cam)
        run["offset"] = float(self._correction_mean[0])

    print("learnt disparity offset on rigs with none (px): the run's own; per keyframe pair (mean): as tracked,"
          " the tracks true, the stereo true, both, both with N(0, 0.3 px) added to the disparities")
    groups: dict[str, list] = {}
    Odometry._learn_offset = instrumented
    try:
        for name, manifest, _, _ in _suite_sets(Path("."), street_root, only or "street"):
            records = manifest.frames
            truth = np.stack([f.T_world_from_base_true if f.true_pose is not None else f.T_world_from_base
                              for f in records])
            mounts = np.stack([manifest.mount.T_base_from_rectified(manifest.calibration.left.R, f.pan_rad)
                               for f in records])
            run = {"gt": [read_pfm(f.gt_disparity) for f in records], "cam": truth @ mounts, "pairs": [], "offset": 0.0,
                   "rng": np.random.default_rng(0)}
            visual_odometry(_odometry_pairs(manifest), manifest.calibration, T_base_from_cam=mounts,
                            T_world_from_base0=truth[0], stamps_s=[f.stamp_s for f in records])
            pairs = np.nanmean(np.array(run["pairs"]), axis=0)
            groups.setdefault(name.partition("|")[0], []).append((run["offset"], *pairs))
            print(f"  {name.replace('|', ', seed '):40s} run {run['offset']:+.3f}   pairs {pairs[0]:+.3f}  "
                  f"tracks true {pairs[1]:+.3f}  stereo true {pairs[2]:+.3f}  both {pairs[3]:+.3f}  "
                  f"both, the disparities 0.3 px noisy {pairs[4]:+.3f}  ({len(run['pairs'])} pairs)", flush=True)
    finally:
        Odometry._learn_offset = learn
    for group, rows in groups.items():
        r = np.array(rows)
        print(f"{group:34s} run mean {r[:, 0].mean():+.3f} max {r[:, 0].max():+.3f}; pairs {r[:, 1].mean():+.3f}, "
              f"tracks true {r[:, 2].mean():+.3f} (sd {r[:, 2].std():.3f}), stereo true {r[:, 3].mean():+.3f}, both "
              f"{r[:, 4].mean():+.3f}, both with 0.3 px of disparity noise {r[:, 5].mean():+.3f}")


def street(root: Path, seeds: list[int], frames: int, steps=(0.5, 1.0, 1.5), turn_deg: float = 3.0) -> None:
    """The street world from a standstill up to each of ``steps`` metres per frame, turning up to ``turn_deg``
    degrees per frame (rendered once into ``root``, reused)."""
    rows = []
    turn = "" if turn_deg == 3.0 else f"-turn{turn_deg:g}"
    for seed in seeds:
        for step in steps:
            out = root / f"street-seed{seed}-step{step}{turn}-{frames}"
            if not (out / "manifest.yaml").is_file():
                write_synthetic_dataset(out, seed=seed, n_frames=frames, path="street", step_m=step, progress=False,
                                        turn_rad_per_frame=math.radians(turn_deg))
            r = compare(read_manifest(out))
            rows.append(r)
            print(_compare_line(f"street seed {seed}, {step} m/frame, turning up to {turn_deg:g} deg/frame", r))
            lost = np.flatnonzero(~r["result"].tracked)
            if len(lost):
                print(f"    lost frames: {lost.tolist()}")
    for key, name in (("vo", "mrstereo"), ("base", "baseline")):
        ate = [r[key].ate_percent for r in rows]
        print(f"{name}: ATE mean {np.mean(ate):.2f} %, max {np.max(ate):.2f} % over {len(rows)} sequences")
    print(f"mrstereo lost frames: {sum(r['vo_lost'] for r in rows)}; target: none lost, ATE <= 0.5 %")


def dataset(root: Path, seed: int, frames: int, width: int, height: int, path: str = "s-curve",
            randomize: bool = False) -> Path:
    """A drifted-odometry sequence (rendered once, reused); a randomized world whose own path is shorter
    than ``frames`` steps gets 10 frames fewer until it fits."""
    out = root / f"{'random-' if randomize else ''}{path}-{width}x{height}-{frames}-seed{seed}"
    if not (out / "manifest.yaml").is_file():
        try:
            write_synthetic_dataset(out, seed=seed, n_frames=frames, width=width, height=height, path=path,
                                    step_m=0.1, odometry_noise=NOISE, progress=False, randomize=randomize)
        except ValueError as exc:
            if not (randomize and "do not fit" in str(exc) and frames > 21):
                raise
            return dataset(root, seed, frames - 10, width, height, path, randomize)
    return out


def maps_randomized(root: Path, seeds: list[int], frames: int) -> None:
    """Maps of randomized worlds with drifted odometry: true poses, drifted, --align, --odometry visual."""
    names = ("drifted odometry", "map --align", "map --odometry visual")
    rows = []
    for seed in seeds:
        r = run_seed(dataset(root, seed, frames, 320, 240, path="front", randomize=True))
        rows.append(r)
        tp, tr = r["maps"]["true poses"]
        print(f"randomized world {seed}: true poses {tp:.3f} / {tr:.3f}; "
              + "; ".join(f"{n} {r['maps'][n][0] - tp:+.3f} / {r['maps'][n][1] - tr:+.3f}" for n in names)
              + f"; visual odometry ATE {r['vo'].ate_percent:.2f} %, lost {r['vo_lost']}")
    for name in names:
        dp = [r["maps"][name][0] - r["maps"]["true poses"][0] for r in rows]
        dr = [r["maps"][name][1] - r["maps"]["true poses"][1] for r in rows]
        print(f"{name:24s} precision - true-pose map: worst {min(dp):+.3f}, mean {np.mean(dp):+.3f}; recall: "
              f"worst {min(dr):+.3f}, mean {np.mean(dr):+.3f} (target within 0.05)")


def repose(observations, poses):
    """The observations at other poses (robot-frame points moved into the world again)."""
    out = []
    for obs, pose in zip(observations, poses):
        T = T_from_planar(*pose) @ np.linalg.inv(T_from_planar(*obs.pose))
        out.append(replace(obs, pose=tuple(float(v) for v in pose), cells=None,
                           obstacle_points_world=transform_points(T, obs.obstacle_points_world).astype(np.float32),
                           floor_points_world=transform_points(T, obs.floor_points_world).astype(np.float32)))
    return out


def run_vo(path: Path) -> dict:
    return compare(read_manifest(path))


def run_seed(path: Path) -> dict:
    config = PipelineConfig()
    manifest = read_manifest(path)
    true = np.array([f.true_pose for f in manifest.frames])
    T_true = np.stack([T_from_planar(*p) for p in true])
    gt = read_ros_map(manifest.ground_truth_map)

    result = compare(manifest)
    vo = result["result"]

    run = build_map(manifest, config=config, progress=False)           # matched once, drifted poses
    given_obs = run.observations

    def metrics(occupancy):
        m = map_metrics(occupancy, gt, path_xy=true)
        return m.precision, m.recall

    maps = {"true poses": metrics(fuse(repose(given_obs, true), grid=config.grid, config=config.mapping)),
            "drifted odometry": metrics(run.grid)}
    given_poses = np.array([f.pose for f in manifest.frames])
    fused = fuse_odometry(given_poses, vo.poses, vo.tracked)
    maps["map --align"] = metrics(fuse(repose(given_obs, fused.poses), grid=config.grid, config=config.mapping))
    keep = vo.tracked
    tracked = repose([o for o, k in zip(given_obs, keep) if k], vo.poses[keep])
    maps["map --odometry visual"] = metrics(fuse(tracked, grid=config.grid, config=config.mapping))
    T_aligned = np.stack([T_from_planar(*p) for p in fused.poses])
    T_given = np.stack([T_from_planar(*f.pose) for f in manifest.frames])
    return {**result, "maps": maps,
            "aligned": trajectory_metrics(T_aligned, T_true), "given": trajectory_metrics(T_given, T_true),
            "visual_steps": int(fused.visual_used.sum()),
            "corrections": (np.mean(fused.corrections(given_poses)[0]),
                            np.degrees(np.mean(fused.corrections(given_poses)[1])))}


def speed(root: Path, frames: int) -> None:
    from mrstereo.io import read_image, read_pfm
    from mrstereo.odometry import visual_odometry

    cv2.setNumThreads(1)
    path = dataset(root, 0, frames, 640, 480)
    manifest = read_manifest(path)
    pairs = [(read_image(f.left_rect), read_image(f.right_rect)) for f in manifest.frames]
    mount = manifest.mount.T_base_from_rectified(manifest.calibration.left.R)
    T0 = T_from_planar(*(manifest.frames[0].true_pose or manifest.frames[0].pose))
    visual_odometry(pairs[:4], manifest.calibration, T_base_from_cam=mount)          # numba's cached kernels loaded
    for label, disparities in (("stereo search", None),
                               ("given disparity", [read_pfm(f.gt_disparity) for f in manifest.frames])):
        t0 = time.perf_counter()
        vo = visual_odometry(pairs, manifest.calibration, T_base_from_cam=mount, T_world_from_base0=T0,
                             disparities=disparities)
        wall = (time.perf_counter() - t0) / len(pairs)
        ms = 1000 * vo.time_s
        print(f"640x480, depth from {label}: odometry stage {np.median(ms):.1f} ms median, {ms.mean():.1f} mean, "
              f"{ms.max():.1f} max CPU per frame (one thread); wall {1000 * wall:.1f} ms; "
              f"{vo.status.count('keyframe')} keyframes of {len(pairs)}, lost {vo.n_lost}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--random-seeds", type=int, nargs="*", default=[0, 1, 2])
    parser.add_argument("--frames", type=int, default=91)
    parser.add_argument("--random-frames", type=int, default=61)
    parser.add_argument("--data", type=Path, default=Path("bench-odometry-data"),
                        help="where the rendered sequences are kept (reused when present)")
    parser.add_argument("--vo-only", action="store_true", help="visual odometry only (no maps)")
    parser.add_argument("--speed", action="store_true", help="time the odometry stage at 640x480")
    parser.add_argument("--speed-frames", type=int, default=30)
    parser.add_argument("--kitti", nargs="?", type=Path, const=Path(os.environ.get("MRSTEREO_DATA", "."))
                        / "kitti_odometry_06", help="a KITTI odometry folder (default: the shared sample)")
    parser.add_argument("--kitti-every", type=int, nargs="+", default=[], metavar="N",
                        help="with --kitti: also every N-th frame (from frames 0 and 1), N times as fast")
    parser.add_argument("--held-out", nargs="?", type=Path, const=Path(os.environ.get("MRSTEREO_DATA", "."))
                        / "kitti_raw_sample" / "2011_09_26",
                        help="a KITTI raw date folder or drive (default: the shared sample)")
    parser.add_argument("--kitti-scale", nargs="*", type=Path, default=None, metavar="PATH",
                        help="where KITTI's error comes from (default: the shared 01 and 06)")
    parser.add_argument("--street", action="store_true", help="the street sequences at car speed")
    parser.add_argument("--street-seeds", type=int, nargs="+", default=[100, 101, 102])
    parser.add_argument("--street-frames", type=int, default=60)
    parser.add_argument("--street-steps", type=float, nargs="+", default=[0.5, 1.0, 1.5],
                        help="metres per frame of the street sequences")
    parser.add_argument("--street-turn", type=float, default=3.0, metavar="DEG",
                        help="the street's largest turn per frame at full speed [deg]")
    parser.add_argument("--maps-randomized", type=str, default=None, metavar="SEEDS",
                        help="maps of randomized worlds with drifted odometry, e.g. 100-119 (settings chosen on 0-9)")
    parser.add_argument("--suite", action="store_true",
                        help="every evaluation set in one table (KITTI 06, 01, raw; street 210-219, 230-239)")
    parser.add_argument("--suite-only", default=None, metavar="TEXT", help="with --suite: the sets whose name holds TEXT")
    parser.add_argument("--learner", action="store_true",
                        help="what the disparity correction reads on the street sets (true offset 0 px)")
    parser.add_argument("--set", nargs="+", default=[], metavar="NAME=VALUE",
                        help="with --suite: OdometryConfig settings other than the defaults")
    args = parser.parse_args()
    if args.suite:
        from mrstereo.odometry import OdometryConfig

        defaults = OdometryConfig()
        settings = {k: v.lower() in ("1", "true") if isinstance(getattr(defaults, k), bool) else type(getattr(defaults, k))(v)
                    for k, v in (item.split("=", 1) for item in args.set)}
        suite(Path(os.environ.get("MRSTEREO_DATA", ".")), args.data, OdometryConfig(**settings), args.suite_only)
        return
    if args.learner:
        learner(args.data, args.suite_only)
        return
    if args.maps_randomized:
        a, _, b = args.maps_randomized.partition("-")
        maps_randomized(args.data, list(range(int(a), int(b or a) + 1)), args.random_frames)
        return
    if args.speed:
        speed(args.data, args.speed_frames)
        return
    if args.kitti is not None or args.held_out is not None:
        if args.kitti is not None:
            kitti(args.kitti, args.kitti_every)
        if args.held_out is not None:
            kitti_raw(args.held_out)
        return
    if args.kitti_scale is not None:
        data = Path(os.environ.get("MRSTEREO_DATA", "."))
        for root in args.kitti_scale or [data / "kitti_odometry_01", data / "kitti_odometry_06"]:
            kitti_scale(root)
        return
    if args.street:
        street(args.data, args.street_seeds, args.street_frames, args.street_steps, args.street_turn)
        return
    rows, vo_rows = [], []
    for seed in args.seeds:
        path = dataset(args.data, seed, args.frames, 320, 240)
        if args.vo_only:
            r = run_vo(path)
            vo_rows.append(r)
            print(_compare_line(f"s-curve seed {seed}", r))
            continue
        r = run_seed(path)
        rows.append(r)
        vo_rows.append(r)
        print(_compare_line(f"s-curve seed {seed}", r))
        print(f"         drifted odometry: ATE {r['given'].ate_percent:.2f} %, end point "
              f"{r['given'].end_point_percent:.2f} %; after --align: ATE {r['aligned'].ate_percent:.2f} %, "
              f"end point {r['aligned'].end_point_percent:.2f} % (the poses moved from the given ones by "
              f"{100 * r['corrections'][0]:.1f} cm and {r['corrections'][1]:.2f} deg on average)")
        for name, (p, rc) in r["maps"].items():
            dp, dr = p - r["maps"]["true poses"][0], rc - r["maps"]["true poses"][1]
            print(f"         map {name:24s} precision {p:.3f} ({dp:+.3f}) recall {rc:.3f} ({dr:+.3f})")
    r = run_vo(dataset(args.data, 0, args.frames, 320, 240, path="front"))
    vo_rows.append(r)
    print(_compare_line("front seed 0", r))
    for seed in args.random_seeds:
        r = run_vo(dataset(args.data, seed, args.random_frames, 320, 240, path="front", randomize=True))
        vo_rows.append(r)
        print(_compare_line(f"randomized world {seed}", r))
    print(f"\nsummary: {len(vo_rows)} sequences")
    for key, name in (("vo", "mrstereo"), ("base", "baseline")):
        ate = [r[key].ate_percent for r in vo_rows]
        end = [r[key].end_point_percent for r in vo_rows]
        print(f"{name}: ATE {np.mean(ate):.2f} % (max {np.max(ate):.2f}), end point {np.mean(end):.2f} % "
              f"(max {np.max(end):.2f})")
    for name in ("drifted odometry", "map --align", "map --odometry visual") if rows else ():
        dp = [r["maps"][name][0] - r["maps"]["true poses"][0] for r in rows]
        dr = [r["maps"][name][1] - r["maps"]["true poses"][1] for r in rows]
        print(f"{name:24s} precision - true-pose map: worst {min(dp):+.3f}; recall: worst {min(dr):+.3f} "
              f"(target within 0.05)")


if __name__ == "__main__":
    main()
