"""CLI of recordings and scale-out: ``mrstereo export`` (a ROS bag to a dataset directory) and
``mrstereo batch`` (many datasets: per-frame disparity, cloud and scan, and a map each, on Dask).

:func:`bag_options` is shared with ``mrstereo map --bag`` (cli/_pipeline.py). docs/scale-out.md.

Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
from pathlib import Path

import click

from ._options import (CALIB_HELP, HEIGHT, TILT, Number, check_mount_options, check_workers, echo_run_floor,
                       map_config, map_options, mount_from_options, mount_option, parse_mount, truth_option, warn,
                       worker_options)

__all__ = ["COMMANDS", "BAG_KEYS", "bag_options", "bag_export_kwargs", "worker_options", "opened_dataset",
           "opened_source", "recording_options", "recording_of", "read_inputs"]


BAG_KEYS = ("left_topic", "right_topic", "camera_info_topics", "odom_topic", "use_tf", "world_frame", "base_frame",
            "camera_frame", "sync_tolerance_s", "rectified_images", "height_m", "tilt_rad", "mount")
"""The parameter names of :func:`bag_options`."""


def bag_options(func):
    """Options naming the topics of a ROS bag (``--bag`` itself is added by the command)."""
    options = [
        click.option("--left-topic", help="Left image topic (sensor_msgs/Image or CompressedImage)."),
        click.option("--right-topic", help="Right image topic."),
        click.option("--camera-info-topics", metavar="LEFT,RIGHT",
                     help="Left and right sensor_msgs/CameraInfo topics (default: <image ns>/camera_info; "
                          "not needed with --calib)."),
        click.option("--odom-topic", help="nav_msgs/Odometry topic giving the robot pose."),
        click.option("--tf", "use_tf", is_flag=True,
                     help="Take the robot pose from /tf and /tf_static (base frame in map, else odom)."),
        click.option("--world-frame", default=None, help="TF world frame (default: map if connected, else odom)."),
        click.option("--base-frame", default="base_link", show_default=True, help="TF frame of the robot."),
        click.option("--camera-frame", default=None,
                     help="TF frame of the left camera (an *_optical_frame, else the camera body frame "
                          "x forward): its pose in --base-frame is the camera mount (unless --mount or "
                          "--height is given), its change of heading the head pan."),
        click.option("--sync-tolerance", "sync_tolerance_s", type=Number(0.0, 10.0, unit="s"), default=0.02,
                     show_default=True,
                     help="Largest left/right stamp difference of a stereo pair [s]."),
        click.option("--rectified-images", is_flag=True, help="The bag's images are already rectified."),
        click.option("--height", "height_m", type=HEIGHT, default=None,
                     help="Camera height above the floor [m] (else the stereo YAML mount:/rig:, else estimated)."),
        click.option("--tilt", "tilt_rad", type=TILT, default=None,
                     help="Downward camera tilt [rad] (with --height)."),
    ]
    for option in reversed(options):
        func = option(func)
    return mount_option(func)


def bag_export_kwargs(*, bag, calib, left_topic, right_topic, camera_info_topics, odom_topic, use_tf, world_frame,
                      base_frame, camera_frame, sync_tolerance_s, rectified_images, height_m, tilt_rad,
                      mount, quiet) -> dict:
    """Validate the bag options and turn them into :func:`mrstereo.recordings.bag.export_bag` keywords.

    Without ``--left-topic``/``--right-topic`` the bag's one stereo pair is picked (and its one odometry
    topic). ``--height``/``--tilt`` describe the rectified camera: without ``--calib`` the bag's camera_info
    is read first.
    """
    from ..camera import read_stereo
    from ..recordings.bag import stereo_from_bag, with_picked_topics

    if odom_topic and use_tf:
        raise click.UsageError("give --odom-topic or --tf, not both")
    info = None
    if camera_info_topics:
        info = tuple(t.strip() for t in camera_info_topics.split(","))
        if len(info) != 2 or not all(info):
            raise click.BadParameter(f"expected 'LEFT,RIGHT', got {camera_info_topics!r}",
                                     param_hint="--camera-info-topics")
    check_mount_options(height_m, tilt_rad, mount)
    calibration = read_stereo(calib) if calib is not None else None
    topics = with_picked_topics(bag, dict(left_topic=left_topic, right_topic=right_topic, odom_topic=odom_topic,
                                          use_tf=use_tf, calibration=calibration, camera_info_topics=info))
    if calibration is None and height_m is not None:
        calibration = stereo_from_bag(bag, left_topic=topics["left_topic"], right_topic=topics["right_topic"],
                                      camera_info_topics=info)
    return dict(left_topic=topics["left_topic"], right_topic=topics["right_topic"], camera_info_topics=info,
                calibration=calibration, odom_topic=topics["odom_topic"], use_tf=use_tf, world_frame=world_frame,
                base_frame=base_frame, camera_frame=camera_frame, sync_tolerance_s=sync_tolerance_s,
                mount=mount_from_options(height_m, tilt_rad, mount, calibration), rectified=rectified_images,
                progress=not quiet)


def read_inputs(manifest, bag: Path | None, calib: Path | None, *, rate_hz: float | None = None, truth=None):
    """Read what a command's recording is made of, before any work: ``(dataset, bag)``, the dataset None
    for a bag (``--bag`` or a RECORDING that is one), whose files are registered instead; ``--calib`` too.
    Every output check that follows sees them all (:func:`mrstereo.io.protecting_inputs`), calibration
    siblings such as OpenLORIS' trans_matrix.yaml too. ``truth``: ``--truth FILE`` / ``--no-truth``
    (:func:`mrstereo.recordings.read_recording`), a bag's applied when it is opened."""
    from ..camera import read_stereo
    from ..io import note_inputs
    from ..recordings.bag import bag_inputs
    from ..recordings.layouts import layout_of, read_recording
    from ..recordings.manifest import Manifest

    if bag is None and not isinstance(manifest, Manifest):
        manifest, is_bag = recording_of(manifest, None)
        if is_bag:
            manifest, bag = None, manifest
    if calib is not None:
        read_stereo(calib)
    if bag is not None:
        note_inputs(bag_inputs(bag))
        return None, bag
    if isinstance(manifest, Manifest):
        return manifest, None
    folders = layout_of(manifest) == "image folders"
    if rate_hz is not None and not folders:
        raise click.UsageError("--rate only with image folders")
    return read_recording(manifest, calibration=calib if folders else None, rate_hz=rate_hz, truth=truth), None


