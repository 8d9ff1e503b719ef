"""CLI of the compile step: ``mrstereo warm-up`` (:func:`mrstereo._warmup.warm_up`).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import click

__all__ = ["COMMANDS"]


@click.command("warm-up")
def warm_up_command() -> None:
    """Compile the per-frame chain's numba kernels now, once.

    numba compiles each kernel on first use and caches it beside the sources: a fresh
    install's first run spends minutes compiling (the message below says so), later
    runs load the kernels in seconds. Run it after installing (e.g. when building a
    robot's image) so that the first frame of `live`, `map` or `batch` is fast.
    """
    from .._warmup import warm_up

    seconds = warm_up(say=lambda line: click.echo(line, err=True))
    click.echo(f"kernels ready ({seconds:.1f} s)")


COMMANDS = [warm_up_command]
