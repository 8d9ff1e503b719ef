"""CLI of the mapping stage: ``mrstereo plan`` (A* on a ROS map, from the robot's last pose or a given start).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import click

from ..io import atomic_write, check_outputs
from ..mapping.planning import plan_path
from ..mapping.rosmap import ros_map_files
from ._options import Number, library_default, numbers


MAX_COORDINATE_M = 1e6
"""The largest coordinate of ``--start`` / ``--goal`` [m]."""


def _xy(ctx, param, value):
    """Parse ``x,y`` (metres) into two floats; ``robot`` is kept as it is (``--start``)."""
    if value == "robot" and param is not None and param.name == "start":
        return value
    return numbers(value, param.opts[-1] if param is not None else "X,Y", 2, -MAX_COORDINATE_M, MAX_COORDINATE_M,
                   unit="m", what="'x,y' in metres")


def _goal(ctx, param, value):
    """Parse ``x,y`` or ``x,y,yaw`` (metres, radians) into ``(x, y, yaw or None)``."""
    n = len(str(value).split(","))
    if n == 3:
        x, y, yaw = numbers(value, "--goal", 3, -MAX_COORDINATE_M, MAX_COORDINATE_M, what="'x,y,yaw' (m, m, rad)")
        if abs(yaw) > 2 * math.pi:
            raise click.BadParameter(f"the heading {yaw:g} rad is not in [-2 pi, 2 pi] (radians, not degrees?)",
                                     param_hint="--goal")
        return x, y, yaw
    return (*_xy(ctx, param, value), None)


def robot_start(map_yaml: Path, trajectory: Path | None) -> tuple[float, float]:
    """The robot's last (x, y): the last pose of ``trajectory`` (TUM), default trajectory.txt beside the map."""
    from ..odometry.trajectory import read_tum

    path = trajectory if trajectory is not None else map_yaml.parent / "trajectory.txt"
    if not path.is_file():
        raise click.BadParameter(f"{path} not found: --start robot takes the robot's last pose from a trajectory "
                                 "(TUM: trajectory.txt of `mrstereo map`/`live`, the output of `mrstereo odometry`); "
                                 "give it with --trajectory", param_hint="--start")
    try:
        _, T = read_tum(path)
    except ValueError as err:
        raise click.BadParameter(f"{path}: {err}", param_hint="--trajectory") from None
    if not len(T):
        raise click.BadParameter(f"{path} holds no pose", param_hint="--trajectory")
    return float(T[-1][0, 3]), float(T[-1][1, 3])


@click.command("plan")
@click.argument("map_yaml", type=click.Path(dir_okay=False, path_type=Path))
@click.option("--start", required=True, callback=_xy, metavar="X,Y|robot",
              help="Start (x, y) in metres, or `robot`: the last pose of the run's trajectory (--trajectory).")
@click.option("--trajectory", type=click.Path(dir_okay=False, path_type=Path),
              help="TUM trajectory whose last pose is the start of `--start robot` [default: trajectory.txt beside "
                   "MAP_YAML].")
@click.option("--goal", required=True, callback=_goal, metavar="X,Y[,YAW]",
              help="Goal (x, y) in metres, optionally with the heading to arrive with (radians, REP 103).")
@click.option("--smooth/--no-smooth", default=library_default(plan_path, "smooth"), show_default=True,
              help="Shortcut the cell staircase by straight segments that keep the inflated clearance.")
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
@click.option("--record-bag", "record_bag", type=click.Path(file_okay=False, path_type=Path),
              help="Also write a ROS 2 bag (MCAP) to this new folder: the map (/map, trinary as map_server "
                   "publishes it) and the path (/plan, nav_msgs/Path in the map frame).")
def plan_command(map_yaml: Path, start, trajectory: Path | None, goal, smooth: bool, radius_m: float, unknown: str,
                 output: Path, plot_png: Path | None, record_bag: Path | None) -> None:
    """Plan a collision-free path on a ROS map with A*.

    MAP_YAML is a ROS map_server map (YAML + PGM, e.g. map.yaml of `mrstereo
    map`). Writes the JSON given by -o: path_xy (metres), poses (x, y, yaw),
    length_m, start, goal, robot_radius_m, unknown, expanded_cells. Exits with
    an error if there is no path.
    """
    from ..io import check_output_dir
    from ..mapping import plot_map, read_ros_map

    ros_map = read_ros_map(map_yaml)
    inputs = ros_map_files(map_yaml) + ([trajectory] if trajectory is not None else [])
    check_outputs({"--out": output, "--plot": plot_png}, inputs,
                  suffixes={"--out": (".json",), "--plot": (".png", ".pdf", ".svg")})
    if record_bag is not None:
        check_output_dir("--record-bag", record_bag, inputs=inputs)
        if record_bag.exists():
            raise click.BadParameter(f"{record_bag} exists; give a new folder (a bag is a folder of its own)",
                                     param_hint="--record-bag")
    if start == "robot":
        start = robot_start(map_yaml, trajectory)
    *goal_xy, goal_yaw = goal
    result = plan_path(ros_map, start, goal_xy, robot_radius_m=radius_m, unknown_is_obstacle=unknown == "blocked",
                       smooth=smooth, goal_yaw_rad=goal_yaw)
    if not result.success:
        raise RuntimeError(result.message)
    record = {"map": str(map_yaml), "start": list(start), "goal": list(goal_xy), "goal_yaw_rad": goal_yaw,
              "robot_radius_m": radius_m, "unknown": unknown, "smooth": smooth, "length_m": result.length_m,
              "expanded_cells": result.expanded_cells,
              "path_xy": [[round(float(x), 6), round(float(y), 6)] for x, y in result.path_xy],
              "poses": [[round(float(v), 6) for v in pose] for pose in result.poses]}
    with atomic_write(output) as tmp:
        tmp.write_text(json.dumps(record, indent=1) + "\n")
    if plot_png is not None:
        plot_map(ros_map, plot_png, planned_path=result.path_xy,
                 title=f"A* path {result.length_m:.2f} m, robot radius {radius_m:g} m")
    if record_bag is not None:
        _plan_bag(record_bag, ros_map, result)
    click.echo(f"path length: {result.length_m:.3f} m ({len(result.path_xy)} points) from "
               f"({start[0]:.2f}, {start[1]:.2f}) -> {output}")


def _plan_bag(path: Path, ros_map, result) -> None:
    """A ROS 2 bag of the map (/map, trinary) and the path (/plan) at time 0."""
    from ..mapping.rosmap import occupancy_values
    from ..recordings.bag_writer import BagWriter

    writer = BagWriter(path)
    try:
        g = ros_map.grid
        writer.map(0, occupancy_values(ros_map.occupancy, occupied_thresh=ros_map.occupied_thresh,
                                       free_thresh=ros_map.free_thresh),
                   resolution_m=g.resolution_m, origin_xy=(g.origin_x_m, g.origin_y_m))
        writer.plan(0, result.poses)
    except BaseException:
        writer.discard()
        raise
    writer.close()


COMMANDS: list = [plan_command]
