"""CLI of the mapping stage: ``mrstereo plan`` (A* on a ROS map).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import json
from pathlib import Path

import click

from ..io import atomic_write, check_outputs
from ..mapping.planning import plan_path
from ..mapping.rosmap import ros_map_files
from ._options import Number, library_default, numbers


MAX_COORDINATE_M = 1e6
"""The largest coordinate of ``--start`` / ``--goal`` [m]."""


def _xy(ctx, param, value):
    """Parse ``x,y`` (metres) into two floats."""
    return numbers(value, param.opts[-1] if param is not None else "X,Y", 2, -MAX_COORDINATE_M, MAX_COORDINATE_M,
                   unit="m", what="'x,y' in metres")


@click.command("plan")
@click.argument("map_yaml", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--start", required=True, callback=_xy, metavar="X,Y", help="Start (x, y) in metres.")
@click.option("--goal", required=True, callback=_xy, metavar="X,Y", help="Goal (x, y) in metres.")
@click.option("--radius", "radius_m", type=Number(0.0, 10.0, unit="m"),
              default=library_default(plan_path, "robot_radius_m"),
              show_default=True, help="Robot radius [m]: obstacles are inflated by it.")
@click.option("--unknown", type=click.Choice(["blocked", "free"]),
              default="blocked" if library_default(plan_path, "unknown_is_obstacle") else "free",
              show_default=True, help="Cells the map never observed: blocked (safe) or free.")
@click.option("-o", "--out", "output", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="Path JSON to write.")
@click.option("--plot", "plot_png", type=click.Path(dir_okay=False, path_type=Path),
              help="Also draw the map and the path to this image.")
def plan_command(map_yaml: Path, start, goal, radius_m: float, unknown: str, output: Path,
                 plot_png: Path | None) -> None:
    """Plan a collision-free path on a ROS map with A*.

    MAP_YAML is a ROS map_server map (YAML + PGM, e.g. map.yaml of `mrstereo
    map`). Writes the JSON given by -o: path_xy (cell centres, metres),
    length_m, start, goal, robot_radius_m, unknown, expanded_cells. Exits with
    an error if there is no path.
    """
    from ..mapping import plot_map, read_ros_map

    ros_map = read_ros_map(map_yaml)
    check_outputs({"--out": output, "--plot": plot_png}, ros_map_files(map_yaml),
                  suffixes={"--out": (".json",), "--plot": (".png", ".pdf", ".svg")})
    result = plan_path(ros_map, start, goal, robot_radius_m=radius_m,
                       unknown_is_obstacle=unknown == "blocked")
    if not result.success:
        raise RuntimeError(result.message)
    record = {"map": str(map_yaml), "start": list(start), "goal": list(goal),
              "robot_radius_m": radius_m, "unknown": unknown, "length_m": result.length_m,
              "expanded_cells": result.expanded_cells,
              "path_xy": [[round(float(x), 6), round(float(y), 6)] for x, y in result.path_xy]}
    with atomic_write(output) as tmp:
        tmp.write_text(json.dumps(record, indent=1) + "\n")
    if plot_png is not None:
        plot_map(ros_map, plot_png, planned_path=result.path_xy,
                 title=f"A* path {result.length_m:.2f} m, robot radius {radius_m:g} m")
    click.echo(f"path length: {result.length_m:.3f} m ({len(result.path_xy)} cells) -> {output}")


COMMANDS: list = [plan_command]
