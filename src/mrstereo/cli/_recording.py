"""CLI: ``mrstereo info`` -- what a recording holds, as the other commands will read it.

Conventions: docs/conventions.md; the layouts: docs/dataset.md.
"""
from __future__ import annotations

from pathlib import Path

import click

from ._options import Number, truth_option

__all__ = ["COMMANDS"]


@click.command("info")
@click.argument("path", type=click.Path(path_type=Path))
@click.option("--calib", "calib", type=click.Path(dir_okay=False, path_type=Path),
              help="Calibration of a folder of image folders or of a bag without camera_info (any format "
                   "`mrstereo calib convert` reads).")
@click.option("--rate", "rate_hz", type=Number(0.0, 1000.0, unit="Hz", open_low=True), default=None,
              help="Frame rate [Hz] of image folders whose file names are not time stamps.")
@truth_option
def info_command(path: Path, calib: Path | None, rate_hz: float | None, truth) -> None:
    """Show what a recording holds and how it will be read.

    Frames, rate, image size, calibration, mount, truth and odometry.
    PATH is anything `mrstereo map` and `mrstereo odometry` read: a dataset
    folder, a KITTI odometry, KITTI raw or EuRoC/ASL folder, a folder of
    left/right image folders, or a ROS bag (also its topics and the stereo
    pair picked; nothing is exported). A folder of no known layout gets one
    line naming what was looked for.
    """
    from ..recordings.layouts import describe_recording, layout_of, open_recording

    layout = layout_of(path)
    if layout == "ROS bag":
        from ..recordings.bag import describe_bag

        topics = describe_bag(path)
        try:
            source = open_recording(path, calibration=calib, truth=truth)
        except ValueError as exc:                      # no pair, no calibration: the topics say what there is
            lines = topics + [("note", str(exc))]
        else:
            with source:
                lines = describe_recording(source) + [
                    ("stereo pair", f"{source.left_topic}, {source.right_topic} ({source.n_left} left, "
                                    f"{source.n_right} right images)"),
                    ("poses from", source.pose_source), ("mount from", source.mount_source)] + \
                    [line for line in topics if line[0] in ("duration", "topic")]
    else:
        with open_recording(path, calibration=calib if layout == "image folders" else None,
                            rate_hz=rate_hz, truth=truth) as source:
            lines = describe_recording(source)
    width = max(len(what) for what, _ in lines)
    for what, value in lines:
        click.echo(f"{what + ':':<{width + 1}} {value}")


COMMANDS = [info_command]
