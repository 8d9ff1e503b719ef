"""CLI: ``mrstereo disparity`` (multi-range matching, docs/matching.md).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from pathlib import Path

import click

from .._interrupt import reached
from ._options import CALIB_HELP, MAX_DISPARITY, profile_option

MAX_DEPTH_M = 1000.0
"""The farthest depth band edge of ``--depth-bands`` [m]."""

__all__ = ["COMMANDS"]


def _float_list(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ValueError(f"{what} must be comma-separated numbers, got {text!r}") from None
    if not values or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{what} must be finite numbers, got {text!r}")
    return values


def _bands(text: str) -> list[tuple[float, float]]:
    bands = []
    for item in text.split(","):
        parts = item.split(":")
        if len(parts) != 2:
            raise ValueError(f"--bands must look like 0:24,24:48,48:96, got {text!r}")
        lo, hi = _float_list(parts[0], "--bands")[0], _float_list(parts[1], "--bands")[0]
        high = MAX_DISPARITY.bounds()[1]
        if not 0 <= lo < hi <= high:
            raise ValueError(f"--bands need 0 <= low < high <= {high:g} px, got {item!r}")
        bands.append((lo, hi))
    return bands


@click.command("disparity")
@profile_option("read, rectify, match")
@click.argument("left", type=click.Path(dir_okay=False))
@click.argument("right", type=click.Path(dir_okay=False))
@click.option("-o", "--out", "output", required=True, type=click.Path(dir_okay=False),
              help="Disparity output: .pfm (Middlebury, inf invalid) or .png (KITTI uint16 x256).")
@click.option("--max-disparity", type=MAX_DISPARITY,
              help="Search 0..N px (split into ranges N/4, N/2, N at decimations 4, 2, 1; fewer levels "
                   "for N < 32).")
@click.option("--bands", help="Disparity bands in full-resolution px, e.g. 0:24,24:48,48:96.")
@click.option("--calib", type=click.Path(dir_okay=False), help=CALIB_HELP)
@click.option("--depth-bands", help="Depth band edges in metres, e.g. 0.5,1,2.5,15 (needs --calib).")
@click.option("--rectified", is_flag=True, help="With --calib: the images are already rectified.")
@click.option("--preset", type=click.Choice(["robust", "mapping", "paper"]), default="robust", show_default=True,
              help="Matcher preset (docs/glossary.md): robust for dense disparity, mapping as map/points/scan "
                   "use it, paper for eq. 9-12 exactly.")
@click.option("--single-range", is_flag=True, help="One full-resolution search instead of three ranges.")
@click.option("--no-fill", is_flag=True, help="Leave holes as holes: no gap filling (robust preset).")
@click.option("--aoi", help="Area of interest row0:row1,col0:col1 (half-open).")
@click.option("--explain", is_flag=True,
              help="Print the multi-range plan (levels, bands, work) and the share of too-near pixels.")
@click.option("--plot", "color_path", type=click.Path(dir_okay=False),
              help="Also write a colour preview PNG with a colour bar in pixels (black: no value; "
                   "magenta: too near).")
def disparity(left, right, output, max_disparity, bands, calib, depth_bands, rectified, preset,
              single_range, no_fill, aoi, explain, color_path):
    """Compute the multi-range disparity of a stereo pair.

    Matches on three horizontal resolutions (paper section 3). LEFT and RIGHT
    are a raw pair rectified with --calib, or a rectified pair
    (--rectified, or without --calib). The search is --max-disparity, --bands,
    --depth-bands or, with --calib alone, the depth bands 0.5-1, 1-2.5 and
    2.5-15 m (docs/matching.md). Writes a Middlebury PFM or a KITTI 16-bit PNG.
    """
    from .. import io
    from ..matching import compute_disparity, preset_config
    from ..profiling import stage

    if bands is not None and max_disparity is not None:
        raise ValueError("give --max-disparity or --bands, not both")
    if calib is None and max_disparity is None and bands is None:
        raise ValueError("give --max-disparity N, --bands, or --calib stereo.yaml")
    if depth_bands is not None and calib is None:
        raise ValueError("--depth-bands needs --calib")
    if depth_bands is not None and (max_disparity is not None or bands is not None):
        raise ValueError("give --depth-bands or a disparity search, not both")
    stereo = None
    if calib is not None:
        from ..camera import read_stereo
        stereo = read_stereo(calib)
    io.check_outputs({"--out": output, "--plot": color_path}, [left, right, calib],
                     suffixes={"--out": (".pfm", ".png"), "--plot": (".png",)})
    aoi_box = None
    if aoi is not None:
        try:
            rows, cols = aoi.split(",")
            aoi_box = tuple(int(v) for v in rows.split(":") + cols.split(":"))
        except ValueError:
            raise ValueError(f"--aoi must look like row0:row1,col0:col1, got {aoi!r}") from None
        if any(v < 0 for v in aoi_box):
            raise ValueError(f"--aoi rows and columns must be >= 0, got {aoi!r}")
    band_list = _bands(bands) if bands is not None else None
    depth_list = _float_list(depth_bands, "--depth-bands") if depth_bands is not None else None
    if depth_list is not None and not all(0 < d <= MAX_DEPTH_M for d in depth_list):
        raise ValueError(f"--depth-bands edges must be in (0, {MAX_DEPTH_M:g}] m, got {depth_bands!r}")

    with stage("read"):
        left_img = io.matching_image(io.read_image(left))
        right_img = io.matching_image(io.read_image(right))
    if left_img.shape[:2] != right_img.shape[:2]:
        raise ValueError(f"left and right images differ in size: {left_img.shape[1]}x{left_img.shape[0]} "
                         f"and {right_img.shape[1]}x{right_img.shape[0]}")
    raw = stereo is not None and not rectified and not stereo.is_rectified
    from ..rejection.streams import warn_pair

    warn_pair(left_img, right_img, stereo, rectified=not raw)
    if raw:
        with stage("rectify"):
            left_img, right_img = stereo.rectify(left_img, right_img)
    config = preset_config(preset)
    if single_range:
        config = config.replace(search={"multi_range": False})
    if no_fill:
        config = config.replace(postfilter={"gap_fill_px": 0})
    reached("frame")
    with stage("match"):
        result = compute_disparity(left_img, right_img, max_disparity_px=max_disparity, disparity_bands_px=band_list,
                                   calibration=stereo, depth_bands_m=depth_list, config=config, aoi=aoi_box)
    valid = float((result.disparity_px == result.disparity_px).mean())
    too_near = float(result.too_near.mean())
    if explain:
        click.echo(result.plan.describe())
        limit = f"match beyond {result.near_limit_px:.1f} px"
        if stereo is not None:
            limit += f", nearer than {stereo.baseline_m * stereo.focal_px / (result.near_limit_px + stereo.doffs_px):.2f} m"
        click.echo(f"valid {valid:.1%} of pixels; too near ({limit}; no value) {too_near:.1%}")
    io.write_disparity(output, result.disparity_px)
    if color_path:
        from ..viz.plot import save_disparity_preview

        save_disparity_preview(color_path, result.disparity_px, title=f"disparity of {Path(left).name}",
                               too_near=result.too_near)
    click.echo(f"wrote {output}: {valid:.0%} of pixels with a disparity"
               + (f", {too_near:.0%} too near (nearer than the search)" if too_near > 0 else ""), err=True)


COMMANDS = [disparity]
