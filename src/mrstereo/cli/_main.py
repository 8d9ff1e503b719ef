"""The ``mrstereo`` click group with every command (imported by :func:`mrstereo.cli.entry`)."""
from __future__ import annotations

import importlib

import click

__all__ = ["main"]

_COMMAND_MODULES = ("_world", "_calibration", "_formats", "_matching", "_evaluation", "_geometry", "_mapping",
                    "_pipeline", "_demo", "_bag", "_data", "_odometry")


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="mrstereo")
def main() -> None:
    """mrstereo: multi-range stereo vision for mobile robot navigation."""


for _name in _COMMAND_MODULES:
    for _command in importlib.import_module(f"{__package__}.{_name}").COMMANDS:
        main.add_command(_command)
