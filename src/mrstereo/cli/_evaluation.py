"""``mrstereo evaluate``: disparity accuracy on Middlebury / KITTI scenes, side by side with OpenCV.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

from pathlib import Path

import click

from ..evaluation.report import METHODS, evaluate_scenes
from ..io import atomic_write, check_outputs, note_read
from ..recordings.manifest import MANIFEST_NAME, read_manifest
from ._options import Number, check_workers, library_default, worker_options


def _write_text(path: Path, text: str) -> None:
    with atomic_write(path) as tmp:
        tmp.write_text(text, encoding="utf-8")


@click.command("evaluate")
@click.argument("dirs", nargs=-1, required=True, type=click.Path(path_type=Path))
@click.option("--methods", "-m", "methods", default=",".join(library_default(evaluate_scenes, "methods")),
              show_default=True,
              help=f"Comma-separated methods to run, some of: {', '.join(METHODS)}.")
@click.option("--json", "json_out", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write the full report as JSON here.")
@click.option("--markdown", "markdown_out", type=click.Path(dir_okay=False, path_type=Path),
              help="Also write the markdown tables here.")
@click.option("--max-disparity", "max_disparity", type=Number(1, 4096, integer=True, unit="px"), default=None,
              help="Disparity search range in pixels for every scene (default: each scene's ndisp or "
                   "ground-truth maximum rounded up to 16).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@worker_options
def evaluate(dirs, methods, json_out, markdown_out, max_disparity, quiet, workers, scheduler, processes):
    """Score stereo matchers against ground-truth disparity.

    Prints a markdown table of every method on every scene folder of DIRS.

    Each DIR is one scene -- Middlebury 2001/2003/2005/2006/2014 or KITTI 2012/2015, detected from
    its files -- or an mrstereo dataset (manifest.yaml, e.g. from `mrstereo synth`), whose frames
    with ground-truth disparity are scored one by one (docs/evaluation.md). Metrics are on
    non-occluded pixels where the dataset has a mask: bad-2 % dense (no estimate = bad), among
    estimated pixels, density and time.

    Example: mrstereo evaluate "$(mrstereo data path teddy)" corridor --json out.json
    """
    check_workers(workers, scheduler, processes)
    names = tuple(m.strip() for m in methods.split(",") if m.strip())
    unknown = [m for m in names if m not in METHODS]
    if not names or unknown:
        raise click.BadParameter(f"unknown method(s) {', '.join(unknown) or '(none given)'}; "
                                 f"choose from {', '.join(METHODS)}", param_hint="--methods")
    for d in dirs:
        if not d.exists():
            raise FileNotFoundError(f"scene directory not found: {d}")
        if not d.is_dir():
            raise ValueError(f"scene must be a directory, got the file {d}")
        note_read(d, folder=True, kind="scene")
        if (d / MANIFEST_NAME).is_file():
            read_manifest(d)            # its files, wherever they lie (a calibration beside the scene folder)
    check_outputs({"--json": json_out, "--markdown": markdown_out},
                  suffixes={"--json": (".json",), "--markdown": (".md", ".markdown", ".txt")})
    report = evaluate_scenes(dirs, methods=names, max_disparity_px=max_disparity, progress=not quiet,
                             workers=workers, scheduler=scheduler, processes=processes)
    markdown = report.to_markdown()
    if json_out is not None:
        _write_text(json_out, report.to_json())
    if markdown_out is not None:
        _write_text(markdown_out, markdown)
    click.echo(markdown, nl=False)


COMMANDS = [evaluate]
