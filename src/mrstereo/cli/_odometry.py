"""CLI of the visual odometry: ``mrstereo odometry`` (a dataset or a bag to a TUM trajectory).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import json
from pathlib import Path

import click

from ..pipeline.odometry import manifest_of, odometry_from_manifest
from ._bag import opened_dataset, read_inputs, recording_of, recording_options
from ._live import check_sink_options, record_bag_option, replayed_to_sinks, viewer_option
from ._options import library_default, profile_option

__all__ = ["COMMANDS", "OUTPUT_SUFFIXES"]

OUTPUT_SUFFIXES = {"--out": (".txt", ".tum"), "--plot": (".png", ".pdf", ".svg"), "--metrics": (".json",)}
"""What the files of ``mrstereo odometry`` may be called: a TUM trajectory is text, the figure an image."""


@click.command("odometry")
@profile_option("read, odometry")
@click.argument("manifest", required=False, metavar="[RECORDING]", type=click.Path(path_type=Path))
@click.option("-o", "--out", "out_path", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Trajectory file (TUM: 't tx ty tz qx qy qz qw' per frame, the robot base in the world).")
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Top-view figure (PNG) of the trajectory beside the given odometry and the truth.")
@click.option("--metrics", "metrics_path", type=click.Path(dir_okay=False, path_type=Path),
              help="JSON with ATE, RPE per metre and end-point error against the true poses (or the given ones).")
@click.option("--calib", "calib", type=click.Path(dir_okay=False, path_type=Path),
              help="Use this stereo calibration (and the raw images) instead of the manifest's; "
                   "with --bag, instead of the camera_info topics.")
@click.option("--start", type=click.Choice(["given", "origin"]), show_default=True,
              default="given" if library_default(odometry_from_manifest, "initial_pose") == "given" else "origin",
              help="Start at the first frame's given pose, or at the origin.")
@recording_options
@viewer_option
@record_bag_option
@click.option("--quiet", is_flag=True, help="No progress bar.")
def odometry_command(manifest: Path | None, out_path: Path, plot_path: Path | None, metrics_path: Path | None,
                     calib: Path | None, start: str, bag: Path | None, rate_hz: float | None,
                     viewers: tuple[str, ...], record_bag: Path | None, quiet: bool, truth, **bag_kw) -> None:
    """Stereo visual odometry of a recording or a ROS bag.

    RECORDING is a dataset folder (docs/dataset.md), a KITTI odometry or
    EuRoC/ASL folder, a folder of left/right image folders (with --calib), or
    a ROS bag.
    Tracks corners of each rectified left image against a keyframe, takes their depth from
    the stereo pair, solves the camera motion with PnP-RANSAC and Levenberg-Marquardt, and
    refines the last keyframes' poses and landmarks by bundle adjustment (docs/odometry.md).
    Writes one TUM line per frame, the 3-D pose of the robot base with its stamp (the frame
    index when the recording has no stamps), readable by the evo tools. A frame where tracking
    is lost gets the motion model's prediction and is reported.
    """
    import numpy as np

    from ..io import check_outputs
    from ..camera import CameraMount
    from ..odometry.trajectory import moved_to_body, plot_trajectories, trajectory_metrics, write_tum
    from ..recordings.sources import check_pair_streams

    recording_of(manifest, bag)                          # one of them
    dataset, bag = read_inputs(manifest, bag, calib, rate_hz=rate_hz, truth=truth)
    outputs = {"--out": out_path, "--plot": plot_path, "--metrics": metrics_path}
    check_outputs(outputs, suffixes=OUTPUT_SUFFIXES)
    inputs = [p for p in (bag if dataset is None else dataset.root, calib) if p is not None]
    viewers = check_sink_options(viewers, record_bag, out_path.with_suffix(""), inputs,
                                 stamps_s=None if dataset is None else dataset.stamps_s)
    opened = opened_dataset(dataset, bag, calib, quiet=quiet, bag_kw=bag_kw, rate_hz=rate_hz, truth=truth)
    with opened as (recording, stereo, stamps):
        check_pair_streams(recording)
        run = odometry_from_manifest(recording, calibration=stereo, progress=not quiet,
                                     initial_pose="given" if start == "given" else "identity")
        dataset = recording if stamps is None else manifest_of(recording)     # (a bag: its stamps and poses)
    if stamps is None:
        stamps = run.stamps_s if run.stamps_s is not None else np.arange(len(run.status), dtype=np.float64)
    stamp_note = "" if run.stamps_s is not None or bag is not None else \
        "\nthe recording has no stamps: t is the frame index"
    write_tum(out_path, stamps, run.T_world_from_base,
              comment=f"mrstereo odometry: {run.message}\nstatus per frame: "
                      + "".join({"keyframe": "K", "tracked": ".", "lost": "x"}[s] for s in run.status) + stamp_note)
    given = np.stack([f.T_world_from_base for f in dataset.frames])
    has_truth = all(f.true_pose is not None for f in dataset.frames)
    truth = np.stack([f.T_world_from_base_true for f in dataset.frames]) if has_truth else None
    reference, ref_name = (truth, "true poses") if has_truth else (given, "given poses")
    if not has_truth and not dataset.has_poses:
        reference, ref_name = None, "none"      # (the given poses are placeholders: nothing to compare with)
    elif start == "origin":       # compare from the common start
        reference = np.linalg.inv(reference[0]) @ reference
    estimate = run.T_world_from_base
    if reference is not None and dataset.pose_frame_mount is not None:
        # the truth is of another body (EuRoC's): the estimate moved to it through the camera mounts
        mount = dataset.mount or CameraMount.from_xyz_rpy((0.0, 0.0, 0.0), (0.0, 0.0, 0.0))
        R = (stereo or dataset.calibration).left.R
        estimate = moved_to_body(estimate, [mount.T_base_from_rectified(R, f.pan_rad) for f in dataset.frames],
                                 dataset.pose_frame_mount.T_base_from_rectified(R), reference[0])
        ref_name += " (of the recording's body frame)"
    metrics = None if reference is None else trajectory_metrics(estimate, reference)
    click.echo(f"odometry of {len(run.status)} frames: {run.message}; "
               f"{run.status.count('keyframe')} keyframes, median {np.median(run.n_inliers[1:]) if len(run.status) > 1 else 0:.0f} "
               f"inliers, {1000 * np.median(run.time_s):.1f} ms per frame (CPU)")
    click.echo(f"vs {ref_name}: {metrics.describe()}" if metrics is not None else
               "the recording has no true or given poses to compare with")
    if metrics_path is not None:
        data = {"reference": ref_name, **({} if metrics is None else metrics.to_dict()), "frames": len(run.status),
                "lost": run.n_lost,
                "keyframes": run.status.count("keyframe"), "status": list(run.status),
                "n_inliers": run.n_inliers.tolist(), "time_s_median": float(np.median(run.time_s))}
        from ..io import atomic_write

        with atomic_write(metrics_path) as tmp_path:
            tmp_path.write_text(json.dumps(data, indent=2))
    if plot_path is not None:
        curves = {"visual odometry": run.poses}
        shift = np.linalg.inv(given[0]) if start == "origin" else np.eye(4)
        if dataset.has_poses and (truth is None or not np.allclose(given, truth)):   # (a benchmark's are its truth)
            curves["given odometry"] = (shift @ given)[:, :3, 3]
        if truth is not None:
            curves["ground truth"] = ((np.linalg.inv(truth[0]) if start == "origin" else np.eye(4)) @ truth)[:, :3, 3]
        plot_trajectories(plot_path, curves, lost=~run.tracked, title=f"visual odometry, {len(run.status)} frames")
    click.echo(f"wrote {', '.join(str(p) for p in outputs.values() if p is not None)}")
    if viewers or record_bag is not None:
        from ..mapping.sinks import replay_odometry

        mount = dataset.mount.T_base_from_rectified((stereo or dataset.calibration).left.R) \
            if dataset.mount is not None else None
        replayed_to_sinks(lambda sinks: replay_odometry(stamps, run.T_world_from_base, sinks, T_base_from_cam=mount),
                          stereo or dataset.calibration, out_path.with_suffix(""), viewers, record_bag)


COMMANDS = [odometry_command]