def recording_options(func):
    """The options of a command reading a RECORDING: ``--bag`` and the bag's topic options, ``--rate``,
    ``--truth``/``--no-truth`` (the command gets ``truth``)."""
    func = truth_option(bag_options(func))
    func = click.option("--rate", "rate_hz", type=Number(0.0, 1000.0, unit="Hz", open_low=True), default=None,
                        help="Frame rate [Hz] of image folders whose file names are not time stamps.")(func)
    return click.option("--bag", "bag", type=click.Path(path_type=Path),
                        help="A ROS 1 .bag / ROS 2 bag directory (also accepted as RECORDING).")(func)


def recording_of(path: Path | None, bag: Path | None) -> tuple[Path, bool]:
    """The path a command reads and whether it is a bag: RECORDING or ``--bag`` (one of them)."""
    from ..recordings.layouts import is_bag

    if (path is None) == (bag is None):
        raise click.UsageError("give a RECORDING or --bag FILE (one of them)")
    return (bag, True) if bag is not None else (path, is_bag(path))


@contextlib.contextmanager
def opened_dataset(manifest, bag: Path | None, calib: Path | None, *, quiet: bool, bag_kw: dict,
                   rate_hz: float | None = None, truth=None):
    """The recording a command works on: ``(recording, stereo, stamps_s)``.

    A ROS bag (``--bag``, or a RECORDING that is one; topics picked when not given) is a
    :class:`~mrstereo.recordings.bag.BagSource` read message by message, never exported (:func:`opened_source`;
    ``stereo`` None: the bag's calibration or ``--calib`` is in it), open for the ``with`` block, with its
    stamps in seconds. Any other RECORDING (a path, or a Manifest already read) is a Manifest with
    ``--height``/``--tilt``/``--mount`` applied and ``--calib`` read (``stereo`` None: the recording's own
    calibration; stamps None). Image folders take ``--calib`` as their calibration and ``--rate`` as their
    frame rate; ``truth`` is ``--truth FILE`` / ``--no-truth``.
    """
    import dataclasses

    from ..camera import read_stereo
    from ..recordings.layouts import layout_of, read_recording
    from ..recordings.manifest import Manifest

    if bag is None and not isinstance(manifest, Manifest):
        manifest, is_bag = recording_of(manifest, None)
        if is_bag:
            manifest, bag = None, manifest
    if bag is not None:
        with opened_source(None, bag, calib, quiet=quiet, bag_kw=bag_kw, rate_hz=rate_hz, truth=truth) as source:
            yield source, None, source.stamps_s
        return
    _no_bag_options(bag_kw)
    if isinstance(manifest, Manifest):
        dataset = manifest
    else:
        folders = layout_of(manifest) == "image folders"
        if rate_hz is not None and not folders:
            raise click.UsageError("--rate only with image folders")
        dataset = read_recording(manifest, calibration=calib if folders else None, rate_hz=rate_hz, truth=truth)
    stereo = read_stereo(calib) if calib is not None else None
    mount = mount_from_options(bag_kw["height_m"], bag_kw["tilt_rad"], bag_kw.get("mount"),
                               dataset.calibration if stereo is None else stereo)
    if mount is not None:
        dataset = dataclasses.replace(dataset, mount=mount)
    yield dataset, stereo, None


