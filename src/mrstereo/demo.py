"""``mrstereo demo``: the whole paper on the built-in synthetic corridor, with ground truth.

World -> calibration (the paper's GA, eq. 4-8, polished by LM; Fusiello rectification, section 2)
-> multi-range matching (eq. 9-12) -> rejection (eq. 13) and 3D (eq. 14-16) -> log-odds mapping
along the path (section 5.2) against the ground-truth map -> A* planning; one report directory
(report.md, metrics.json, PNG figures). User guide: docs/world.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import json
import math
import os
import time
from contextlib import contextmanager
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from . import _checks
from .io import atomic_write, read_disparity, read_image, write_image
from .viz.plot import disparity_colorbar, disparity_range_px, draw_disparity, new_figure, save_figure

__all__ = ["DemoResult", "run_demo", "DEMO_STEPS"]

DEMO_STEPS = ("world", "calibration", "matching", "mapping", "planning", "report")


@dataclass(frozen=True)
class DemoResult:
    out_dir: Path
    report: Path
    metrics: dict


def _disparity_panels(path: Path, panels: dict[str, np.ndarray], *, range_px: tuple[float, float],
                      background: np.ndarray) -> Path:
    """Paper Figs 7-10 style: several disparity maps over the left image, one colour scale.

    A panel title is ``"name\ndetails"`` (two short lines, so neighbouring titles never overlap).
    """
    names = list(panels)
    cols = 3
    rows = math.ceil(len(names) / cols)
    fig = new_figure(4.4 * cols + 0.8, 3.6 * rows)
    fig.set_layout_engine("constrained")
    mappable = None
    for k, name in enumerate(names):
        ax = fig.add_subplot(rows, cols, k + 1)
        img = panels[name]
        if img.dtype == np.uint8:
            ax.imshow(img, cmap="gray", vmin=0, vmax=255)
            ax.set_title(name, fontsize=9)
        else:
            mappable = draw_disparity(ax, img, range_px=range_px, background=background // 2 + 64)
            ax.set_title(f"{name}\n{np.isfinite(img).mean():.0%} of pixels with a disparity", fontsize=9)
        ax.set_axis_off()
    if mappable is not None:
        disparity_colorbar(fig, mappable, fig.axes, range_px=range_px, fraction=0.02, pad=0.01)
    return save_figure(fig, path)


def _disparity_errors(estimate: np.ndarray, truth: np.ndarray) -> dict:
    gt = np.isfinite(truth)
    est = gt & np.isfinite(estimate)
    err = np.abs(estimate[est] - truth[est])
    return {"density": float(est.sum() / max(gt.sum(), 1)),
            "bad1_estimated": float((err > 1).mean()) if err.size else float("nan"),
            "bad2_estimated": float((err > 2).mean()) if err.size else float("nan"),
            "mean_abs_error_px": float(err.mean()) if err.size else float("nan")}


class _Steps:
    """The demo's progress bar (``demo: world 0/6``: the step that is running now) and the time of each step."""

    def __init__(self, timing_s: dict, progress: bool):
        from tqdm.auto import tqdm

        self.timing_s = timing_s
        self.bar = tqdm(total=len(DEMO_STEPS), desc="demo", unit="step", disable=not progress)

    @contextmanager
    def __call__(self, name: str):
        self.bar.set_description_str(f"demo: {name}")
        t0 = time.perf_counter()
        yield
        self.timing_s[name] = round(time.perf_counter() - t0, 2)
        self.bar.update()

    def close(self) -> None:
        self.bar.set_description_str("demo: done")
        self.bar.close()


MAX_DEMO_FRAMES = 1000
"""The most frames of a demo run (its report draws every stage of every frame)."""


