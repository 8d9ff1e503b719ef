"""CLI of the live loop: ``mrstereo live`` (cameras, video files or a recording to a map while it runs).

Conventions: docs/conventions.md; user guide: docs/live.md.
"""
from __future__ import annotations

import signal
import threading
from pathlib import Path

import click

from ..evaluation.outputs import LIVE_FILES
from ..pipeline.live import LiveConfig
from .._interrupt import reached
from .._limits import limit, max_workers
from ._options import (CALIB_HELP, HEIGHT, TILT, Number, map_config, map_options, mount_from_options, mount_option,
                       profile_option, truth_option)

__all__ = ["COMMANDS", "viewer_option", "record_bag_option", "check_sink_options", "replayed_to_sinks"]

VIEWERS = ("none", "rerun", "foxglove")
VIEWER_PORT, FOXGLOVE_PORT = 9876, 8765
"""Default ports on 127.0.0.1 of Rerun's data stream and of Foxglove's websocket server (their tools' own)."""


def viewer_option(func):
    """``--viewer none|rerun|foxglove`` (repeatable): the live view (optional extra ``mrstereo[viz]``)."""
    return click.option("--viewer", "viewers", type=click.Choice(VIEWERS), multiple=True,
                        help="Live view: rerun (spawns the viewer with a display, else serves its data on localhost, "
                             "--viewer-port; saves OUT/view.rrd) and/or foxglove (websocket on localhost, "
                             "--foxglove-port; saves OUT/view.mcap). "
                             "Needs pip install \"mrstereo[viz]\". [default: none]")(func)


def record_bag_option(func):
    """``--record-bag DIR``: a ROS 2 bag (MCAP) of the run's scans, clouds, map, odometry and TF."""
    return click.option("--record-bag", "record_bag", type=click.Path(file_okay=False, path_type=Path),
                        help="Also write a ROS 2 bag (MCAP) to this new folder: /scan, /points, /map, /odom, "
                             "/tf (docs/live.md).")(func)


VIEW_SUFFIXES = {"rerun": ".rrd", "foxglove": ".mcap"}
"""The file each viewer's stream is saved to: the view stem (OUT/view for live and map) with this suffix."""


def check_sink_options(viewers, record_bag: Path | None, view_stem: Path, inputs, *,
                       output_dirs=(), stamps_s=None) -> tuple[str, ...]:
    """Check ``--viewer`` (its package installed, its file ``view_stem`` + .rrd/.mcap) and ``--record-bag``
    (a new folder apart from the inputs and the ``output_dirs``; the recording's ``stamps_s`` when known, ones a
    bag holds) before any work; the viewers asked for."""
    from ..io import check_output_dir, check_outputs

    viewers = tuple(dict.fromkeys(v for v in viewers if v != "none"))
    if viewers:
        from ..viz.live import require_viewers

        require_viewers(viewers)
        files = [view_stem.with_suffix(VIEW_SUFFIXES[v]) for v in viewers]
        check_outputs({f"--viewer {v} (writes {f})": f for v, f in zip(viewers, files)}, inputs)
    if record_bag is not None:
        folders = [Path(p) for p in inputs if p is not None and Path(p).is_dir()]
        check_output_dir("--record-bag", record_bag, inputs=[p for p in inputs if p is not None],
                         input_dirs=folders + list(output_dirs), must_be_empty=True,
                         input_kind="input or output folder")
        if record_bag.exists():
            raise click.BadParameter(f"{record_bag} exists; give a new folder (a bag is a folder of its own)",
                                     param_hint="--record-bag")
        if stamps_s is not None:
            from ..recordings.bag_writer import check_bag_stamps

            check_bag_stamps(stamps_s)
    return viewers


def replayed_to_sinks(replay, stereo, view_stem: Path, viewers, record_bag: Path | None) -> None:
    """Open the sinks of ``--viewer``/``--record-bag`` of a finished run (the viewers' files only: the run is
    over), call ``replay(sinks)``, close them (discard on error) and say what was written."""
    from ..pipeline.sinks import open_sinks

    sinks = open_sinks(stereo, view_stem, viewers=viewers, record_bag=record_bag, rerun_mode="none",
                       foxglove_port=None)
    try:
        replay(sinks)
    except BaseException:
        for sink in sinks:
            sink.discard()
        raise
    for sink in sinks:
        sink.close()
    for viewer in viewers:
        click.echo(f"wrote {view_stem.with_suffix(VIEW_SUFFIXES[viewer])} ({viewer})")
    if record_bag is not None:
        click.echo(f"wrote the ROS 2 bag {record_bag}")


def _pair(text: str, option: str, kind=float, sep: str = ","):
    try:
        a, b = (kind(v) for v in text.lower().split(sep))
    except ValueError:
        raise click.BadParameter(f"expected two numbers 'a{sep}b', got {text!r}", param_hint=option) from None
    return a, b


