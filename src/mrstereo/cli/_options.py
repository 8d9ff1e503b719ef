"""Options shared by several commands.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import functools
import inspect
import math
from pathlib import Path

import click

from .._limits import max_workers

CALIB_HELP = ("Calibration file in any supported format (mrstereo/ROS stereo YAML, Kalibr camchain, OpenCV "
              "FileStorage, OpenLORIS), or two per-camera files as LEFT,RIGHT; see `mrstereo calib convert --help`.")


class Number(click.ParamType):
    """A finite number within ``[low, high]`` (``open_low``/``open_high``: the bound itself excluded).

    Every numeric option of the command line has one: an absurd value (``--pan 1e300``,
    ``--max-disparity 100000``, ``nan``) is refused at parsing with the valid range and its unit.
    A bound may be a callable (a limit read when the option is parsed, e.g. the cores).
    """

    def __init__(self, low, high, *, unit: str = "", integer: bool = False, open_low: bool = False,
                 open_high: bool = False) -> None:
        self.low, self.high, self.unit, self.integer = low, high, unit, integer
        self.open_low, self.open_high = open_low, open_high
        self.name = "integer" if integer else "float"

    def bounds(self) -> tuple[float, float]:
        return tuple(b() if callable(b) else b for b in (self.low, self.high))

    def describe(self) -> str:
        low, high = self.bounds()
        text = f"{'(' if self.open_low else '['}{low:g}, {high:g}{')' if self.open_high else ']'}"
        return text + (f" {self.unit}" if self.unit else "")

    def get_metavar(self, param, ctx=None) -> str:
        return "INTEGER" if self.integer else "FLOAT"

    def convert(self, value, param, ctx):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            number = value
        else:
            try:
                number = int(str(value), 10) if self.integer else float(str(value))
            except ValueError:
                self.fail(f"{value!r} is not {'an integer' if self.integer else 'a number'}", param, ctx)
        if not math.isfinite(number):
            self.fail(f"{value!r} is not a finite number; the range is {self.describe()}", param, ctx)
        low, high = self.bounds()
        if number < low or number > high or (self.open_low and number == low) or \
                (self.open_high and number == high):
            self.fail(f"{value} is not in the range {self.describe()}", param, ctx)
        return int(number) if self.integer else float(number)


def numbers(text: str, option: str, count: int, low: float, high: float, *, unit: str = "",
            what: str = "") -> tuple[float, ...]:
    """``count`` comma-separated finite numbers in ``[low, high]`` from an option's text."""
    try:
        values = tuple(float(v) for v in str(text).split(","))
    except ValueError:
        values = ()
    if len(values) != count or not all(math.isfinite(v) for v in values):
        raise click.BadParameter(f"expected {count} comma-separated numbers{' ' + what if what else ''}, got "
                                 f"{text!r}", param_hint=option)
    bad = [v for v in values if not low <= v <= high]
    if bad:
        raise click.BadParameter(f"{bad[0]:g} is not in the range [{low:g}, {high:g}]{' ' + unit if unit else ''}",
                                 param_hint=option)
    return values


def library_default(func, name: str):
    """The default of the keyword ``name`` of the library function ``func``: an option's default is the library's."""
    return inspect.signature(func).parameters[name].default


def worker_options(func):
    """``--workers N [--processes]`` / ``--scheduler ADDRESS`` (docs/scale-out.md)."""
    func = click.option("--processes", is_flag=True,
                        help="With --workers: worker processes instead of worker threads of this process.")(func)
    func = click.option("--scheduler", default=None, metavar="ADDRESS",
                        help="Run the work (frames, scenes) on an existing Dask cluster (tcp://host:8786); its "
                             "workers must see the same files.")(func)
    func = click.option("--workers", type=Number(1, max_workers, integer=True), default=None,
                        help="Run the work (frames, scenes) on N single-threaded worker threads (with --processes: a "
                             "local Dask cluster of N worker processes; default: in this process). At most the "
                             "number of cores (MRSTEREO_MAX_WORKERS raises it).")(func)
    return func


def check_workers(workers, scheduler, processes: bool = False) -> None:
    if workers is not None and scheduler is not None:
        raise click.UsageError("give --workers or --scheduler, not both")
    if processes and workers is None:
        raise click.UsageError("--processes only with --workers")
    if processes or scheduler is not None:
        from .._executor import require_scale
        require_scale()                 # before any work: one line naming the extra



