"""Obstacle detection, rejection and depth accuracy on the synthetic corridor.

Usage::

    python benchmarks/bench_obstacles.py [--frames N] [--seed S] [--quick]

Renders frames of ``mrstereo.world.default_scene()`` along the corridor (head
pans 0 and +-45 degrees as in the paper's Sec. 5.2), matches them with
``mrstereo.matching.compute_disparity`` (``mapping`` preset (the chain's default), multi-range) and
measures, within 4 m of the robot, on 5 cm cells of the robot frame:

* obstacle recall: GT obstacle cells (cells holding a ground-truth point of a
  world object, labels >= 10, between ``min_obstacle_height_m`` and
  ``max_obstacle_height_m``, seen by both cameras, not nearer than the plan's
  0.5 m) with a detected obstacle point within 1 cell (5 cm) of them; walls,
  doors and posters are scored apart (wall-cell recall);
* false obstacles: visible GT floor cells (2 cells away from any GT obstacle
  cell) holding a detected obstacle point, over all such cells;
* ghost points: floor-labelled pixels whose estimated point is classified as an
  obstacle, before and after the eq. (13) rejection, and the obstacle recall
  before and after it;
* the eq. (13) threshold T scan (ghosts vs recall) used to choose the default;
* depth error |Z - Z_gt| of detected obstacle pixels per range band (Range I,
  II, III of the matcher's default plan), multi-range vs a single full-resolution
  range of equal work (``multi_range=False``, as many disparities as the
  multi-range plan evaluates per pixel);
* the floor estimated by V-disparity and by a 3D plane against the true mount.

``--floor-speed``: the time of the floor fit instead (``estimate_ground``, the 3-D plane: what every frame of
a recording without a mount runs), on the first ``--frames`` frames of the shared real recordings
(EuRoC, OpenLORIS, KITTI odometry 06: ``$MRSTEREO_DATA``), against OpenCV's ``StereoBM`` and mrstereo's
matcher on the same rectified pair: medians per recording and the median of the per-frame ratios.

    python benchmarks/bench_obstacles.py --floor-speed [--frames 10]
"""
from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np
from scipy import ndimage

from mrstereo.geometry import (ObstacleConfig, detect_obstacles, estimate_ground, ground_from_mount,
                               points_robot_from_disparity)
from mrstereo.matching import compute_disparity
from mrstereo.matching.config import preset_config
from mrstereo.rejection import RejectionConfig, reject_uniform
from mrstereo.world import LABEL_FLOOR, default_scene, default_stereo, is_obstacle_label, render_stereo_frame

RES_M = 0.05
RADIUS_M = 4.0
BANDS_M = ((0.5, 1.0, "I"), (1.0, 2.5, "II"), (2.5, 4.0, "III"))   # III is cut at RADIUS_M


def _cells(points_xy: np.ndarray) -> set[tuple[int, int]]:
    ij = np.floor(points_xy / RES_M).astype(np.int64)
    return set(map(tuple, ij))


