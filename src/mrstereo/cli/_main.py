"""The ``mrstereo`` click group with every command (imported by :func:`mrstereo.cli.entry`).

A command's module is imported when the command runs (or is listed by ``--help``), not before:
``mrstereo map`` does not import what ``calibrate``, ``evaluate`` or ``export`` need.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import importlib

import click

__all__ = ["main", "COMMAND_MODULES"]

COMMAND_MODULES = {
    "synth": "_world", "calibrate": "_calibration", "stereo-calibrate": "_calibration", "rectify": "_calibration",
    "calib": "_formats", "disparity": "_matching", "evaluate": "_evaluation", "points": "_geometry",
    "scan": "_geometry", "plan": "_mapping", "map": "_pipeline", "demo": "_demo", "export": "_bag",
    "batch": "_bag", "data": "_data", "odometry": "_odometry", "info": "_recording", "live": "_live",
    "warm-up": "_warmup",
}
"""Command name -> the module of ``mrstereo.cli`` that defines it (in its ``COMMANDS`` list)."""


class _LazyGroup(click.Group):
    """A group that imports a command's module on first use (``COMMAND_MODULES``).

    ``commands`` (the dict click's own Group keeps) imports them all, for code that walks it.
    """

    @property
    def commands(self) -> dict:
        for name in COMMAND_MODULES:
            self.get_command(None, name)
        return self._loaded

    @commands.setter
    def commands(self, value) -> None:
        self._loaded = dict(value)

    def list_commands(self, ctx) -> list[str]:
        return sorted(COMMAND_MODULES)

    def get_command(self, ctx, cmd_name: str):
        if cmd_name not in self._loaded and cmd_name in COMMAND_MODULES:
            for command in importlib.import_module(f"{__package__}.{COMMAND_MODULES[cmd_name]}").COMMANDS:
                self._loaded.setdefault(command.name, command)
        return self._loaded.get(cmd_name)


@click.group(cls=_LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="mrstereo")
def main() -> None:
    """mrstereo: multi-range stereo vision for mobile robot navigation."""
