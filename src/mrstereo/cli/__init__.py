"""Command-line interface: parse, validate, call one library function per command.

Every failure the user can fix (missing file, bad YAML, mismatched images,
NaN parameter) ends as one line ``mrstereo: error: ...`` and exit code 2.
"""
from __future__ import annotations

import importlib
import sys

import click

_COMMAND_MODULES = ("_world", "_calibration", "_formats", "_matching", "_evaluation", "_geometry", "_mapping", "_pipeline", "_demo", "_bag",
                    "_data")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="mrstereo")
def main() -> None:
    """mrstereo: multi-range stereo vision for mobile robot navigation."""


for _name in _COMMAND_MODULES:
    for _command in importlib.import_module(f"{__name__}.{_name}").COMMANDS:
        main.add_command(_command)


def entry(argv: list[str] | None = None) -> int:
    """Console-script entry point: run the CLI, turn errors into one line."""
    from ..parallel import keep_freed_memory

    keep_freed_memory()          # this process is ours: no page faults on every frame's arrays
    try:
        main.main(args=argv, prog_name="mrstereo", standalone_mode=False)
    except click.exceptions.Abort:
        click.echo("mrstereo: aborted", err=True)
        return 130
    except click.ClickException as exc:
        exc.show()
        return exc.exit_code
    except (ValueError, TypeError, OSError, RuntimeError) as exc:
        message = str(exc) or type(exc).__name__
        if isinstance(exc, FileNotFoundError) and exc.filename and str(exc.filename) not in message:
            message = f"file not found: {exc.filename}"
        click.echo(f"mrstereo: error: {message}", err=True)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(entry())
