"""Options shared by several commands."""
from __future__ import annotations

import click


def worker_options(func):
    """``--workers N`` / ``--scheduler ADDRESS`` (docs/scale-out.md)."""
    func = click.option("--scheduler", default=None, metavar="ADDRESS",
                        help="Run the work (frames, scenes) on an existing Dask cluster (tcp://host:8786); its "
                             "workers must see the same files.")(func)
    func = click.option("--workers", type=int, default=None,
                        help="Run the work (frames, scenes) on a local Dask cluster of N worker processes "
                             "(default: in this process).")(func)
    return func


def check_workers(workers, scheduler) -> None:
    if workers is not None and scheduler is not None:
        raise click.UsageError("give --workers or --scheduler, not both")
    if workers is not None and workers < 1:
        raise click.BadParameter(f"must be >= 1, got {workers}", param_hint="--workers")
