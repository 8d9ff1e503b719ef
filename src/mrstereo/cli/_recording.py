"""CLI: ``mrstereo info`` -- what a recording holds, as the other commands will read it.

Conventions: docs/conventions.md; the layouts: docs/dataset.md.
"""
from __future__ import annotations

from pathlib import Path

import click

from ._options import Number

__all__ = ["COMMANDS"]


@click.command("info")
@click.argument("path", type=click.Path(path_type=Path))
@click.option("--calib", "calib", type=click.Path(dir_okay=False, path_type=Path),
              help="Calibration of a folder of image folders (any format `mrstereo calib convert` reads).")
@click.option("--rate", "rate_hz", type=Number(0.0, 1000.0, unit="Hz", open_low=True), default=None,
              help="Frame rate [Hz] of image folders whose file names are not time stamps.")
def info_command(path: Path, calib: Path | None, rate_hz: float | None) -> None:
    """Show what a recording holds and how it will be read.

    Frames, rate, image size, calibration, mount, truth and odometry.
    PATH is anything `mrstereo map` and `mrstereo odometry` read: a dataset
    folder, a KITTI odometry or EuRoC/ASL folder, a folder of left/right image
    folders, or a ROS bag (its topics, and the stereo pair picked). A folder of
    no known layout gets one line naming what was looked for.
    """
    from ..recordings.layouts import describe_recording, layout_of, read_recording

    layout = layout_of(path)
    if layout == "ROS bag":
        from ..recordings.bag import describe_bag

        lines = describe_bag(path)
    else:
        lines = describe_recording(read_recording(path, calibration=calib if layout == "image folders" else None,
                                                  rate_hz=rate_hz))
    width = max(len(what) for what, _ in lines)
    for what, value in lines:
        click.echo(f"{what + ':':<{width + 1}} {value}")


COMMANDS = [info_command]