def _no_bag_options(bag_kw: dict) -> None:
    """Refuse the bag options given to a RECORDING that is not a bag."""
    used = [f"--{k.replace('_', '-')}" for k, v in bag_kw.items()
            if v not in (None, False) and k not in ("height_m", "tilt_rad", "mount", "base_frame", "sync_tolerance_s")]
    if used:
        raise click.UsageError(f"{', '.join(used)} only with a ROS bag")


@contextlib.contextmanager
def opened_source(recording, bag: Path | None, calib: Path | None, *, quiet: bool, bag_kw: dict,
                  rate_hz: float | None = None, truth=None):
    """The recording a command works on as a :class:`~mrstereo.recordings.sources.FrameSource`
    (:func:`mrstereo.recordings.open_recording`), open for the ``with`` block.

    A ROS bag (``--bag``, or a RECORDING that is one) is read message by message with the bag options
    (topics picked when not given; one line on stderr says what was found). Any other RECORDING gets
    ``--height``/``--tilt``/``--mount`` as its mount; ``--calib`` is the calibration of image folders,
    and replaces any other recording's (whose raw images are then read); ``--rate`` the frame rate of
    image folders; ``truth`` is ``--truth FILE`` / ``--no-truth``.
    """
    from ..recordings.layouts import layout_of, open_recording

    path, is_bag = recording_of(recording, bag)
    if is_bag:
        from ..recordings.bag import BagSource

        if rate_hz is not None:
            raise click.UsageError("--rate only with image folders")
        source = BagSource(path, truth=truth, **bag_export_kwargs(bag=path, calib=calib, quiet=quiet, **bag_kw))
        echo_export(source)
    else:
        _no_bag_options(bag_kw)
        folders = layout_of(path) == "image folders"
        if rate_hz is not None and not folders:
            raise click.UsageError("--rate only with image folders")
        source = open_recording(path, calibration=calib, prefer_raw=calib is not None and not folders,
                                rate_hz=rate_hz, truth=truth)
        mount = mount_from_options(bag_kw["height_m"], bag_kw["tilt_rad"], bag_kw.get("mount"), source.calibration)
        if mount is not None:
            source.mount = mount
    with source:
        yield source


def echo_export(result) -> None:
    """One line on stderr of what a bag gave (a :class:`~mrstereo.recordings.bag.BagExport` or ``BagSource``)."""
    from ..geometry.ground import ground_from_mount

    mount = "none (the floor is estimated when mapping)"
    if result.mount is not None:
        floor = ground_from_mount(result.mount, R_rect_from_cam=result.calibration.left.R)
        mount = f"height {floor.height_m:.3f} m, tilt {floor.tilt_rad:.3f} rad ({result.mount_source})"
    click.echo(f"bag: {result.n_frames} stereo pairs from {result.n_left} left / {result.n_right} right images; "
               f"pose: {result.pose_source}; mount: {mount}", err=True)


@click.command("export")
@click.option("--bag", "bag", required=True, type=click.Path(path_type=Path),
              help="ROS 1 .bag file or ROS 2 bag directory (sqlite3 or mcap).")