HEIGHT = Number(0.0, 20.0, unit="m", open_low=True)
"""``--height``: the camera above the floor."""
TILT = Number(-math.pi / 2, math.pi / 2, unit="rad")
"""``--tilt``: downward tilt of the camera."""
SEED = Number(0, 2 ** 32 - 1, integer=True)
"""``--seed`` of every command."""
MAX_IMAGE_SIDE = 100_000
"""The largest image width or height of ``--image-size`` [px]."""
MAX_DISPARITY = Number(1.0, 4096.0, unit="px")
"""``--max-disparity``: a search below a pixel finds nothing, one beyond the widest images is a typo."""


def mount_option(func):
    """``--mount x,y,z,roll,pitch,yaw``: the 6-DoF camera mount (docs/conventions.md, Frames)."""
    return click.option("--mount", "mount", default=None, metavar="X,Y,Z,ROLL,PITCH,YAW",
                        help="Camera mount in the robot base frame: position [m] and REP 103 roll, pitch "
                             "(positive = looking down), yaw [rad] of the camera body (docs/conventions.md). "
                             "Overrides a mount:/rig: entry; not with --height/--tilt.")(func)


MOUNT_XYZ_M = 100.0
"""The largest camera position (each of x, y, z) of ``--mount`` [m]."""
ANGLE_RAD = 2 * math.pi
"""The largest angle of ``--mount``, ``--pan`` [rad] (in either direction)."""


def parse_mount(text):
    """A :class:`~mrstereo.camera.mount.CameraMount` from ``--mount`` text (None stays None)."""
    from ..camera.mount import CameraMount

    if text is None:
        return None
    values = numbers(text, "--mount", 6, -MOUNT_XYZ_M, MOUNT_XYZ_M, what="'x,y,z,roll,pitch,yaw' (metres, radians)")
    rpy = values[3:]
    if not all(abs(v) <= ANGLE_RAD for v in rpy):
        raise click.BadParameter(f"roll, pitch and yaw must be in [-{ANGLE_RAD:g}, {ANGLE_RAD:g}] rad, got {text!r}",
                                 param_hint="--mount")
    return CameraMount.from_xyz_rpy(values[:3], rpy)


def check_mount_options(height_m, tilt_rad, mount) -> None:
    """``--mount`` or ``--height``/``--tilt``: not both, finite, no ``--tilt`` without ``--height``."""
    if mount is not None and (height_m is not None or tilt_rad is not None):
        raise click.UsageError("give --mount or --height/--tilt, not both")
    if height_m is None and tilt_rad is not None:
        raise click.UsageError("--tilt needs --height")


def mount_from_options(height_m, tilt_rad, mount, stereo):
    """The CameraMount of ``--mount``, or of the paper's rig ``--height``/``--tilt`` (the rectified left
    camera of the calibration ``stereo``); None when none is given."""
    from ..camera import CameraMount

    check_mount_options(height_m, tilt_rad, mount)
    if mount is not None:
        return parse_mount(mount)
    if height_m is None:
        return None
    return CameraMount.from_rig(height_m, 0.0 if tilt_rad is None else tilt_rad, R_rect_from_cam=stereo.left.R)


def echo_floor(ground, *, prefix: str = "floor") -> None:
    """One stderr line for the floor a command used; a warning line when a fit is not confident."""
    if ground is None:
        return
    if not ground.success:
        click.echo(f"{prefix} ({ground.method}): not found ({ground.message})", err=True)
        return
    click.echo(f"{prefix} ({ground.method}): height {ground.height_m:.3f} m, tilt {math.degrees(ground.tilt_rad):.2f} "
               f"deg, roll {math.degrees(ground.roll_rad):.2f} deg; {ground.confidence_text}", err=True)
    warn_floor(ground)


def echo_run_floor(ground, *, prefix: str = "floor") -> None:
    """For a whole run (map, batch): the floor on stdout when it was estimated, and a warning if weak."""
    if ground is None or ground.method == "mount":
        return
    click.echo(f"{prefix} {ground.message}: height {ground.height_m:.3f} m, tilt {ground.tilt_rad:.4f} rad, "
               f"roll {ground.roll_rad:.4f} rad; {ground.confidence_text}")
    warn_floor(ground)


def warn_floor(ground) -> None:
    """One ``mrstereo: warning: ...`` line on stderr for a floor estimate that is not confident."""
    from ..geometry.ground import MAX_FLOOR_RESIDUAL_M, MIN_FLOOR_SHARE

    if ground.success and not ground.confident:
        click.echo(f"mrstereo: warning: the floor estimate is not confident ({ground.confidence_text}; needs at "
                   f"least {100 * MIN_FLOOR_SHARE:.0f} % inliers and at most {MAX_FLOOR_RESIDUAL_M:.3f} m): "
                   "little floor in view, obstacles and free space may be wrong; give the camera mount "
                   "(--mount or --height/--tilt)", err=True)