@click.command("live")
@profile_option("read, rectify, match, reject, 3-D, free space, scan, odometry, grid, sinks")
@click.argument("sources", nargs=-1, required=True, metavar="SOURCE [SOURCE]")
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output folder: map.yaml + map.pgm, map.png, trajectory.txt, metrics.json, refreshed while it runs.")
@click.option("--calib", "calib", type=click.Path(dir_okay=False, path_type=Path),
              help=CALIB_HELP + " Needed for cameras and video files; a recording has its own.")
@click.option("--side-by-side", is_flag=True,
              help="The one camera or video holds the left image in the left half of each frame, the right in "
                   "the right half.")
@click.option("--realtime", is_flag=True,
              help="Replay a video file or recording at its recorded rate: the newest frame wins, the others are "
                   "dropped and counted (a camera always runs in real time).")
@click.option("--speed", type=Number(0.0, 1000.0, open_low=True), default=LiveConfig.speed, show_default=True,
              help="With --realtime: replay this many times faster than recorded (0.5: half speed).")
@click.option("--max-frames", type=Number(1, lambda: limit("MRSTEREO_MAX_FRAMES"), integer=True),
              default=None, help="Stop after N frames from the source.")
@click.option("--save-every", "save_every_s", type=Number(0.0, 86400.0, unit="s"),
              default=LiveConfig.save_every_s, show_default=True,
              help="Write the outputs every S seconds (and at the end).")
@click.option("--odometry", type=click.Choice(["visual", "given"]), default=None,
              help="Robot poses: stereo visual odometry, or the recording's own odometry. [default: the "
                   "recording's when it has one, else visual]")
@viewer_option
@record_bag_option
@map_options
@click.option("--workers", type=Number(1, max_workers, integer=True), default=LiveConfig.workers, show_default=True,
              help="Frames matched at once (threads; one per core).")
@click.option("--camera-size", default=None, metavar="WxH",
              help="Ask the camera for frames of this size (a side-by-side camera: the whole frame).")
@click.option("--camera-fps", type=Number(0.0, 1000.0, unit="Hz", open_low=True),
              default=None, help="Ask the camera for this frame rate.")
@click.option("--height", "height_m", type=HEIGHT, default=None,
              help="Camera height above the floor [m] (else the calibration's mount:/rig:, else estimated).")
@click.option("--tilt", "tilt_rad", type=TILT, default=None, help="Downward camera tilt [rad] (with --height).")
@mount_option
@click.option("--viewer-port", type=Number(0, 65535, integer=True), default=VIEWER_PORT, show_default=True,
              help="--viewer rerun without a display: the port of its data stream on 127.0.0.1 (connect a viewer "
                   "with `rerun rerun+http://127.0.0.1:PORT/proxy`).")
@click.option("--viewer-web-port", type=Number(1, 65535, integer=True), default=None,
              help="--viewer rerun: also serve Rerun's web viewer on this port (Rerun serves it on every interface "
                   "of the machine, not only localhost).")
@click.option("--foxglove-port", type=Number(0, 65535, integer=True), default=FOXGLOVE_PORT, show_default=True,
              help="--viewer foxglove: the port of its websocket server on 127.0.0.1.")
