"""CLI: ``calib convert`` -- a calibration of another tool as mrstereo's stereo YAML.

Formats and detection: docs/calibration-formats.md.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

from pathlib import Path

import click

from ..camera import write_stereo
from ..camera.formats import import_calibration
from ..io import refuse_overwrite_input


def _image_size(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() and int(p) > 0 for p in parts):
        raise ValueError(f"--image-size must be WIDTHxHEIGHT in pixels, like 640x480, got {text!r}")
    return int(parts[0]), int(parts[1])


@click.group("calib")
def calib_group() -> None:
    """Import the calibration files of other tools."""


@calib_group.command("convert")
@click.argument("inputs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("-o", "--out", "output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Stereo YAML to write (.yaml or .yml).")
@click.option("--image-size", help="WIDTHxHEIGHT, for OpenCV files that do not store the image size.")
@click.option("--alpha", type=click.FloatRange(0.0, 1.0), default=0.0, show_default=True,
              help="Rectification of raw pairs: 0 keeps only valid pixels, 1 keeps every raw pixel.")
def convert_cmd(inputs, output: Path, image_size, alpha: float) -> None:
    """Write another tool's calibration as a stereo YAML.

    INPUTS is one file, or one file per camera (also written LEFT,RIGHT). The
    format is detected from the content: mrstereo/ROS stereo YAML, two ROS
    camera_info YAMLs, Kalibr camchain.yaml, OpenCV FileStorage (YAML/XML) of
    cv2.stereoCalibrate, two ASL/EuRoC sensor.yaml, OpenLORIS sensors.yaml
    (docs/calibration-formats.md). Raw pairs are rectified (Fusiello et al.
    2000). Example:

    mrstereo calib convert cam0/sensor.yaml cam1/sensor.yaml -o stereo.yaml
    """
    if output.suffix.lower() not in (".yaml", ".yml"):
        raise ValueError(f"--out must end in .yaml or .yml, got {output}")
    files = [part for item in inputs for part in (item.split(",") if not Path(item).exists() else [item])]
    refuse_overwrite_input(output, files)
    result = import_calibration(files, image_size=_image_size(image_size), alpha=alpha)
    write_stereo(output, result.stereo)
    s = result.stereo
    how = "rectified by mrstereo (Fusiello)" if result.rectified_here else "rectification from the file"
    click.echo(f"{', '.join(files)}: {result.format}; {s.size[0]}x{s.size[1]}, baseline {s.baseline_m:.4f} m, "
               f"rectified focal {s.focal_px:.2f} px, {how}")
    click.echo(f"wrote {output}")


COMMANDS = [calib_group]
