"""CLI of the main job: ``mrstereo demo``.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

from pathlib import Path

import click

from ..demo import MAX_DEMO_FRAMES, run_demo
from ._options import SEED, Number, library_default

__all__ = ["COMMANDS"]


@click.command("demo")
@click.option("-o", "--out", "out_dir", default=library_default(run_demo, "out_dir"), show_default=True,
              type=click.Path(path_type=Path),
              help="Report directory (must not exist or be empty).")
@click.option("--seed", default=library_default(run_demo, "seed"), show_default=True, type=SEED,
              help="Seed of the world's textures and noise and of the GA.")
@click.option("--frames", "n_frames", default=library_default(run_demo, "n_frames"), show_default=True,
              type=Number(1, MAX_DEMO_FRAMES, integer=True),
              help="Frames of the corridor sequence (front, +45 and -45 degree views per stop).")
@click.option("--randomize", is_flag=True,
              help="A randomized world drawn from --seed instead of the built-in corridor (docs/world.md).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def demo_command(out_dir: Path, seed: int, n_frames: int, randomize: bool, quiet: bool) -> None:
    """Run the whole pipeline on the built-in corridor.

    Renders the corridor, calibrates the rig from rendered chessboards (GA + LM),
    rectifies, matches multi-range, suppresses the ground, maps along the path,
    plans a path through the map, and compares every stage with ground truth
    in report.md and metrics.json, with its figures.
    """
    from ..io import staged_new_dir

    with staged_new_dir(out_dir, option="--out") as tmp:        # the report complete or not at all
        result = run_demo(tmp / "report", seed=seed, n_frames=n_frames, progress=not quiet,
                          randomize=randomize)
        for item in (tmp / "report").iterdir():
            item.rename(tmp / item.name)
    report = out_dir / result.report.relative_to(tmp / "report")
    m = result.metrics
    c, g = m["calibration"], m.get("map") or {}
    click.echo(f"calibration: RMS {c['rms_px']:.3f} px, focal error {c['focal_error_pct']:+.2f} %, "
               f"rectified |dy| {c['rectified_vertical_error_px']:.3f} px")
    if g:
        click.echo(f"map vs ground truth: precision {g['precision']:.3f}, recall {g['recall']:.3f}, "
                   f"wall profile error {100 * g['mean_distance_m']:.1f} cm")
    p = m["plan"]
    click.echo("planned path: " + (f"{p['length_m']:.2f} m" if p["success"] else p["message"]))
    click.echo(f"report: {report.resolve()}")


COMMANDS = [demo_command]