@truth_option
@click.option("--quiet", is_flag=True, help="No progress line.")
def live_command(sources: tuple[str, ...], out_dir: Path, calib: Path | None, side_by_side: bool, realtime: bool,
                 speed: float, max_frames: int | None, save_every_s: float, odometry: str | None,
                 viewers: tuple[str, ...], record_bag: Path | None, workers: int, camera_size: str | None,
                 camera_fps: float | None, height_m: float | None, tilt_rad: float | None, mount,
                 viewer_port: int, viewer_web_port: int | None, foxglove_port: int, quiet: bool,
                 no_mount_check: bool, truth, **options) -> None:
    """Map live from stereo cameras, video files or a recording.

    Cameras, video files or a recording in, a map out as it grows.

    SOURCE is a camera (an index such as 0, or a device path such as /dev/video0), a video
    file, or a recording (whatever `mrstereo map` reads). Two SOURCEs are the left and right
    camera or video; one camera or video with --side-by-side holds both images in each frame.

    Every frame is rectified, matched, ground-suppressed, triangulated and turned into a laser
    scan; the robot's pose comes from visual odometry (or the recording's odometry) and the map
    grows with it. When processing is slower than the source, the newest frame wins: older
    frames are dropped and counted. The outputs are written atomically every --save-every
    seconds and at the end (a map_server can reload OUT/map.yaml). Ctrl-C stops the run and
    writes the outputs (a second Ctrl-C aborts). docs/live.md.
    """
    from ..camera import read_stereo
    from ..io import check_output_dir, check_outputs
    from ..pipeline.live import run_live
    from ..recordings.sources import is_camera, open_source

    if len(sources) > 2:
        raise click.UsageError(f"give one or two SOURCEs (left and right), got {len(sources)}")
    for value, option in ((save_every_s, "--save-every"), (speed, "--speed")):
        if not (value > 0 and value < float("inf")):
            raise click.BadParameter(f"must be a number > 0, got {value}", param_hint=option)
    config = map_config(**options)
    size = _pair(camera_size, "--camera-size", int, "x") if camera_size else None
    file_inputs = [Path(s) for s in sources if not is_camera(s)] + ([calib] if calib is not None else [])
    check_output_dir("--out", out_dir, inputs=file_inputs,
                     input_dirs=[p for p in file_inputs if p.is_dir()])
    check_outputs({f"--out {out_dir / name}": out_dir / name for name in LIVE_FILES}, file_inputs)
    viewers = check_sink_options(viewers, record_bag, out_dir / "view", file_inputs, output_dirs=[out_dir])
    _check_ports(viewers, viewer_port, viewer_web_port, foxglove_port)
    sinks_needed = bool(viewers) or record_bag is not None
    stereo = read_stereo(calib) if calib is not None else None
    from .._warmup import warm_up

    warm_up(say=lambda line: click.echo(line, err=True))      # compiled before the source opens: no frame dropped
    with open_source(sources, side_by_side=side_by_side, prefer_raw=calib is not None, size=size,
                     rate_hz=camera_fps, truth=truth) as source:
        stereo = stereo or source.calibration
        if stereo is None:
            raise click.UsageError("cameras and video files need --calib (a stereo calibration)")
        camera_mount = mount_from_options(height_m, tilt_rad, mount, stereo)
        live = LiveConfig(save_every_s=save_every_s, max_frames=max_frames, realtime=realtime, speed=speed,
                          workers=workers, odometry=odometry, check_mount=not no_mount_check)
        sinks = []
        try:
            if sinks_needed:
                from ..pipeline.sinks import open_sinks

                sinks = open_sinks(stereo, out_dir / "view", viewers=viewers, record_bag=record_bag, echo=click.echo,
                                   viewer_port=viewer_port, viewer_web_port=viewer_web_port,
                                   foxglove_port=foxglove_port)
            stop = threading.Event()
            with _stop_on_signals(stop, quiet):
                run = run_live(source, out_dir, calibration=stereo, mount=camera_mount, config=config, live=live,
                               sinks=sinks, stop=stop, on_save=None if quiet else _progress)
        except BaseException as exc:
            if not isinstance(exc, KeyboardInterrupt):      # (run_live discarded them; a failed start: here)
                for sink in sinks:
                    try:
                        sink.discard()
                    except Exception:
                        pass
            raise
    m = run.metrics()
    if not quiet:
        click.echo("", err=True)
    click.echo(f"live ({run.stopped}): {run.frames_in} frames in, {run.frames_processed} processed "
               f"({run.frames_dropped} dropped), {run.frames_mapped} mapped at {m['rate_hz']:.1f} Hz; latency "
               f"median {m['latency_ms']['median']:.0f} ms, p95 {m['latency_ms']['p95']:.0f} ms; odometry "
               f"{run.odometry}{f' ({run.frames_lost} frames lost)' if run.frames_lost else ''}")
    if run.mount_warning:
        from ._options import warn

        warn(run.mount_warning)
    if run.floor is not None and run.floor.method != "mount":
        click.echo(f"floor {run.floor.message}: height {run.floor.height_m:.3f} m, tilt {run.floor.tilt_rad:.4f} rad")
    click.echo(f"wrote {', '.join(LIVE_FILES)}{''.join(f', {n}' for n in _view_files(viewers))} to {out_dir}"
               + (f"; the bag to {record_bag}" if record_bag is not None else ""))


def _check_ports(viewers, viewer_port: int, viewer_web_port: int | None, foxglove_port: int) -> None:
    """The ports the viewers will listen on, free before any work (one line naming the option otherwise)."""
    from ..viz.live import check_port

    if "rerun" in viewers:
        check_port(viewer_port, "--viewer-port")
        if viewer_web_port is not None:
            check_port(viewer_web_port, "--viewer-web-port")
    if "foxglove" in viewers:
        check_port(foxglove_port, "--foxglove-port")


def _view_files(viewers) -> list[str]:
    return [{"rerun": "view.rrd", "foxglove": "view.mcap"}[v] for v in viewers]


def _progress(run) -> None:
    m = run.metrics()
    click.echo(f"\rlive: {run.frames_in} in, {run.frames_processed} processed, {run.frames_dropped} dropped, "
               f"{m['rate_hz']:.1f} Hz, latency {m['latency_ms']['median']:.0f} ms   ", err=True, nl=False)


class _stop_on_signals:
    """While active, the first Ctrl-C (or SIGTERM) sets ``stop`` (the run ends and writes its outputs); a
    second one goes to the handler before (mrstereo's: one line, exit 130)."""

    def __init__(self, stop: threading.Event, quiet: bool) -> None:
        self.stop, self.quiet, self.previous = stop, quiet, {}

    def _handler(self, signum, frame) -> None:
        if self.stop.is_set():
            previous = self.previous.get(signum)
            if callable(previous):
                previous(signum, frame)
            raise KeyboardInterrupt
        self.stop.set()
        click.echo("\nmrstereo: stopping: writing the outputs (Ctrl-C again to abort)", err=True)
        reached("stopping")

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGINT, signal.SIGTERM):
                self.previous[sig] = signal.signal(sig, self._handler)
        return self

    def __exit__(self, *exc) -> None:
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)


COMMANDS = [live_command]
