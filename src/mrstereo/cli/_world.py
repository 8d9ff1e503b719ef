"""CLI of the synthetic world: ``mrstereo synth``.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from pathlib import Path

import click

from ..world.dataset import write_synthetic_dataset
from .._limits import limit
from ._options import SEED, Number, library_default, numbers

IMAGE_SIDE = Number(16, 8192, integer=True, unit="px")
"""``--width`` / ``--height`` of rendered images."""

__all__ = ["COMMANDS"]


@click.command("synth")
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(path_type=Path),
              help="New (or empty) dataset directory.")
@click.option("--seed", default=library_default(write_synthetic_dataset, "seed"), show_default=True,
              type=SEED,
              help="Texture and sensor-noise seed (with --randomize: the whole world).")
@click.option("--frames", "n_frames", default=library_default(write_synthetic_dataset, "n_frames"), show_default=True,
              type=Number(1, lambda: limit("MRSTEREO_MAX_FRAMES"), integer=True),
              help="Number of frames (with --path stops: front, +45 and -45 degree views at each stop).")
@click.option("--width", default=library_default(write_synthetic_dataset, "width"), show_default=True,
              type=IMAGE_SIDE, help="Image width.")
@click.option("--height", default=library_default(write_synthetic_dataset, "height"), show_default=True,
              type=IMAGE_SIDE, help="Image height.")
@click.option("--randomize", is_flag=True,
              help="A randomized world drawn from --seed (corridor, textures, lights, rig, sensors, "
                   "obstacles, path) instead of the built-in corridor.")
@click.option("--wall-texture", "wall_texture", type=click.Choice(["paint", "tiles", "stripes", "blotch", "wood"]),
              default=None,
              help="With --randomize: give the walls this material instead of the drawn one; everything else "
                   "stays the seed's world (e.g. stripes: a repetitive-texture variant).")
@click.option("--path", "path_kind", type=click.Choice(["stops", "front", "s-curve", "street"]),
              default=library_default(write_synthetic_dataset, "path"), show_default=True,
              help="stops: front/left/right views at each stop (mapping); front, s-curve: one front view every "
                   "--step metres (odometry sequences; with --randomize: front, along the world's own path); "
                   "street: a long street world (drawn from --seed) driven from a standstill up to --step metres "
                   "per frame, turning up to --turn degrees per frame.")
@click.option("--step", "step_m", type=Number(0.0, 10.0, unit="m", open_low=True),
              default=library_default(write_synthetic_dataset, "step_m"),
              show_default=True,
              help="Path length between frames of a front or s-curve sequence [m] (street: at full speed).")
@click.option("--turn", "turn_deg", type=Number(0.0, 90.0, unit="deg", open_high=True),
              default=round(math.degrees(library_default(write_synthetic_dataset, "turn_rad_per_frame")), 9),
              show_default=True, help="--path street: the largest heading change per frame at full speed [deg].")
@click.option("--rate", "rate_hz", type=Number(0.0, 1000.0, unit="Hz", open_low=True), default=library_default(write_synthetic_dataset, "frame_rate_hz"),
              show_default=True, help="Frames per second of a sequence (the frames' time stamps).")
@click.option("--odometry-noise", "odometry_noise", metavar="SCALE,DEG_PER_M", default=None,
              help="Store drifted odometry as each frame's pose (scale error, heading drift in degrees per "
                   "metre, e.g. 0.03,2) and the truth as true_pose.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def synth(out_dir: Path, seed: int, n_frames: int, width: int, height: int, randomize: bool,
          wall_texture: str | None, path_kind: str, step_m: float, turn_deg: float, rate_hz: float,
          odometry_noise: str | None, quiet: bool) -> None:
    """Render the synthetic corridor as a dataset.

    The dataset folder given by -o is laid out as docs/dataset.md describes; --path street
    renders a long street instead, driven at car speed (docs/world.md).

    Writes raw and rectified stereo pairs, ground-truth disparity (PFM) and
    labels, the true calibration, the ground-truth map and manifest.yaml.
    With --randomize the world itself is drawn from the seed (docs/world.md).
    """

    from ..io import check_output_dir

    if wall_texture is not None and not randomize:
        raise click.UsageError("--wall-texture needs --randomize")
    check_output_dir("--out", out_dir, must_be_empty=True)
    noise = None
    if odometry_noise is not None:
        scale, deg_per_m = numbers(odometry_noise, "--odometry-noise", 2, -90.0, 90.0,
                                   what="'scale,deg_per_m' (e.g. 0.03,2)")
        if abs(scale) > 0.5:
            raise click.BadParameter(f"the scale error must be in [-0.5, 0.5], got {scale:g}",
                                     param_hint="--odometry-noise")
        noise = (scale, math.radians(deg_per_m))
    if randomize and path_kind == "street":
        raise click.UsageError("--path street has its own world: not with --randomize")
    path = write_synthetic_dataset(out_dir, seed=seed, n_frames=n_frames, width=width, height=height,
                                   path=path_kind, step_m=step_m, odometry_noise=noise, progress=not quiet,
                                   randomize=randomize, wall_texture=wall_texture,
                                   turn_rad_per_frame=math.radians(turn_deg), frame_rate_hz=rate_hz)
    click.echo(f"wrote {n_frames} frames to {path} (manifest: {path / 'manifest.yaml'})")


COMMANDS = [synth]
