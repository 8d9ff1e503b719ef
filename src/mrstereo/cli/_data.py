"""CLI of the sample data: ``mrstereo data fetch|path|list`` (mrstereo.recordings.samples).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import click

__all__ = ["COMMANDS"]


@click.group("data")
def data_group() -> None:
    """Fetch and locate the public sample scenes.

    Middlebury, KITTI, OpenCV's chessboards and an OpenLORIS-Scene sample.

    Files are read from $MRSTEREO_DATA when it is set (a local copy, used as is),
    else from pooch's cache folder, where `mrstereo data fetch` downloads them and
    checks each file's SHA-256.
    """


def _names(names: tuple[str, ...]) -> tuple[str, ...]:
    from ..recordings.samples import SCENES, scene

    for name in names:
        scene(name)            # ValueError naming the unknown scene and the known ones
    return names or tuple(SCENES)


@data_group.command("fetch")
@click.argument("names", nargs=-1, metavar="[NAME...]")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def fetch_command(names: tuple[str, ...], quiet: bool) -> None:
    """Download sample scenes and print their folders.

    Downloads the scenes NAME... (default: all) unless they are there already.
    """
    from ..recordings.samples import fetch

    for name in _names(names):
        try:
            folder = fetch(name, progress=not quiet)
        except OSError as err:             # no network, DNS, refused, timed out (requests' errors are OSErrors)
            reason = str(getattr(err, "__cause__", None) or err).splitlines()[0][:160]
            raise OSError(f"could not download sample data {name!r} (offline?): {type(err).__name__}: {reason}; "
                          f"or set MRSTEREO_DATA to a local copy") from None
        click.echo(f"{name}: {folder}")


@data_group.command("path")
@click.argument("name", required=False)
def path_command(name: str | None) -> None:
    """Print the folder of a sample scene, or the data root.

    The folder of the scene NAME (or the data root without NAME). A scene
    that is not there (not fetched, or incomplete) is an error that names the
    fetch command.
    """
    from ..recordings.samples import data_root, local_path, missing_files

    if not name:
        click.echo(data_root())
        return
    missing = missing_files(_names((name,))[0])
    if missing:
        raise FileNotFoundError(f"sample data {name!r} is not here ({missing[0]} is missing): run "
                                f"`mrstereo data fetch {name}` first (or set MRSTEREO_DATA to a local copy)")
    click.echo(local_path(name))


@data_group.command("list")
@click.option("--verify", "check", is_flag=True, help="Also check every local file's SHA-256.")
def list_command(check: bool) -> None:
    """List the sample scenes, their sources and presence."""
    from ..recordings.samples import is_available, scene, verify

    problems = 0
    for name in _names(()):
        entry = scene(name)
        state = "present" if is_available(name) else "not fetched"
        if check and state == "present":
            issues = verify(name)
            problems += len(issues)
            state = "verified" if not issues else f"{len(issues)} file(s) differ"
        repos = sorted({f.repository for f in entry.files})
        click.echo(f"{name:26s} {state:12s} {len(entry.files):3d} files  {entry.folder}  "
                   f"{entry.description}; from {', '.join(repos)}")
    if problems:
        raise ValueError(f"{problems} local file(s) differ from the registry's SHA-256")


COMMANDS = [data_group]