def run_demo(out_dir: str | os.PathLike = "mrstereo-demo", *, seed: int = 0, n_frames: int = 30,
             n_calibration_views: int = 12, progress: bool = True, randomize: bool = False) -> DemoResult:
    """Run the whole pipeline on the built-in world and write a report directory.

    Parameters
    ----------
    out_dir : path
        Report directory (created; an existing non-empty directory is refused).
    seed : int
        Seed of the world's textures and noise and of the GA.
    n_frames : int
        Frames of the corridor sequence (front, +45 and -45 degree views per stop).
    n_calibration_views : int
        Chessboard poses rendered for the stereo calibration.
    progress : bool
        A progress bar naming the step that runs.
    randomize : bool
        A randomized world drawn from ``seed`` (:func:`mrstereo.world.randomize.random_world`:
        corridor, textures, lights, rig, sensors, obstacles) instead of the built-in corridor.
    """
    seed = _checks.positive_int("seed", seed, minimum=0)
    n_frames = _checks.positive_int("n_frames", n_frames)
    if n_frames > MAX_DEMO_FRAMES:
        raise ValueError(f"n_frames must be at most {MAX_DEMO_FRAMES} (the demo maps every frame and draws "
                         f"each stage; use `mrstereo synth` and `mrstereo map` for long runs), got {n_frames}")
    out = Path(out_dir)
    if out.exists() and any(out.iterdir()):
        raise ValueError(f"output directory {out} already exists and is not empty")
    out.mkdir(parents=True, exist_ok=True)
    metrics: dict = {"seed": seed, "randomize": bool(randomize), "timing_s": {}}
    steps = _Steps(metrics["timing_s"], progress)
    with steps("world"):
        manifest = _world(out, seed=seed, n_frames=n_frames, randomize=randomize)
    with steps("calibration"):
        estimated, metrics["calibration"] = _calibration(out / "calibration", manifest, seed=seed,
                                                         n_views=n_calibration_views)
    with steps("matching"):
        metrics["frame0"] = _first_frame(out, manifest, estimated, metrics["calibration"])
    with steps("mapping"):
        run, union = _maps(manifest, estimated, metrics)
    with steps("planning"):
        files = _plan(out, run, union, metrics)
    with steps("report"):
        report = out / "report.md"
        with atomic_write(report) as tmp:
            tmp.write_text(_report_markdown(metrics, files))
    with atomic_write(out / "metrics.json") as tmp:
        tmp.write_text(json.dumps(metrics, indent=2, default=float))
    steps.close()
    return DemoResult(out_dir=out, report=report, metrics=metrics)


def _world(out: Path, *, seed: int, n_frames: int, randomize: bool):
    """1. Render the corridor sequence (raw and ideally rectified pairs, GT disparity, GT map); its figures."""
    from .mapping import read_ros_map
    from .mapping.figures import plot_map
    from .world import read_manifest, write_synthetic_dataset
    from .world.figures import save_stereo_figure

    manifest = read_manifest(write_synthetic_dataset(out / "data", seed=seed, n_frames=n_frames, progress=False,
                                                     randomize=randomize))
    first = manifest.frames[0]
    save_stereo_figure(out / "world_frame0.png", {
        "raw left (distorted, misaligned)": read_image(first.left), "raw right": read_image(first.right),
        "ideally rectified left": read_image(first.left_rect), "ideally rectified right": read_image(first.right_rect)},
        title="built-in corridor, frame 0")
    plot_map(read_ros_map(manifest.ground_truth_map), out / "world_gt_map.png",
             robot_path=np.array([f.pose for f in manifest.frames]),
             title="ground-truth map (12 m x 6 m, 5 cm cells) and robot path")
    return manifest


