"""CLI of the synthetic world: ``mrstereo synth``."""
from __future__ import annotations

from pathlib import Path

import click

__all__ = ["COMMANDS"]


@click.command("synth")
@click.option("--out", "out_dir", required=True, type=click.Path(path_type=Path),
              help="New (or empty) dataset directory.")
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0),
              help="Texture and sensor-noise seed (with --randomize: the whole world).")
@click.option("--frames", "n_frames", default=30, show_default=True, type=click.IntRange(min=1),
              help="Number of frames (front, +45 and -45 degree views at each stop).")
@click.option("--width", default=320, show_default=True, type=click.IntRange(min=16), help="Image width.")
@click.option("--height", default=240, show_default=True, type=click.IntRange(min=16), help="Image height.")
@click.option("--randomize", is_flag=True,
              help="A randomized world drawn from --seed (corridor, textures, lights, rig, sensors, "
                   "obstacles, path) instead of the built-in corridor.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def synth(out_dir: Path, seed: int, n_frames: int, width: int, height: int, randomize: bool, quiet: bool) -> None:
    """Render the synthetic office corridor into a dataset directory (docs/dataset.md).

    Writes raw and rectified stereo pairs, ground-truth disparity (PFM) and
    labels, the true calibration, the ground-truth map and manifest.yaml.
    With --randomize the world itself is drawn from the seed (docs/world.md).
    """
    from ..io import check_output_dir
    from ..world.dataset import write_synthetic_dataset

    check_output_dir("--out", out_dir, must_be_empty=True)
    path = write_synthetic_dataset(out_dir, seed=seed, n_frames=n_frames, width=width, height=height,
                                   progress=not quiet, randomize=randomize)
    click.echo(f"wrote {n_frames} frames to {path} (manifest: {path / 'manifest.yaml'})")


COMMANDS = [synth]
