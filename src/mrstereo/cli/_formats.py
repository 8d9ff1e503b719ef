"""CLI: ``calib convert`` -- a calibration of another tool as mrstereo's stereo YAML.

Formats and detection: docs/calibration-formats.md.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

from pathlib import Path

import click

from ..camera import write_stereo
from ..camera.formats import import_calibration
from ..io import check_outputs
from ._options import MAX_IMAGE_SIDE, Number


def _image_size(text: str | None) -> tuple[int, int] | None:
    if text is None:
        return None
    parts = text.lower().split("x")
    if len(parts) != 2 or not all(p.strip().isdigit() and 0 < int(p) <= MAX_IMAGE_SIDE for p in parts):
        raise ValueError(f"--image-size/--size must be WIDTHxHEIGHT in pixels (1 to {MAX_IMAGE_SIDE} each), like "
                         f"640x480, got {text!r}")
    return int(parts[0]), int(parts[1])


@click.group("calib")
def calib_group() -> None:
    """Import the calibration files of other tools."""


@calib_group.command("convert")
@click.argument("inputs", nargs=-1, type=click.Path(dir_okay=False))
@click.option("-o", "--out", "output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Stereo YAML to write (.yaml or .yml).")
@click.option("--image-size", "--size", "image_size", metavar="WxH",
              help="Image size in pixels: of a pre-rectified camera (--fx ...), or of OpenCV files that do not "
                   "store it.")
@click.option("--alpha", type=Number(0.0, 1.0), default=0.0, show_default=True,
              help="Rectification of raw pairs: 0 keeps only valid pixels, 1 keeps every raw pixel.")
@click.option("--fx", type=Number(0.0, 1e6, unit="px", open_low=True),
              help="Pre-rectified camera (no INPUTS): focal length [px] of the rectified images.")
@click.option("--fy", type=Number(0.0, 1e6, unit="px", open_low=True),
              help="Pre-rectified camera: vertical focal length [px] (default: --fx).")
@click.option("--cx", type=Number(-1e6, 1e6, unit="px"),
              help="Pre-rectified camera: principal point x [px].")
@click.option("--cy", type=Number(-1e6, 1e6, unit="px"),
              help="Pre-rectified camera: principal point y [px].")
@click.option("--baseline", "baseline_m", type=Number(0.0, 1e3, unit="m", open_low=True),
              help="Pre-rectified camera: baseline [m] (OAK-D 0.075).")
def convert_cmd(inputs, output: Path, image_size, alpha: float, **numbers) -> None:
    """Write another tool's calibration as a stereo YAML.

    INPUTS is one file, or one file per camera (also written LEFT,RIGHT). The
    format is detected from the content: mrstereo/ROS stereo YAML, two ROS
    camera_info YAMLs, Kalibr camchain.yaml, OpenCV FileStorage (YAML/XML) of
    cv2.stereoCalibrate, two ASL/EuRoC sensor.yaml, OpenLORIS sensors.yaml
    (docs/calibration-formats.md). Raw pairs are rectified (Fusiello et al.
    2000). Examples:

    mrstereo calib convert cam0/sensor.yaml cam1/sensor.yaml -o stereo.yaml

    A camera that delivers rectified pairs (OAK-D/DepthAI, ZED, RealSense)
    needs no file, only the rectified focal length, principal point, baseline
    and image size:

    mrstereo calib convert --fx 798.3 --cx 640.1 --cy 360.4 --baseline 0.075 --size 1280x720 -o stereo.yaml
    """
    check_outputs({"--out": output}, suffixes={"--out": (".yaml", ".yml")})
    if inputs and any(v is not None for v in numbers.values()):
        raise click.UsageError("give calibration files (INPUTS) or the numbers of a pre-rectified camera (--fx, "
                               "--cx, --cy, --baseline, --size), not both")
    if not inputs:
        stereo = _prerectified(image_size=_image_size(image_size), **numbers)
        write_stereo(output, stereo)
        click.echo(f"pre-rectified pair: {stereo.size[0]}x{stereo.size[1]}, focal {stereo.focal_px:.2f} px, baseline "
                   f"{stereo.baseline_m:.4f} m (P_right[0,3] = -fx baseline = {stereo.right.P[0, 3]:.3f})")
        click.echo(f"wrote {output}")
        return
    files = [part for item in inputs for part in (item.split(",") if not Path(item).exists() else [item])]
    size = _image_size(image_size)
    check_outputs({"--out": output}, files, suffixes={"--out": (".yaml", ".yml")})
    result = import_calibration(files, image_size=size, alpha=alpha)      # (reads siblings: trans_matrix.yaml)
    check_outputs({"--out": output}, files)
    write_stereo(output, result.stereo)
    s = result.stereo
    how = "rectified by mrstereo (Fusiello)" if result.rectified_here else "rectification from the file"
    click.echo(f"{', '.join(files)}: {result.format}; {s.size[0]}x{s.size[1]}, baseline {s.baseline_m:.4f} m, "
               f"rectified focal {s.focal_px:.2f} px, {how}")
    click.echo(f"wrote {output}")


def _prerectified(*, image_size, fx, fy, cx, cy, baseline_m):
    """The :meth:`~mrstereo.camera.StereoCamera.ideal` pair of the numbers of a pre-rectified camera."""
    from ..camera import Camera, StereoCamera

    given = {"--fx": fx, "--cx": cx, "--cy": cy, "--baseline": baseline_m, "--size": image_size}
    missing = [name for name, value in given.items() if value is None]
    if missing:
        raise click.UsageError(f"a pre-rectified camera needs --fx, --cx, --cy, --baseline and --size (missing "
                               f"{', '.join(missing)}), or give calibration files")
    if baseline_m > 5.0:        # factory files give millimetres (ZED) or centimetres (DepthAI)
        raise click.BadParameter(f"is in metres, got {baseline_m:g} (millimetres or centimetres?)",
                                 param_hint="--baseline")
    width, height = image_size
    for name, value, extent in (("--cx", cx, width), ("--cy", cy, height)):
        if not 0.0 <= value <= extent:      # a principal point off the image: a typo or another image size
            raise click.BadParameter(f"{value:g} px is outside the image (0 to {extent} px for --size "
                                     f"{width}x{height})", param_hint=name)
    camera = Camera(width=width, height=height, fx=fx, fy=fx if fy is None else fy, cx=cx, cy=cy)
    return StereoCamera.ideal(camera, baseline_m)


COMMANDS = [calib_group]