@bag_options
@click.option("--calib", "calib", type=click.Path(dir_okay=False, path_type=Path),
              help=CALIB_HELP + " Used instead of the camera_info topics.")
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="New dataset directory (manifest.yaml, stereo.yaml, left/, right/).")
@click.option("--quiet", is_flag=True, help="No progress bar.")
def export_command(bag: Path, out_dir: Path, quiet: bool, **options) -> None:
    """Write the stereo pairs of a ROS bag as a dataset.

    The dataset folder given by -o is laid out as docs/dataset.md describes.

    Left and right images are paired by header stamp, the calibration comes
    from camera_info (or --calib), the robot pose from --odom-topic or --tf.
    Every command that reads a DATASET then reads the recording.
    """
    from ..io import check_output_dir
    from ..recordings.sources import check_pair_streams
    from ..recordings.bag import export_bag
    from ..recordings.manifest import read_manifest

    read_inputs(None, bag, options.get("calib"))
    check_output_dir("--out", out_dir, must_be_empty=True)
    kwargs = bag_export_kwargs(bag=bag, quiet=quiet, **options)
    result = export_bag(bag, out_dir, **kwargs)
    echo_export(result)
    check_pair_streams(read_manifest(out_dir))
    click.echo(f"wrote {result.n_frames} frames to {out_dir} (manifest: {out_dir / 'manifest.yaml'})")


@click.command("batch")
@click.argument("manifests", nargs=-1, required=True, metavar="RECORDINGS...", type=click.Path(path_type=Path))
@click.option("-o", "--out", "out_dir", required=True, type=click.Path(file_okay=False, path_type=Path),
              help="Output directory: one folder per recording and summary.json.")
@worker_options
@map_options
@click.option("--no-maps", is_flag=True, help="Only the per-frame outputs, no map per dataset.")
@mount_option
@truth_option
@click.option("--quiet", is_flag=True, help="No progress bar.")
def batch_command(manifests, out_dir: Path, workers, scheduler, processes: bool, no_maps: bool, mount, quiet: bool,
                  no_mount_check: bool, truth, **options) -> None:
    """Process many recordings into per-frame outputs and maps.

    RECORDINGS are dataset folders, KITTI odometry or EuRoC/ASL folders and
    ROS bags (`mrstereo info` shows what is read). Per frame a disparity
    (PFM), a point cloud (PLY) and a laser scan (JSON); per recording a map,
    as `mrstereo map` makes it, with the same map options. A bag (its one
    stereo pair and odometry topic picked) is read as a stream and gives its
    map only. Resumable: finished outputs are kept on a re-run, failed frames
    are retried; a bag's map is kept while the bag and options are unchanged.

    Failures of single frames are listed in OUT/summary.json and the rest goes on;
    the command then ends with an error line naming how many failed. A dataset
    without a camera mount (and no --mount) uses the floor estimated from its
    first frames (reported per dataset, with its confidence); a given mount
    that disagrees with that floor is replaced by it, with a warning.
    """
    import dataclasses

    from ..io import check_output_dir
    from ..pipeline.batch import run_batch
    from ..recordings.bag import BagSource
    from ..recordings.layouts import is_bag, read_recording

    check_workers(workers, scheduler, processes)
    config = map_config(**options)
    camera_mount = parse_mount(mount)
    if truth and len(manifests) > 1:
        raise click.UsageError(f"--truth FILE is the truth of one recording, got {len(manifests)} RECORDINGS")
    manifests = [BagSource(m, mount=camera_mount, truth=truth) if is_bag(m) else read_recording(m, truth=truth)
                 for m in manifests]
    check_output_dir("--out", out_dir)
    if camera_mount is not None:
        manifests = [m if isinstance(m, BagSource) else dataclasses.replace(m, mount=camera_mount) for m in manifests]
    summary = run_batch(manifests, out_dir, config=config, maps=not no_maps, workers=workers,
                        scheduler=scheduler, processes=processes, progress=not quiet, check_mount=not no_mount_check)
    for d in summary.datasets:
        click.echo(f"{d.name}: {d.n_frames} frames ({d.n_computed} computed, {d.n_skipped} already done, "
                   f"{d.n_failed} failed){'; map ' + d.map_status if d.map_status else ''}")
        echo_run_floor(d.floor, prefix=f"{d.name}: floor")
        if d.mount_warning:
            warn(f"{d.name}: {d.mount_warning}")
    click.echo(f"wrote {out_dir} (summary: {summary.path})")
    if summary.failures:
        first = summary.failures[0]
        raise RuntimeError(f"{len(summary.failures)} frame(s) failed, listed in {summary.path}; first: "
                           f"{first['dataset']} frame {first['frame']}: {first['error']}")


COMMANDS = [export_command, batch_command]
