"""CLI of the whole chain: ``mrstereo map`` (a dataset to a ROS occupancy map).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

from pathlib import Path

import click

from ..pipeline.run import build_map
from ._bag import BAG_KEYS, opened_dataset, read_inputs, recording_of, recording_options
from ._live import check_sink_options, record_bag_option, replayed_to_sinks, viewer_option
from ._options import (check_workers, echo_map_warnings, echo_run_floor, library_default, map_config, map_options,
                       profile_option, worker_options)

__all__ = ["COMMANDS"]

MAP_FILES = ("map.yaml", "map.pgm", "map.png", "log_odds.npy", "metrics.json", "trajectory.txt", "tiles.npz",
             "overview.yaml", "overview.png")
"""What ``mrstereo map`` writes into its output folder (:func:`mrstereo.pipeline.write_map_outputs`)."""


@click.command("map")
@profile_option("read, rectify, match, reject, 3-D, free space, grid; with --odometry visual: odometry; "
                "with --align: align")
@click.argument("manifest", required=False, metavar="[RECORDING]", type=click.Path(path_type=Path))
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output directory (map.pgm, map.yaml, map.png, log_odds.npy, metrics.json).")
@click.option("--calib", "calib", type=click.Path(dir_okay=False, path_type=Path),
              help="Use this stereo calibration (and the raw images) instead of the recording's; the calibration "
                   "of image folders; with a bag, instead of the camera_info topics.")
@map_options
@click.option("--odometry", type=click.Choice(["auto", "given", "visual"]),
              default=library_default(build_map, "odometry"), show_default=True,
              help="Robot poses: the recording's (or the bag's odometry), or stereo visual odometry from the "
                   "first frame's pose (docs/odometry.md); auto: the recording's when it has some.")
@click.option("--align", is_flag=True,
              help="Correct the given poses with stereo visual odometry: each step of the given odometry fused "
                   "with the visual one by their expected errors (docs/odometry.md); the corrections go to "
                   "metrics.json.")
@worker_options
@recording_options
@viewer_option
@record_bag_option
@click.option("--resume-from", "prior_path", type=click.Path(dir_okay=False, path_type=Path),
              help="Continue mapping on this saved map (map.yaml of an earlier run, or any map_server map of "
                   "the same resolution): its occupied / free cells start at the sensor model's most certain "
                   "log-odds, its unknown cells unknown; the recording's poses must be in its frame. The map "
                   "written covers both.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def map_command(manifest: Path | None, out_dir: Path, calib: Path | None, odometry: str, align: bool,
                workers: int | None, scheduler: str | None, processes: bool, bag: Path | None, rate_hz: float | None,
                viewers: tuple[str, ...], record_bag: Path | None, prior_path: Path | None, quiet: bool,
                no_mount_check: bool, truth, **options) -> None:
    """Build an occupancy grid map from a recording.

    RECORDING is a dataset folder (docs/dataset.md), a KITTI odometry or
    EuRoC/ASL folder, a folder of left/right image folders (with --calib), or
    a ROS bag (docs/scale-out.md; its stereo topics are picked when it has one
    pair). `mrstereo info RECORDING` shows what is read.

    Every frame is rectified, matched (multi-range), ground-suppressed (eq. 13),
    triangulated and fused along the robot path. Writes a ROS map_server map
    (map.pgm + map.yaml), map.png with the path and fields of view, the
    log-odds array and metrics.json (floor, mount, points outside the map, and
    the comparison with a ground-truth map). The map grows to cover the path
    and what was seen, unless --size/--origin fix its window. A given camera
    mount is checked against the floor seen in the first frames.
    --workers N (threads, or processes with --processes) and --scheduler
    ADDRESS (a Dask cluster) spread the frames; the map is the same bit for bit.
    """
    from ..io import check_output_dir, check_outputs, staged_dir
    from ..evaluation.outputs import check_map, write_map_outputs

    check_workers(workers, scheduler, processes)
    if align and odometry == "visual":
        raise click.UsageError("--align corrects the given poses with visual odometry: not with --odometry visual")
    recording_of(manifest, bag)                          # one of them
    bag_kw = {k: options.pop(k) for k in list(options) if k in BAG_KEYS}
    config = map_config(**options)
    dataset, bag = read_inputs(manifest, bag, calib, rate_hz=rate_hz, truth=truth)    # read once: checked, mapped below
    if prior_path is not None:
        from ..mapping.rosmap import read_ros_map

        read_ros_map(prior_path)                             # a bad map refused before any work
    check_output_dir("--out", out_dir, may_hold_inputs=True)
    check_outputs({f"--out {out_dir / name}": out_dir / name for name in MAP_FILES})     # (names the file)
    inputs = [p for p in (bag if dataset is None else dataset.root, calib) if p is not None]
    viewers = check_sink_options(viewers, record_bag, out_dir / "view", inputs, output_dirs=[out_dir],
                                 stamps_s=None if dataset is None else dataset.stamps_s)
    with opened_dataset(dataset, bag, calib, quiet=quiet, bag_kw=bag_kw, rate_hz=rate_hz, truth=truth) as \
            (dataset, stereo, _):
        run = build_map(dataset, config=config, calibration=stereo, progress=not quiet, workers=workers,
                        scheduler=scheduler, processes=processes, odometry=odometry, align=align or None,
                        check_mount=not no_mount_check, keep_points=bool(viewers) or record_bag is not None,
                        prior=prior_path)
        echo_map_warnings(run)
        check_map(run)
        with staged_dir(out_dir, prefix="map") as staging:      # all files or none: Ctrl-C leaves the old set
            files = {key: out_dir / path.name for key, path in write_map_outputs(run, staging).items()}
    click.echo(f"map of {len(run.observations)} frames: {run.grid!r}")
    echo_run_floor(run.floor)
    if run.metrics is not None:
        m = run.metrics
        in_view = "" if m.recall_in_view != m.recall_in_view else f" ({m.recall_in_view:.3f} of the walls in view)"
        coverage = "" if m.free_coverage != m.free_coverage else f", free coverage {m.free_coverage:.3f}"
        click.echo(f"vs ground truth: precision {m.precision:.3f}, recall {m.recall:.3f}{in_view}, "
                   f"wall profile error {m.mean_distance_m * 100:.1f} cm, free correct {m.free_precision:.3f}"
                   f"{coverage}")
    if run.odometry:
        click.echo(f"visual odometry: {run.odometry['visual_odometry']['message']}")
    if run.fusion is not None:
        a = run.pose_metrics()["alignment"]
        click.echo(f"given odometry fused with visual odometry: {a['visual_steps']} of {a['frames'] - 1} steps "
                   f"measured visually ({a['rejected_visual_steps']} rejected), the poses moved by "
                   f"{100 * a['mean_correction_m']:.1f} cm / {a['mean_correction_deg']:.2f} deg on average")
    click.echo(f"wrote {', '.join(p.name for p in files.values())} to {out_dir}")
    if viewers or record_bag is not None:
        from ..mapping.sinks import replay_map_run

        replayed_to_sinks(lambda sinks: replay_map_run(run, sinks, config=config), run.manifest.calibration,
                          out_dir / "view", viewers, record_bag)


COMMANDS = [map_command]