def profile_option(stages: str):
    """``--profile``: time the command's ``stages`` (:mod:`mrstereo.profiling`) and print a per-frame table.

    ``stages`` names them for the help, e.g. ``"read, rectify, match"``. Put the decorator right
    under ``@click.command``. Worker processes are not seen.
    """
    def decorate(func):
        @functools.wraps(func)
        def wrapper(*args, profile: bool = False, **kwargs):
            if not profile:
                return func(*args, **kwargs)
            from ..profiling import profiling

            with profiling() as prof:
                result = func(*args, **kwargs)
            click.echo(prof.table(), err=True)
            return result

        return click.option("--profile", is_flag=True,
                            help=f"Print the time per frame of every stage ({stages}) at the end "
                                 "(stderr).")(wrapper)
    return decorate


def drop_options(func):
    """The drop test's options (``map``, ``batch``, ``live``, ``points``, ``scan``): ``--drops/--no-drops``,
    ``--max-step``, ``--max-slope`` (:func:`drop_config`); defaults those of the library."""
    from ..geometry.drops import DropConfig
    from ..geometry.obstacles import ObstacleConfig

    options = [
        click.option("--drops/--no-drops", "drops", default=ObstacleConfig.drops is not None, show_default=True,
                     help="Drop test: where the floor ends (a ledge, a hole, a stairwell) is lethal, a step or slope "
                          "within --max-step and --max-slope is not (docs/obstacles.md, \"Drops\")."),
        click.option("--max-step", "max_step_m", type=Number(0.0, 1.0, unit="m"),
                     default=DropConfig.max_step_m, show_default=True,
                     help="Highest step the robot climbs up or down [m]; a deeper drop is lethal."),
        click.option("--max-slope", "max_slope_deg", type=Number(0.0, 89.0, unit="deg"),
                     default=DropConfig.max_slope_deg, show_default=True,
                     help="Steepest slope the robot drives [deg]; a floor that falls away faster is a drop."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def drop_config(*, drops: bool, max_step_m: float, max_slope_deg: float, **_):
    """The :class:`~mrstereo.geometry.drops.DropConfig` of the :func:`drop_options` (None: ``--no-drops``)."""
    from ..geometry.drops import DropConfig

    return DropConfig(max_step_m=max_step_m, max_slope_deg=max_slope_deg) if drops else None


def map_options(func):
    """The options of a map shared by ``map``, ``batch`` and ``live``: preset, fusion, window or growth, range,
    footprint, mount check, the drop test (:func:`map_config`)."""
    from ..mapping import GridSpec, MappingConfig
    from ..pipeline.run import PipelineConfig

    options = [
        click.option("--preset", type=click.Choice(["mapping", "robust", "paper"]), default=PipelineConfig.preset,
                     show_default=True, help="Matching preset."),
        click.option("--fusion", type=click.Choice(["log_odds", "union"]), default=MappingConfig.fusion,
                     show_default=True, help="Log-odds fusion (OctoMap) or the paper's union of occupied cells."),
        click.option("--resolution", "resolution_m", type=Number(0.001, 10.0, unit="m"),
                     default=GridSpec.resolution_m, show_default=True, help="Cell size [m]."),
        click.option("--size", "size_m", default=None, metavar="W,H",
                     help="A fixed map window: width (x) and height (y) [m], with --origin; points outside are "
                          "counted and warned about. Default: the map grows to cover the path and what was seen."),
        click.option("--origin", "origin_m", default=None, metavar="X,Y",
                     help="World position of the lower-left corner of a fixed map window [m] (with --size)."),
        click.option("--max-range", "max_range_m", type=Number(0.0, 1000.0, unit="m", open_low=True), default=None,
                     help="Mapping range [m]: points farther from the robot are dropped. Default: where the rig's "
                          "depth error reaches that of the paper's rig at 4 m (4 m or more; `mrstereo info`)."),
        click.option("--footprint", "footprint_m", type=Number(0.0, 100.0, unit="m"),
                     default=MappingConfig.footprint_radius_m,
                     show_default=True,
                     help="Robot radius [m]: the cells its footprint sweeps along the path are free (0: off)."),
        click.option("--no-mount-check", is_flag=True,
                     help="Use the given camera mount even when the floor seen in the first frames disagrees."),
    ]
    for option in reversed(options):
        func = option(func)
    return drop_options(func)


MAX_MAP_SIZE_M = 100_000.0
"""The largest map window side and origin coordinate of ``--size``/``--origin`` [m]."""


def map_config(*, preset: str, fusion: str, resolution_m: float, size_m: str | None, origin_m: str | None,
               max_range_m: float | None, footprint_m: float, **options):
    """The :class:`~mrstereo.pipeline.PipelineConfig` of the :func:`map_options`."""
    import dataclasses

    from ..geometry.obstacles import ObstacleConfig
    from ..mapping import GridSpec
    from ..pipeline.run import PipelineConfig

    if (size_m is None) != (origin_m is None):
        raise click.UsageError("a fixed map window needs both --size W,H and --origin X,Y")
    grid = None
    if size_m is not None:
        width, height = numbers(size_m, "--size", 2, 0.0, MAX_MAP_SIZE_M, unit="m", what="'W,H' in metres")
        ox, oy = numbers(origin_m, "--origin", 2, -MAX_MAP_SIZE_M, MAX_MAP_SIZE_M, unit="m", what="'X,Y' in metres")
        if width <= 0 or height <= 0:
            raise click.BadParameter(f"width and height must be > 0, got {size_m!r}", param_hint="--size")
        grid = GridSpec(width_m=width, height_m=height, resolution_m=resolution_m, origin_x_m=ox, origin_y_m=oy)
    drops = drop_config(**options)
    obstacles = None
    if max_range_m is not None:
        obstacles = ObstacleConfig(max_range_m=max_range_m, drops=drops)
    config = PipelineConfig(preset=preset, grid=grid, resolution_m=resolution_m, obstacles=obstacles, drops=drops)
    return dataclasses.replace(config.with_fusion(fusion),
                               mapping=dataclasses.replace(config.with_fusion(fusion).mapping,
                                                           footprint_radius_m=footprint_m or None))


def warn(message: str) -> None:
    """One ``mrstereo: warning: ...`` line on stderr."""
    click.echo(f"mrstereo: warning: {message}", err=True)


def echo_map_warnings(run, *, prefix: str = "") -> None:
    """The warnings of a map run: a mount not used, points outside a fixed window."""
    if run.mount_warning:
        warn(prefix + run.mount_warning)
    n = run.grid.points_outside
    if n:
        g, truth = run.grid.grid, run.ground_truth_map
        on_truth = truth is not None and (truth.grid.origin_x_m, truth.grid.origin_y_m, truth.grid.width_m,
                                          truth.grid.height_m) == (g.origin_x_m, g.origin_y_m, g.width_m, g.height_m)
        advice = ("the window of the recording's ground-truth map; --size/--origin set another" if on_truth else
                  "leave out --size/--origin for a map that grows")
        warn(f"{prefix}{n} points fell outside the map window x {g.origin_x_m:g}..{g.origin_x_m + g.width_m:g} m, "
             f"y {g.origin_y_m:g}..{g.origin_y_m + g.height_m:g} m (their rays were cut at its border; counted in "
             f"metrics.json): {advice}")


def truth_option(func):
    """``--truth FILE`` and ``--no-truth`` of every command that reads a recording, passed on as ``truth``:
    None (the recording's own truth), False (none) or the file (:mod:`mrstereo.recordings.truth`)."""
    @functools.wraps(func)
    def wrapper(*args, truth_file=None, no_truth: bool = False, **kwargs):
        if truth_file is not None and no_truth:
            raise click.UsageError("give --truth FILE or --no-truth, not both")
        return func(*args, truth=False if no_truth else truth_file, **kwargs)

    wrapper = click.option(
        "--no-truth", is_flag=True,
        help="Read no ground truth of the recording (not even its file: an empty or broken one does not stop "
             "the run); the poses come from visual odometry (a bag: its odometry topic and TF are not read).")(wrapper)
    return click.option(
        "--truth", "truth_file", type=click.Path(dir_okay=False, path_type=Path), default=None,
        help="Ground truth from this file instead of the recording's: TUM 't x y z qx qy qz qw' (t in s) or EuRoC "
             "csv (t in ns, p, q wxyz), matched to the frames by stamp (nearest within 20 ms; frames without a "
             "pose are left out). Poses of the EuRoC body frame, of KITTI's / image folders' left camera (in "
             "the first camera's frame), of a dataset's or bag's robot base (docs/dataset.md).")(wrapper)