def _calibration(calib_dir: Path, manifest, *, seed: int, n_views: int):
    """2. Chessboard images -> corners -> GA + LM (eq. 4-8) -> Fusiello; and the paper's GA alone on its dot
    target (Figs 2-3). Returns the estimated rig and its errors against the true one."""
    from .calibration import CalibrationView, calibrate_stereo, chessboard_views, ga_calibrate_single
    from .calibration.report import residual_figure
    from .camera import write_stereo
    from .world import render_calibration_views, render_paper_dot_target

    truth = manifest.calibration
    views = render_calibration_views(truth, target="chessboard", board=(9, 6), spacing_m=0.03, n_views=n_views,
                                     seed=seed)
    paths_l = [calib_dir / "images" / f"left_{k:02d}.png" for k in range(len(views))]
    paths_r = [calib_dir / "images" / f"right_{k:02d}.png" for k in range(len(views))]
    for v, left, right in zip(views, paths_l, paths_r):
        write_image(left, v.image)
        write_image(right, v.image_right)
    left_views, size = chessboard_views(paths_l, (9, 6), 0.03)
    right_views, _ = chessboard_views(paths_r, (9, 6), 0.03)
    pairs = [(a, b) for a, b in zip(left_views, right_views) if a is not None and b is not None]
    cal = calibrate_stereo([a for a, _ in pairs], [b for _, b in pairs], width=size[0], height=size[1],
                           method="ga+lm", rng=seed)
    estimated = replace(cal.stereo, mount=manifest.mount)
    write_stereo(calib_dir / "stereo.yaml", estimated)
    residual_figure(calib_dir / "residuals_left.png", estimated.left.camera, [a for a, _ in pairs])
    dots = render_paper_dot_target(truth, seed=seed)
    dot_view = CalibrationView(dots.points_target, dots.points_px, name="paper dot target")
    ga = ga_calibrate_single(dot_view, width=size[0], height=size[1], rng=seed)
    residual_figure(calib_dir / "paper_dot_target_ga.png", ga.camera, [dot_view])
    write_image(calib_dir / "paper_dot_target.png", dots.image)
    true_l, est_l = truth.left.camera, estimated.left.camera
    return estimated, {
        "pairs_used": len(pairs), "pairs_rendered": len(views),
        "rms_px": cal.rms_px, "rectified_vertical_error_px": cal.vertical_error_px,
        "focal_error_pct": 100 * (est_l.fx / true_l.fx - 1),
        "principal_point_error_px": float(np.hypot(est_l.cx - true_l.cx, est_l.cy - true_l.cy)),
        "baseline_m": estimated.baseline_m, "true_baseline_m": truth.baseline_m,
        "paper_ga_single_view_rms_px": ga.rms_px,
    }


def _first_frame(out: Path, manifest, estimated, calibration: dict) -> dict:
    """3.-4. Frame 0 through the chain of ``mrstereo scan`` with the estimated calibration: rectification
    against the ideal one (into ``calibration``), the disparity of each range and after eq. (13) against the
    ground truth, the top view. Returns the frame's metrics."""
    from .geometry.scan import plot_top_view
    from .geometry.pair import scan_from_pair
    from .pipeline.run import PipelineConfig

    record = manifest.frames[0]
    pair = scan_from_pair(read_image(record.left), read_image(record.right), estimated, pan_rad=record.pan_rad,
                          preset=PipelineConfig.preset)
    frame, result = pair.frame, pair.frame.matching
    left, ideal_l = frame.left_rect, read_image(record.left_rect)
    valid = (left > 0) & (ideal_l > 0)
    calibration["rectification_mean_abs_diff_gray"] = float(
        np.abs(left.astype(float) - ideal_l.astype(float))[valid].mean())
    # geometric difference: where each rectified pixel samples the raw image, estimate vs truth
    shift = [np.hypot(e[0] - t[0], e[1] - t[1]) for e, t in zip(estimated.rectification_maps(),
                                                                   manifest.calibration.rectification_maps())]
    calibration["rectification_map_difference_px"] = {
        "left_mean": float(shift[0].mean()), "left_max": float(shift[0].max()),
        "right_mean": float(shift[1].mean()), "right_max": float(shift[1].max())}
    calibration["rectified_focal_px"] = estimated.focal_px
    calibration["true_rectified_focal_px"] = manifest.calibration.focal_px
    panels = {"rectified left (estimated calibration)": left}
    names = {1: "III (full resolution)", 2: "II (1/2 horizontal)", 4: "I (1/4 horizontal)"}
    for level, d in zip(result.plan.levels, result.levels):
        depth = (f", {level.depth_band_m[0]:.1f}-{level.depth_band_m[1]:.1f} m" if level.depth_band_m else "")
        panels[f"range {names.get(level.decimation, level.decimation)}\n"
               f"{level.band_px[0]:.0f}-{level.band_px[1]:.0f} px{depth}"] = d
    panels["combined (eq. 12)"] = result.disparity_px
    panels["after ground suppression (eq. 13)"] = frame.disparity_px
    gt = read_disparity(record.gt_disparity)
    panels["ground truth"] = gt
    _disparity_panels(out / "disparity.png", panels, range_px=disparity_range_px(gt, result.disparity_px),
                      background=left)
    obstacles = frame.obstacles
    plot_top_view(out / "top_view.png", obstacle_points_robot=obstacles.obstacle_points_robot,
                  floor_points_robot=obstacles.floor_points_robot, scan=pair.scan,
                  title="top view of frame 0 (robot frame)")
    return {"plan": result.plan.describe(), "ghost_points_removed": int(frame.rejection.n_rejected),
            "matching_vs_gt": _disparity_errors(result.disparity_px, gt),
            "after_rejection_vs_gt": _disparity_errors(frame.disparity_px, gt)}


