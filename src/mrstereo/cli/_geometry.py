"""CLI: ``mrstereo points`` (PLY point cloud) and ``mrstereo scan`` (virtual laser scan).

Both run one stereo pair through rectification, multi-range matching,
eq. (13) rejection and the 3D stage (:mod:`mrstereo.geometry.pair`).

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from pathlib import Path

import click
import numpy as np

from ..io import check_outputs
from ..geometry.pair import obstacles_from_pair, scan_from_pair
from ._options import (ANGLE_RAD, CALIB_HELP, HEIGHT, MAX_DISPARITY, TILT, Number, drop_config, drop_options,
                       echo_floor, library_default, mount_from_options, mount_option, profile_option)

__all__ = ["COMMANDS"]


def _common(func):
    options = [
        click.argument("left", type=click.Path(dir_okay=False)),
        click.argument("right", type=click.Path(dir_okay=False)),
        click.option("--calib", "calib", required=True, type=click.Path(dir_okay=False),
                     help=CALIB_HELP + " A stereo YAML may hold the mount (mount: or rig:)."),
        click.option("-o", "--out", "output", required=True, type=click.Path(dir_okay=False), help="Output file."),
        click.option("--rectified", is_flag=True, help="The images are already rectified."),
        click.option("--height", "height_m", type=HEIGHT, default=None,
                     help="Camera height above the floor [m] (overrides the YAML mount)."),
        click.option("--tilt", "tilt_rad", type=TILT, default=None,
                     help="Downward camera tilt [rad] (overrides the YAML mount; needs --height or a YAML mount)."),
        click.option("--pan", "pan_rad", type=Number(-ANGLE_RAD, ANGLE_RAD, unit="rad"),
                     default=library_default(obstacles_from_pair, "pan_rad"),
                     show_default=True, help="Head pan about the robot's z axis [rad], positive to the left."),
        click.option("--preset", type=click.Choice(["mapping", "robust", "paper"]),
                     default=library_default(obstacles_from_pair, "preset"), show_default=True, help="Matcher preset."),
        click.option("--max-disparity", "max_disparity_px", type=MAX_DISPARITY, default=None,
                     help="Largest disparity to search [px] (default: the matcher's)."),
        click.option("--texture-threshold", type=Number(0.0, 255.0, unit="gray levels"), default=None,
                     help="T of eq. (13): reject patches with std <= T gray levels (0 disables)."),
        click.option("--min-height", "min_height_m", type=Number(0.0, 10.0, unit="m"), default=None,
                     help="Obstacles start this high above the floor [m]."),
        click.option("--max-height", "max_height_m", type=Number(0.0, 20.0, unit="m", open_low=True), default=None,
                     help="Points above this height [m] are ignored."),
        click.option("--max-range", "max_range_m", type=Number(0.0, 1000.0, unit="m", open_low=True), default=None,
                     help="Drop points farther [m]."),
        click.option("--ground", "ground_method", type=click.Choice(["v_disparity", "plane"]), default=None,
                     help="Floor estimator used when the mount is unknown."),
    ]
    for option in reversed(options):
        func = option(func)
    return mount_option(drop_options(func))


def _run(left, right, calib, output, *, rectified, height_m, tilt_rad, pan_rad, preset, max_disparity_px,
         texture_threshold, min_height_m, max_height_m, max_range_m, ground_method, max_step_m, max_slope_deg,
         drops, mount, scan: bool, **scan_kw):
    from dataclasses import replace

    from ..camera import read_stereo
    from ..geometry import ObstacleConfig, ground_from_mount
    from ..io import read_image
    from ..rejection.streams import warn_pair
    from ..profiling import stage
    from ..rejection import RejectionConfig

    stereo = read_stereo(calib)
    if mount is None and stereo.mount is not None and (height_m is not None or tilt_rad is not None):
        # one of --height/--tilt: the other is the calibration YAML's (of its rectified left camera)
        given = ground_from_mount(stereo.mount, R_rect_from_cam=stereo.left.R)
        height_m = given.height_m if height_m is None else height_m
        tilt_rad = given.tilt_rad if tilt_rad is None else tilt_rad
    camera_mount = mount_from_options(height_m, tilt_rad, mount, stereo)
    from ..io import matching_image

    with stage("read"):
        left_img, right_img = matching_image(read_image(left)), matching_image(read_image(right))
    if left_img.shape != right_img.shape:
        raise ValueError(f"left and right images differ in size: {left_img.shape[1]}x{left_img.shape[0]} "
                         f"and {right_img.shape[1]}x{right_img.shape[0]}")
    warn_pair(left_img, right_img, stereo, rectified=rectified)
    rejection = RejectionConfig() if texture_threshold is None else \
        RejectionConfig(texture_threshold=texture_threshold)
    config = ObstacleConfig()
    updates = {k: v for k, v in (("min_obstacle_height_m", min_height_m), ("max_obstacle_height_m", max_height_m),
                                 ("max_range_m", max_range_m), ("ground_method", ground_method)) if v is not None}
    config = replace(config, drops=drop_config(drops=drops, max_step_m=max_step_m, max_slope_deg=max_slope_deg),
                     **updates)
    options = dict(rectified=rectified, mount=camera_mount, pan_rad=pan_rad, preset=preset,
                   max_disparity_px=max_disparity_px, rejection=rejection, config=config)
    if scan:
        return stereo, scan_from_pair(left_img, right_img, stereo, **scan_kw, **options)
    return stereo, obstacles_from_pair(left_img, right_img, stereo, **options)


def _read_inputs(calib) -> None:
    """The calibration read before any output is checked (its sibling files become inputs too)."""
    from ..camera import read_stereo

    read_stereo(calib)


def _report_ground(obstacles) -> None:
    echo_floor(obstacles.ground)


@click.command("points")
@profile_option("read, rectify, match, reject, 3-D")
@_common
@click.option("--which", type=click.Choice(["all", "obstacles", "floor"]), default="all", show_default=True,
              help="Which points to write.")
@click.option("--color", is_flag=True, help="Write red/green/blue from the colour left image (else its gray level).")
@click.option("--depth-png", "depth_png", type=click.Path(dir_okay=False, path_type=Path), default=None,
              help="Also write the depth of the rectified left image as a 16-bit PNG in millimetres, 0 invalid "
                   "(RealSense / ROS depth_image_proc 16UC1), from the matcher's disparity.")
def points_command(left, right, calib, output, which, color, depth_png, **kw):
    """Write a stereo pair's robot-frame point cloud as PLY.

    LEFT and RIGHT are a raw pair (rectified with --calib first) or a rectified
    pair (--rectified). The points are in the robot base frame (REP 103,
    metres), in a binary PLY with the pixel's gray level (or colour, --color).
    The camera mount comes from --mount or --height/--tilt, else the
    calibration's mount:/rig: entry, else the floor is estimated from the
    disparity (docs/conventions.md).
    """
    from ..geometry import write_ply

    _read_inputs(calib)
    check_outputs({"--out": output, "--depth-png": depth_png}, [left, right, calib],
                  suffixes={"--out": (".ply",), "--depth-png": (".png",)})
    stereo, frame = _run(left, right, calib, output, scan=False, **kw)
    obs = frame.obstacles
    if not obs.success:
        raise RuntimeError(f"{obs.message}; give --mount or --height and --tilt (or a mount: entry in the calibration)")
    valid = np.isfinite(obs.points_robot_image).all(axis=-1)
    mask = {"all": valid, "obstacles": obs.obstacle_mask, "floor": obs.floor_mask}[which]
    pts = obs.points_robot_image[mask]
    label = np.where(obs.obstacle_mask, 1, np.where(obs.floor_mask, 2, 0)).astype(np.uint8)[mask]
    img = frame.left_rect
    if color and img.ndim != 3:
        raise ValueError(f"--color needs a colour left image, {left} is gray")
    gray = img if img.ndim == 2 else np.asarray(img, np.float32) @ np.float32([0.114, 0.587, 0.299])
    look = {"colors_rgb": img[mask][:, ::-1]} if color else {"intensity": np.asarray(gray)[mask]}
    n = write_ply(output, pts, label=label, comment="mrstereo robot frame, metres", **look)
    if depth_png is not None:
        from ..geometry import depth_m_from_disparity_px
        from ..io.images import write_depth_png

        write_depth_png(depth_png, depth_m_from_disparity_px(frame.raw_disparity_px, focal_px=stereo.focal_px,
                                                             baseline_m=stereo.baseline_m))
    _report_ground(obs)
    click.echo(f"wrote {n} points ({int(obs.obstacle_mask.sum())} obstacle, {int(obs.floor_mask.sum())} floor) "
               f"to {output}", err=True)


@click.command("scan")
@profile_option("read, rectify, match, reject, 3-D, scan")
@_common
@click.option("--plot", "plot_path", type=click.Path(dir_okay=False), default=None,
              help="Also write a top-view PNG (obstacle points, floor points, scan).")
@click.option("--angle-increment", "angle_increment_deg", type=Number(0.01, 90.0, unit="deg"),
              default=math.degrees(library_default(scan_from_pair, "angle_increment_rad")), show_default=True,
              help="Angular step of the scan [deg].")
@click.option("--range-min", "range_min_m", type=Number(0.0, 100.0, unit="m"),
              default=library_default(scan_from_pair, "range_min_m"),
              show_default=True, help="Smallest range [m] (raised to the matcher's near limit).")
def scan_command(left, right, calib, output, plot_path, angle_increment_deg, range_min_m, **kw):
    """Write a stereo pair's virtual laser scan (JSON or CSV).

    Each bearing holds its nearest obstacle in the robot base frame. JSON uses
    the fields of ROS sensor_msgs/LaserScan (angle_min, angle_max,
    angle_increment, range_min, range_max, ranges, intensities, header); a
    range that is not a number is the string "Infinity" (seen clear past
    range_max), "NaN" (no measurement) or "-Infinity" (nearer than range_min),
    the REP 117 values. An output ending in .csv is written as
    angle_rad,range_m,intensity rows with inf, nan, -inf (docs/obstacles.md).
    The camera mount is found as for `mrstereo points`.
    """
    from ..geometry import plot_top_view, write_scan_csv, write_scan_json

    suffix = Path(output).suffix.lower()
    _read_inputs(calib)
    check_outputs({"--out": output, "--plot": plot_path}, [left, right, calib],
                  suffixes={"--out": (".json", ".csv"), "--plot": (".png",)})
    _, result = _run(left, right, calib, output, scan=True, angle_increment_rad=math.radians(angle_increment_deg),
                     range_min_m=range_min_m, **kw)
    obs = result.frame.obstacles
    if not obs.success:
        raise RuntimeError(f"{obs.message}; give --mount or --height and --tilt (or a mount: entry in the calibration)")
    (write_scan_csv if suffix == ".csv" else write_scan_json)(output, result.scan)
    if plot_path is not None:
        plot_top_view(plot_path, obstacle_points_robot=obs.obstacle_points_robot,
                      floor_points_robot=obs.floor_points_robot, scan=result.scan,
                      x_range_m=(0.0, max(1.0, result.scan.range_max_m)),
                      title=f"top view: {Path(left).name}")
    _report_ground(obs)
    n = int(np.isfinite(result.scan.ranges_m).sum())
    click.echo(f"wrote a scan of {result.scan.ranges_m.size} rays ({n} returns) to {output}", err=True)


COMMANDS = [points_command, scan_command]