def _cell_image(cells: set, origin: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    img = np.zeros(shape, bool)
    if cells:
        ij = np.array(sorted(cells)) - origin
        ok = (ij >= 0).all(axis=1) & (ij[:, 0] < shape[0]) & (ij[:, 1] < shape[1])
        img[ij[ok, 0], ij[ok, 1]] = True
    return img


def visible_in_right(disparity_px: np.ndarray, tolerance_px: float = 0.5) -> np.ndarray:
    """GT pixels seen by both cameras: inside the right image and not occluded there.

    A left pixel ``u`` lands at ``u - d`` in the right image; it is occluded when a
    pixel to its right lands left of it (a nearer surface crosses in front).
    """
    d = disparity_px.astype(np.float64)
    u = np.arange(d.shape[1], dtype=np.float64)[None, :]
    x_r = np.where(np.isfinite(d), u - d, np.inf)
    # minimum of x_r over the pixels strictly to the right of each pixel
    right_min = np.minimum.accumulate(x_r[:, ::-1], axis=1)[:, ::-1]
    right_min = np.concatenate([right_min[:, 1:], np.full((d.shape[0], 1), np.inf)], axis=1)
    return np.isfinite(d) & (x_r >= 0) & (right_min >= x_r - tolerance_px)


def frame_truth(frame, stereo, config: ObstacleConfig, *, min_depth_m: float):
    """GT robot-frame points and pixel masks: obstacles, walls (+doors, posters...), floor.

    Pixels count when seen by both cameras (:func:`visible_in_right`), ``min_depth_m <= Z``
    (what the matcher's plan can see) and their horizontal range is within RADIUS_M;
    obstacles and walls within the height band.
    """
    T = stereo.mount.T_base_from_rectified(stereo.left.R, frame.pan_rad)
    gt = points_robot_from_disparity(frame.disparity_px, stereo, T)
    with np.errstate(invalid="ignore"):
        near = ((np.hypot(gt[..., 0], gt[..., 1]) <= RADIUS_M) & (frame.depth_m >= min_depth_m)
                & visible_in_right(frame.disparity_px))
        band = (gt[..., 2] > config.min_obstacle_height_m) & (gt[..., 2] <= config.max_obstacle_height_m)
    obstacle = near & band & is_obstacle_label(frame.labels)
    wall = near & band & ~is_obstacle_label(frame.labels) & (frame.labels != LABEL_FLOOR) & (frame.labels > 0)
    floor = near & (frame.labels == LABEL_FLOOR)
    return gt, obstacle, wall, floor


def cell_scores(detected_xy, gt_obstacle_xy, gt_wall_xy, gt_floor_xy, matched_obstacle_xy=None):
    """Recall of obstacle / wall cells (a detection within 1 cell) and the false-obstacle rate.

    False obstacles: visible floor cells at least 2 cells away from any GT obstacle or
    wall cell that hold a detected obstacle point, over all such floor cells.
    """
    if detected_xy.size:
        detected_xy = detected_xy[np.hypot(*detected_xy.T) <= RADIUS_M]
    origin = np.array([-int(RADIUS_M / RES_M) - 3] * 2)
    shape = (2 * int(RADIUS_M / RES_M) + 7,) * 2
    det_img, obs_img, wall_img, flo_img = (_cell_image(_cells(xy), origin, shape)
                                           for xy in (detected_xy, gt_obstacle_xy, gt_wall_xy, gt_floor_xy))
    matched = obs_img if matched_obstacle_xy is None else _cell_image(_cells(matched_obstacle_xy), origin, shape)
    det_near = ndimage.binary_dilation(det_img, structure=np.ones((3, 3), bool))
    occupied = ndimage.binary_dilation(obs_img | wall_img, iterations=2, structure=np.ones((3, 3), bool))
    free = flo_img & ~occupied
    return dict(obs_hit=int((obs_img & det_near).sum()), n_obs=int(obs_img.sum()),
                matched_hit=int((matched & det_near).sum()), n_matched=int(matched.sum()),
                wall_hit=int((wall_img & det_near).sum()), n_wall=int(wall_img.sum()),
                false=int((free & det_img).sum()), n_free=int(free.sum()))


def evaluate(disparity, frame, stereo, config, truth, *, raw, ground=None):
    """Scores of one frame; ``raw`` is the matcher's disparity before rejection.

    ``matched`` cells are GT obstacle cells with at least one pixel the matcher gave a
    disparity (before rejection): the recall on them measures this stage alone.
    """
    gt, gt_obs, gt_wall, gt_floor = truth
    res = detect_obstacles(disparity, stereo, pan_rad=frame.pan_rad, config=config, ground=ground)
    det = res.obstacle_mask
    matched = gt_obs & np.isfinite(raw)
    out = cell_scores(res.obstacle_points_robot[:, :2], gt[gt_obs][:, :2], gt[gt_wall][:, :2], gt[gt_floor][:, :2],
                      gt[matched][:, :2])
    out.update(ghosts=int((det & gt_floor).sum()), obs_px=int((det & gt_obs).sum()), n_obs_px=int(gt_obs.sum()),
               result=res)
    return out


def summary(rows) -> dict:
    """Totals over frames; rates are pooled (cells of all frames)."""
    tot = {k: sum(r[k] for r in rows) for k in ("obs_hit", "n_obs", "matched_hit", "n_matched", "wall_hit", "n_wall", "false", "n_free",
                                                "ghosts", "obs_px", "n_obs_px")}
    return dict(recall=tot["obs_hit"] / max(tot["n_obs"], 1), wall=tot["wall_hit"] / max(tot["n_wall"], 1),
                false_rate=tot["false"] / max(tot["n_free"], 1),
                matched_recall=tot["matched_hit"] / max(tot["n_matched"], 1),
                pixel_recall=tot["obs_px"] / max(tot["n_obs_px"], 1), **tot)


def depth_errors(disparity, frame, stereo, detected):
    """|Z - Z_gt| (camera depth) of detected obstacle pixels, per range band."""
    with np.errstate(divide="ignore", invalid="ignore"):
        z = stereo.focal_px * stereo.baseline_m / (disparity.astype(np.float64) + stereo.doffs_px)
    z_gt = frame.depth_m.astype(np.float64)
    out = {}
    for lo, hi, name in BANDS_M:
        m = detected & (z_gt >= lo) & (z_gt < hi) & np.isfinite(z)
        out[name] = np.abs(z[m] - z_gt[m])
    return out


def _fmt(summ: dict) -> str:
    return (f"obstacle-cell recall {summ['recall']:.4f} ({summ['obs_hit']}/{summ['n_obs']}; "
            f"{summ['matched_recall']:.4f} of the {summ['n_matched']} cells the matcher saw), "
            f"false obstacle cells {summ['false_rate']:.4f} ({summ['false']}/{summ['n_free']} floor cells), "
            f"wall-cell recall {summ['wall']:.3f}, obstacle pixel recall {summ['pixel_recall']:.3f}")


def floor_speed(n_frames: int) -> int:
    """Print the median time of the 3-D plane floor fit per real recording, against StereoBM and the matcher."""
    from mrstereo._executor import keep_freed_memory
    from mrstereo.evaluation.baselines import stereo_bm
    from mrstereo.recordings import read_recording
    from mrstereo.recordings.manifest import frame_pair
    from mrstereo.recordings.samples import data_root
    from mrstereo.rejection import reject_uniform as reject

    keep_freed_memory()          # as the mrstereo command does: frame-sized arrays reused, not faulted in anew
    print("| recording | frames | floor fit ms | StereoBM ms | matcher ms | fit / StereoBM | fit / matcher |")
    print("|---|---|---|---|---|---|---|")
    for name in ("euroc_asl_sample", "openloris_sample", "kitti_odometry_06"):
        if not (data_root() / name).is_dir():
            print(f"| {name} | not in {data_root()} (set $MRSTEREO_DATA) | | | | | |")
            continue
        manifest = read_recording(data_root() / name)
        stereo = manifest.calibration
        times = {"fit": [], "bm": [], "match": []}
        for k, record in enumerate(manifest.frames[:n_frames + 1]):
            left, right, rectified = frame_pair(record)
            if not rectified:
                left, right = stereo.rectify(left, right)
            t0 = time.perf_counter()
            matched = compute_disparity(left, right, calibration=stereo, preset="mapping")
            t1 = time.perf_counter()
            stereo_bm(left, right, max_disparity_px=matched.near_limit_px)
            rejected = reject(matched.disparity_px, left).disparity_px       # what the chain fits the floor to
            t2 = time.perf_counter()
            estimate_ground(rejected, stereo, method="plane", rng=0)
            t3 = time.perf_counter()
            if k:                                   # the first frame compiles
                for key, dt in zip(times, (t3 - t2, t2 - t1, t1 - t0)):
                    times[key].append(dt)
        fit, bm, match = (np.array(v) for v in times.values())
        print(f"| {name} {stereo.size[0]}x{stereo.size[1]} | {len(fit)} | {np.median(fit) * 1e3:.1f} | "
              f"{np.median(bm) * 1e3:.1f} | {np.median(match) * 1e3:.1f} | {np.median(fit / bm):.2f} | "
              f"{np.median(fit / match):.2f} |")
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--frames", type=int, default=6, help="frames to render (poses x pans)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--quick", action="store_true", help="2 frames, 2 thresholds")
    ap.add_argument("--floor-speed", action="store_true", help="the floor fit's time on real recordings")
    args = ap.parse_args(argv)
    if args.frames < 1:
        ap.error(f"--frames must be at least 1, got {args.frames}")
    if args.floor_speed:
        return floor_speed(args.frames)
    n_frames = 2 if args.quick else args.frames

    scene, stereo = default_scene(), default_stereo()
    config = ObstacleConfig()
    # Poses along the corridor (deterministic for a seed); a pose inside an object is skipped.
    rng = np.random.default_rng(args.seed)
    candidates = [(float(x), float(rng.uniform(-0.35, 0.35)), float(rng.uniform(-0.1, 0.1)))
                  for x in np.linspace(0.3, 11.0, 4 * n_frames)]
    pans = [0.0, math.radians(45), -math.radians(45)]
    robust = preset_config("mapping")
    default_t = RejectionConfig().texture_threshold
    thresholds = [0.0, default_t] if args.quick else sorted({0.0, 1.5, 2.0, 2.5, 3.0, 4.0, default_t})
    bands = [name for *_, name in BANDS_M]
    rows = {k: [] for k in ("multi", "single", "multi, floor estimated")}
    scan_t = {(p, t): [] for p in ("mapping", "paper") for t in thresholds}
    errors = {k: {b: [] for b in bands} for k in ("multi", "single")}
    grounds = {"v_disparity": [], "plane": []}
    t_match, n_eq, plan = [], None, None
    k = 0
    for pose in candidates[:: max(1, len(candidates) // n_frames)]:
        if k == n_frames:
            break
        pan = pans[k % len(pans)]
        try:
            frame = render_stereo_frame(scene, stereo, pose=pose, pan_rad=pan, seed=args.seed + k)
        except ValueError:          # camera inside an obstacle
            continue
        L, R = frame.left_rect, frame.right_rect
        t0 = time.perf_counter()
        multi = compute_disparity(L, R, calibration=stereo, preset="mapping")
        t_match.append(time.perf_counter() - t0)
        plan = multi.plan
        min_depth = min(lv.depth_band_m[0] for lv in plan.levels)
        truth = frame_truth(frame, stereo, config, min_depth_m=min_depth)
        r0, r1, c0, c1 = plan.aoi
        n_eq = int(round(plan.work / ((r1 - r0) * (c1 - c0))))
        single = compute_disparity(L, R, max_disparity_px=n_eq, config=robust.replace(search={"multi_range": False}),
                                   aoi=plan.aoi)
        paper = compute_disparity(L, R, calibration=stereo, preset="paper")
        for name, raw in (("mapping", multi.disparity_px), ("paper", paper.disparity_px)):
            for t in thresholds:
                d = reject_uniform(raw, L, config=RejectionConfig(texture_threshold=t)).disparity_px
                scan_t[(name, t)].append(evaluate(d, frame, stereo, config, truth, raw=raw))
        for name, raw in (("multi", multi.disparity_px), ("single", single.disparity_px)):
            d = reject_uniform(raw, L, config=RejectionConfig()).disparity_px
            ev = evaluate(d, frame, stereo, config, truth, raw=raw)
            rows[name].append(ev)
            for band, err in depth_errors(d, frame, stereo, ev["result"].obstacle_mask & truth[1]).items():
                errors[name][band].append(err)
            if name == "multi":
                for method in grounds:
                    grounds[method].append(estimate_ground(raw, stereo, method=method, rng=0))
                g = grounds[config.ground_method][-1]
                rows["multi, floor estimated"].append(
                    evaluate(d, frame, stereo, config, truth, raw=raw, ground=g if g.success else None))
        print(f"frame {k}: pose ({pose[0]:.2f}, {pose[1]:.2f}, {pose[2]:.2f}) pan {math.degrees(pan):+.0f} deg: "
              f"{_fmt(summary(rows['multi'][-1:]))}", file=sys.stderr)
        k += 1

    print(f"# Obstacles on the synthetic corridor: {k} frames (seed {args.seed}), 320x240, mapping "
          f"preset, T = {default_t} (eq. 13); obstacles = world objects (labels >= 10) at "
          f"{min_depth:.2f} m <= Z and range <= {RADIUS_M} m; {RES_M * 100:.0f} cm cells")
    print(f"matcher median {np.median(t_match) * 1e3:.0f} ms/frame; plan:\n{plan.describe()}\n")
    for name, r in rows.items():
        label = {"single": f"single range 0-{n_eq} px (equal work)"}.get(name, name + "-range" if name == "multi" else name)
        print(f"{label:>36}: {_fmt(summary(r))}")
    print("\n## Eq. (13) rejection: threshold T vs floor ghost pixels and obstacle recall (all frames)")
    print(f"{'preset':>7} {'T':>5} {'ghost px':>9} {'false cells':>11} {'cell recall':>11} {'seen-cell rec':>13} "
          f"{'pixel recall':>12} {'wall recall':>11}")
    for (name, t), r in scan_t.items():
        sm = summary(r)
        print(f"{name:>7} {t:>5.1f} {sm['ghosts']:>9d} {sm['false_rate']:>11.4f} {sm['recall']:>11.4f} "
              f"{sm['matched_recall']:>13.4f} "
              f"{sm['pixel_recall']:>12.3f} {sm['wall']:>11.3f}")
    print("\n## Depth error |Z - Z_gt| of detected obstacle pixels per range band (camera depth)")
    print(f"{'band':>14} {'method':>7} {'pixels':>7} {'median mm':>9} {'p90 mm':>8} {'median rel %':>12}")
    for lo, hi, band in BANDS_M:
        for name in ("multi", "single"):
            e = np.concatenate(errors[name][band])
            label = f"{band} {lo}-{hi} m" if name == "multi" else ""
            if e.size == 0:
                print(f"{label:>14} {name:>7} {0:>7d} {'-':>9} {'-':>8} {'-':>12}")
                continue
            print(f"{label:>14} {name:>7} {e.size:>7d} {np.median(e) * 1e3:>9.1f} {np.percentile(e, 90) * 1e3:>8.1f} "
                  f"{np.median(e) / (0.5 * (lo + hi)) * 100:>12.2f}")
    rig = ground_from_mount(stereo.mount, R_rect_from_cam=stereo.left.R)      # the true floor
    print(f"\n## Floor estimated from the disparity (true: height {rig.height_m:g} m, tilt "
          f"{math.degrees(rig.tilt_rad):.2f} deg)")
    for method, gs in grounds.items():
        ok = [g for g in gs if g.success]
        if not ok:
            print(f"{method:>12}: failed on all frames")
            continue
        dh = np.array([abs(g.height_m - rig.height_m) for g in ok])
        dt = np.array([abs(math.degrees(g.tilt_rad - rig.tilt_rad)) for g in ok])
        print(f"{method:>12}: {len(ok)}/{len(gs)} frames; |dh| median {np.median(dh) * 1e3:.1f} mm, "
              f"max {dh.max() * 1e3:.1f} mm; |dtilt| median {np.median(dt):.3f} deg, max {dt.max():.3f} deg")
    return 0


if __name__ == "__main__":
    sys.exit(main())