def _maps(manifest, estimated, metrics: dict):
    """5. The map along the path with the estimated calibration (raw images), with the paper's union fusion,
    and with a single-range search of the same work; their metrics into ``metrics``."""
    from .mapping import read_ros_map
    from .mapping.metrics import map_metrics
    from .pipeline.run import PipelineConfig, build_map, map_from_observations

    config = PipelineConfig()
    run = build_map(manifest, config=config, calibration=estimated, progress=False)
    union = map_from_observations(manifest, run.observations, config=config.with_fusion("union"), stereo=estimated)
    metrics["map"] = run.metrics.to_dict() if run.metrics is not None else None
    metrics["map_union"] = union.metrics.to_dict() if union.metrics is not None else None
    single = config.single_range_equal_work(estimated)
    single_run = build_map(manifest, config=single, calibration=estimated, progress=False)
    metrics["map_single_range"] = single_run.metrics.to_dict() if single_run.metrics is not None else None
    metrics["map_single_range"]["max_disparity_px"] = single.max_disparity_px
    gt_map, path_xy = read_ros_map(manifest.ground_truth_map), np.array([f.pose for f in manifest.frames])
    metrics["near_recall_within_1m"] = {
        name: map_metrics(grid, gt_map, path_xy=path_xy, within_m=1.0).recall
        for name, grid in (("multi-range", run.grid), ("single range", single_run.grid))}
    return run, union


def _plan(out: Path, run, union, metrics: dict) -> dict:
    """6. A* from the first to the last pose through the map; the map outputs and figures with the path."""
    from .mapping import plan_path
    from .mapping.figures import plot_map
    from .evaluation.outputs import write_map_outputs

    path_xy = np.array([f.pose for f in run.manifest.frames])
    start, goal = tuple(path_xy[0, :2]), tuple(path_xy[-1, :2])
    plan = plan_path(run.grid.to_ros_map(), start, goal, robot_radius_m=0.2, unknown_is_obstacle=False)
    metrics["plan"] = {"success": plan.success, "message": plan.message, "length_m": plan.length_m,
                       "start": list(start), "goal": list(goal), "robot_radius_m": 0.2, "unknown": "free"}
    files = write_map_outputs(run, out / "map", planned_path=plan.path_xy if plan.success else None)
    plot_map(union.grid, out / "map" / "map_union.png", robot_path=path_xy, ground_truth=union.ground_truth_map,
             title="occupancy grid (paper's union)")
    return files


