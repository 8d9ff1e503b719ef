"""CLI of the whole chain: ``mrstereo map`` (a dataset to a ROS occupancy map).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

from pathlib import Path

import click

from ..mapping import GridSpec, MappingConfig
from ..pipeline.run import PipelineConfig, build_map
from ._bag import bag_options, opened_dataset
from ._live import check_sink_options, record_bag_option, replayed_to_sinks, viewer_option
from ._options import check_workers, echo_run_floor, library_default, profile_option, worker_options

__all__ = ["COMMANDS"]

MAP_FILES = ("map.yaml", "map.pgm", "map.png", "log_odds.npy", "metrics.json")
"""What ``mrstereo map`` writes into its output folder (:func:`mrstereo.pipeline.write_map_outputs`)."""


@click.command("map")
@profile_option("read, rectify, match, reject, 3-D, free space, grid; with --odometry visual: odometry; "
                "with --align: align")
@click.argument("manifest", required=False, metavar="[DATASET]", type=click.Path(path_type=Path))
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output directory (map.pgm, map.yaml, map.png, log_odds.npy, metrics.json).")
@click.option("--calib", "calib", type=click.Path(dir_okay=False, path_type=Path),
              help="Use this stereo calibration (and the raw images) instead of the manifest's; "
                   "with --bag, instead of the camera_info topics.")
@click.option("--fusion", type=click.Choice(["log_odds", "union"]), default=MappingConfig.fusion, show_default=True,
              help="Log-odds fusion (OctoMap) or the paper's union of occupied cells.")
@click.option("--preset", type=click.Choice(["mapping", "robust", "paper"]), default=PipelineConfig.preset,
              show_default=True, help="Matching preset.")
@click.option("--resolution", "resolution_m", type=float, default=GridSpec.resolution_m, show_default=True,
              help="Cell size [m].")
@click.option("--size", "size_m", default=f"{GridSpec.width_m:g},{GridSpec.height_m:g}", show_default=True,
              metavar="W,H", help="Map width (x) and height (y) [m].")
@click.option("--origin", "origin_m", default=f"{GridSpec.origin_x_m:g},{GridSpec.origin_y_m:g}", show_default=True,
              metavar="X,Y", help="World position of the lower-left map corner [m].")
@click.option("--odometry", type=click.Choice(["given", "visual"]), default=library_default(build_map, "odometry"),
              show_default=True,
              help="Robot poses: the dataset's (or the bag's odometry), or stereo visual odometry from the "
                   "first frame's pose (docs/odometry.md).")
@click.option("--align", is_flag=True,
              help="Correct the given poses with stereo visual odometry: each step of the given odometry fused "
                   "with the visual one by their expected errors (docs/odometry.md); the corrections go to "
                   "metrics.json.")
@worker_options
@click.option("--bag", "bag", type=click.Path(path_type=Path),
              help="Map a ROS 1 .bag / ROS 2 bag directory instead of a DATASET (see the topic options).")
@bag_options
@viewer_option
@record_bag_option
@click.option("--quiet", is_flag=True, help="No progress bar.")
def map_command(manifest: Path | None, out_dir: Path, calib: Path | None, fusion: str, preset: str,
                resolution_m: float, size_m: str, origin_m: str, odometry: str, align: bool, workers: int | None,
                scheduler: str | None, processes: bool, bag: Path | None, viewers: tuple[str, ...],
                record_bag: Path | None, quiet: bool, **bag_kw) -> None:
    """Build an occupancy grid map from a recording or a ROS bag.

    DATASET is a dataset folder or its manifest.yaml (docs/dataset.md) or a KITTI odometry
    folder; --bag maps a ROS bag instead (docs/scale-out.md).

    Every frame is rectified, matched (multi-range), ground-suppressed (eq. 13),
    triangulated and fused along the robot path. Writes a ROS map_server map
    (map.pgm + map.yaml), map.png with the path and fields of view, the
    log-odds array and, when the manifest has a ground-truth map, metrics.json.
    --workers N (threads, or processes with --processes) and --scheduler
    ADDRESS (a Dask cluster) spread the frames; the map is the same bit for bit.
    """
    from ..io import check_output_dir, check_outputs, remove_stale_temporaries, staged_dir
    from ..pipeline.batch import dataset_files
    from ..pipeline.run import write_map_outputs
    from ..recordings.layouts import read_recording

    check_workers(workers, scheduler, processes)
    if align and odometry == "visual":
        raise click.UsageError("--align corrects the given poses with visual odometry: not with --odometry visual")
    if (manifest is None) == (bag is None):
        raise click.UsageError("give a DATASET or --bag FILE (one of them)")
    (width, height), (ox, oy) = _pair(size_m, "--size"), _pair(origin_m, "--origin")
    grid = GridSpec(width_m=width, height_m=height, resolution_m=resolution_m, origin_x_m=ox, origin_y_m=oy)
    config = PipelineConfig(preset=preset, grid=grid).with_fusion(fusion)
    check_output_dir("--out", out_dir)
    outputs = {f"--out {out_dir / name}": out_dir / name for name in MAP_FILES}     # (names the file)
    if bag is not None:
        inputs = [bag, calib]
        check_outputs(outputs, inputs, input_dirs=[bag] if bag.is_dir() else [])
    else:
        dataset = read_recording(manifest)           # read once: checked here, mapped below
        inputs = [manifest, calib] + dataset_files(dataset)
        check_outputs(outputs, inputs)
        manifest = dataset
    viewers = check_sink_options(viewers, record_bag, out_dir / "view", inputs, output_dirs=[out_dir])
    with opened_dataset(manifest, bag, calib, quiet=quiet, bag_kw=bag_kw) as (dataset, stereo, _):
        run = build_map(dataset, config=config, calibration=stereo, progress=not quiet, workers=workers,
                        scheduler=scheduler, processes=processes, odometry=odometry, align=align or None)
        remove_stale_temporaries(out_dir)
        with staged_dir(out_dir, prefix="map") as staging:      # all files or none: a kill leaves the old set
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
    if run.odometry is not None:
        click.echo(f"visual odometry: {run.odometry.message}")
    if run.fusion is not None:
        a = run.pose_metrics()["alignment"]
        click.echo(f"given odometry fused with visual odometry: {a['visual_steps']} of {a['frames'] - 1} steps "
                   f"measured visually ({a['rejected_visual_steps']} rejected), the poses moved by "
                   f"{100 * a['mean_correction_m']:.1f} cm / {a['mean_correction_deg']:.2f} deg on average")
    click.echo(f"wrote {', '.join(p.name for p in files.values())} to {out_dir}")
    if viewers or record_bag is not None:
        from ..pipeline.sinks import replay_map_run

        replayed_to_sinks(lambda sinks: replay_map_run(run, sinks, config=config), run.manifest.calibration,
                          out_dir / "view", viewers, record_bag)


def _pair(text: str, option: str) -> tuple[float, float]:
    try:
        a, b = (float(v) for v in text.split(","))
    except ValueError:
        raise click.BadParameter(f"expected two numbers 'a,b', got {text!r}", param_hint=option) from None
    return a, b


COMMANDS = [map_command]
