"""Options shared by several commands."""
from __future__ import annotations

import click


def worker_options(func):
    """``--workers N [--processes]`` / ``--scheduler ADDRESS`` (docs/scale-out.md)."""
    func = click.option("--processes", is_flag=True,
                        help="With --workers: worker processes instead of worker threads of this process.")(func)
    func = click.option("--scheduler", default=None, metavar="ADDRESS",
                        help="Run the work (frames, scenes) on an existing Dask cluster (tcp://host:8786); its "
                             "workers must see the same files.")(func)
    func = click.option("--workers", type=int, default=None,
                        help="Run the work (frames, scenes) on a local Dask cluster of N single-threaded workers "
                             "(default: in this process).")(func)
    return func


def check_workers(workers, scheduler, processes: bool = False) -> None:
    if workers is not None and scheduler is not None:
        raise click.UsageError("give --workers or --scheduler, not both")
    if processes and workers is None:
        raise click.UsageError("--processes only with --workers")
    if workers is not None and workers < 1:
        raise click.BadParameter(f"must be >= 1, got {workers}", param_hint="--workers")