def _report_markdown(m: dict, files: dict) -> str:
    c = m["calibration"]
    lines = ["# mrstereo demo report", "",
             "The built-in synthetic corridor, processed end to end. All numbers are against ground truth.", "",
             "## Calibration (GA + LM, Fusiello rectification)", "",
             f"- pairs used: {c['pairs_used']} of {c['pairs_rendered']} rendered chessboard pairs",
             f"- RMS reprojection error: {c['rms_px']:.3f} px; rectified |y_l - y_r|: "
             f"{c['rectified_vertical_error_px']:.3f} px",
             f"- focal length error: {c['focal_error_pct']:+.2f} %; principal point error: "
             f"{c['principal_point_error_px']:.2f} px; baseline {c['baseline_m']:.4f} m "
             f"(true {c['true_baseline_m']:.4f} m)",
             f"- paper's GA alone on the single-view dot target: RMS {c['paper_ga_single_view_rms_px']:.3f} px",
             f"- rectifying raw frame 0 with the estimate vs the ideal rectified image: "
             f"{c['rectification_mean_abs_diff_gray']:.2f} grey levels mean abs difference; the "
             f"rectification maps differ by {c['rectification_map_difference_px']['left_mean']:.2f} px "
             f"(left) / {c['rectification_map_difference_px']['right_mean']:.2f} px (right) on average, "
             f"max {max(c['rectification_map_difference_px']['left_max'], c['rectification_map_difference_px']['right_max']):.2f} px "
             f"(the estimate's rectified focal length is {c['rectified_focal_px']:.1f} px against the world's "
             f"{c['true_rectified_focal_px']:.1f} px: Fusiello's new camera keeps only valid pixels; and a "
             "rectified frame is defined up to a rotation about the baseline)", "",
             "![world](world_frame0.png)", "", "![ground truth map](world_gt_map.png)", "",
             "![residuals](calibration/residuals_left.png)", "",
             "![paper dot target](calibration/paper_dot_target_ga.png)", "",
             "## Multi-range matching and ground suppression (frame 0)", "",
             "```", m["frame0"]["plan"], "```", "",
             "| stage | density | bad-1 (estimated) | bad-2 (estimated) | mean abs error [px] |",
             "|---|---|---|---|---|"]
    for key, name in (("matching_vs_gt", "matching (eq. 9-12)"), ("after_rejection_vs_gt", "after eq. 13")):
        e = m["frame0"][key]
        lines.append(f"| {name} | {e['density']:.1%} | {e['bad1_estimated']:.1%} | {e['bad2_estimated']:.1%} | "
                     f"{e['mean_abs_error_px']:.2f} |")
    lines += ["", "![disparity](disparity.png)", "", "![top view](top_view.png)", "",
              "## Occupancy grid along the path", "",
              "| fusion | occupied precision | occupied recall | wall profile error [cm] | free correct | "
              "free recall |",
              "|---|---|---|---|---|---|"]
    single = m.get("map_single_range") or {}
    for key, name in (("map", "multi-range, log-odds"), ("map_union", "multi-range, paper's union"),
                      ("map_single_range", f"single range 0-{single.get('max_disparity_px', 0):.0f} px "
                                           "(equal work), log-odds")):
        g = m.get(key)
        if g:
            lines.append(f"| {name} | {g['precision']:.3f} | {g['recall']:.3f} | "
                         f"{100 * g['mean_distance_m']:.1f} | {g['free_precision']:.3f} | "
                         f"{g['free_recall']:.3f} |")
    near = m["near_recall_within_1m"]
    lines += ["", f"Occupied recall within 1 m of the path (near obstacles): multi-range "
                  f"{near['multi-range']:.3f}, single range of equal work {near['single range']:.3f}."]
    p = m["plan"]
    lines += ["", ("A* path from start to goal: "
                   + (f"{p['length_m']:.2f} m" if p["success"] else f"failed ({p['message']})")), "",
              "![map](map/map.png)", "", "![union](map/map_union.png)", "",
              "Timing [s]: " + ", ".join(f"{k} {v}" for k, v in m["timing_s"].items()), ""]
    return "\n".join(lines)
