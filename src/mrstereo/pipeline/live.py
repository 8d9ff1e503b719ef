"""The live loop: frames from a camera (or a file, or a recording) to a map, a trajectory and a scan, as they come.

Three kinds of threads, never a growing queue between them: capture into a one-frame slot
(:class:`LatestFrame`; the newest frame wins), matchers running the per-frame chain -- match
(eq. 9-12), reject (eq. 13), 3-D (eq. 14-16), scan (:func:`mrstereo.geometry.pair.scan_from_pair`)
-- and the fuser (the calling thread: pose, grid, sinks). A writer thread saves snapshots every
``save_every_s`` seconds, each file atomically. How it keeps up: docs/live.md.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
import math
import os
import threading
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..camera import CameraMount, StereoCamera
from ..evaluation.outputs import LiveRun, write_live_outputs
from ..geometry.pair import Observed
from ..odometry import LOST
from ..profiling import Profile, active, profiling, stage
from ..recordings.sources import FrameSource, StereoFrame, paced
from .. import _checks
from .._interrupt import reached
from .._executor import Growing, StreamThreads, Writer, peak_rss_mb, rss_mb
from ..mapping.sinks import LiveFrame
from .mapper import MappedFrame, PipelineConfig, StereoMapper
from .run import config_for_recording

__all__ = ["LiveConfig", "run_live"]

@dataclass(frozen=True)
class LiveConfig:
    """Options of the live loop (docs/live.md).

    Attributes
    ----------
    save_every_s : float
        Write the outputs this often [s] (and at the end).
    max_frames : int, optional
        Stop after this many frames from the source.
    realtime : bool
        Replay a file or recording at its recorded rate (newest frame wins, as from a camera);
        a camera is always real time. Off: every frame of a file is processed.
    speed : float
        With ``realtime``: replay this many times faster than recorded.
    workers : int
        Frames matched at once (threads; one per core).
    odometry : {"visual", "given"} or None
        The robot's pose: stereo visual odometry, or the recording's own odometry; None: the
        recording's when it has one, else visual.
    check_mount : bool
        Check a given mount against the floor seen in the first frames (as ``mrstereo map`` does).
    """

    save_every_s: float = 5.0
    max_frames: int | None = None
    realtime: bool = False
    speed: float = 1.0
    workers: int = 2
    odometry: str | None = None
    check_mount: bool = True

    def __post_init__(self) -> None:
        if not (math.isfinite(self.save_every_s) and self.save_every_s > 0):
            raise ValueError(f"save_every_s must be a finite number > 0, got {self.save_every_s!r}")
        if self.max_frames is not None and int(self.max_frames) < 1:
            raise ValueError(f"max_frames must be >= 1, got {self.max_frames!r}")
        if not (math.isfinite(self.speed) and self.speed > 0):
            raise ValueError(f"speed must be a finite number > 0, got {self.speed!r}")
        if _checks.positive_int("workers", self.workers) > 2:    # (the default, 2, also on one core)
            _checks.workers("workers", self.workers)
        if self.odometry not in (None, "visual", "given"):
            raise ValueError(f"odometry must be 'visual', 'given' or None, got {self.odometry!r}")


@dataclass
class _Matched:
    """A frame through the matcher (:meth:`StereoMapper.observe`), with its arrival time."""

    frame: StereoFrame
    arrival_s: float
    observed: Observed | None = None
    error: BaseException | None = None


class _Fuser:
    """The ordered part of the loop: the mapper's integration (floor, pose, map), sinks (the calling thread)."""

    def __init__(self, mapper: StereoMapper, live: LiveConfig, sinks: Sequence, run: LiveRun) -> None:
        self.mapper, self.live, self.sinks, self.run = mapper, live, list(sinks), run
        self.latencies = Growing(())

    def fuse(self, item) -> None:
        run, mapper = self.run, self.mapper
        run.frames_processed += 1
        mapper.check_streams(item.frame)
        for mapped in mapper.integrate(item.observed):
            if mapped.status == LOST:
                continue
            self.latencies.append(1000.0 * (time.perf_counter() - item.arrival_s))
            if self.sinks:
                self._sinks(mapped)
        run.frames_mapped, run.frames_lost = len(mapper.trajectory_index), mapper.frames_lost
        run.frames_before_floor = mapper.frames_held
        run.floor, run.mount = mapper.floor, mapper.mount
        run.mount_warning = mapper.mount_warning

    def fuse_rest(self) -> None:
        """The end of the source: the frames still held for the floor estimate are mapped."""
        mapper = self.mapper
        for mapped in mapper.finish():
            if self.sinks and mapped.status != LOST:
                self._sinks(mapped)
        self.run.frames_mapped, self.run.frames_lost = len(mapper.trajectory_index), mapper.frames_lost
        self.run.frames_before_floor = 0
        self.run.floor, self.run.mount, self.run.mount_warning = mapper.floor, mapper.mount, mapper.mount_warning

    def _sinks(self, mapped: MappedFrame) -> None:
        out = LiveFrame(index=mapped.index, stamp_s=mapped.stamp_s, T_world_from_base=mapped.T_world_from_base,
                        T_base_from_cam=mapped.T_base_from_cam, left_rect=mapped.left_rect,
                        disparity_px=mapped.disparity_px, obstacle_points_robot=mapped.obstacle_points_robot,
                        scan=mapped.scan, grid=self.mapper.grid, status=mapped.status)
        with stage("sinks"):
            for sink in self.sinks:
                sink.frame(out)


def run_live(source: FrameSource, out_dir: str | os.PathLike, *, calibration: StereoCamera | None = None,
             mount: CameraMount | None = None, config: PipelineConfig | None = None,
             live: LiveConfig = LiveConfig(), sinks: Sequence = (), stop: threading.Event | None = None,
             on_save: Callable[[LiveRun], None] | None = None) -> LiveRun:
    """Run the chain on a source as its frames come; write the outputs while it runs and at the end.

    Parameters
    ----------
    source : FrameSource
        Cameras, video files or a recording (:func:`mrstereo.recordings.sources.open_source`).
    out_dir : path
        Output folder (created): map.yaml, map.pgm, map.png, trajectory.txt, metrics.json.
    calibration : StereoCamera, optional
        The rig's calibration (default: the source's; a camera or video needs one).
    mount : CameraMount, optional
        The camera on the robot (default: the source's, else the calibration's; with none the floor is
        estimated from the first frames).
    config : PipelineConfig, optional
        Every stage's options (default: the map's; a map that grows, or the window of the recording's
        ground-truth map).
    live : LiveConfig
        Rate, saving, workers, odometry.
    sinks : sequence
        Objects with ``frame(LiveFrame)``, ``close()`` and ``discard()`` (viewers, a ROS bag):
        ``frame`` for every mapped frame in order, ``close`` at the end, ``discard`` after an error.
    stop : threading.Event, optional
        Set it (from a signal handler, another thread) to end the run: the frames in flight are
        finished and the outputs written. KeyboardInterrupt does the same and is raised again after.
    on_save : callable, optional
        Called with the run after each snapshot (progress display).
    """
    stereo = calibration if calibration is not None else source.calibration
    if not isinstance(stereo, StereoCamera):
        raise ValueError(f"{source.name}: no calibration: give one (--calib)")
    if not isinstance(live, LiveConfig):
        raise TypeError(f"live must be a LiveConfig, got {type(live).__name__}")
    if live.odometry == "given" and not source.has_poses:
        raise ValueError(f"{source.name} has no odometry of its own: use visual odometry")
    odometry = live.odometry or ("given" if source.has_poses else "visual")
    config = config_for_recording(PipelineConfig() if config is None else config, source.ground_truth_map)
    mapper = StereoMapper(stereo, mount or source.mount or stereo.mount, config, check_mount=live.check_mount,
                          odometry=odometry, pose_frame_mount=source.pose_frame_mount, name=source.name)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    run = LiveRun(grid=mapper.grid, stamps_s=np.empty(0), T_world_from_base=np.empty((0, 4, 4)), source=source.name,
                  odometry=odometry)
    fuser = _Fuser(mapper, live, sinks, run)
    stop = stop or threading.Event()
    frames = paced(source, speed=live.speed, stop=stop) if live.realtime and not source.realtime else source
    threads = StreamThreads(frames, lambda frame: _Matched(frame=frame, arrival_s=time.perf_counter()),
                            _observe_with(mapper), workers=live.workers, lossless=not (source.realtime or live.realtime),
                            max_items=live.max_frames, stop=stop)
    clock = _Clock(profile=active() or Profile())
    writer = Writer(lambda snapshot: run.files.update(write_live_outputs(out, snapshot)))
    interrupted = None
    with profiling(clock.profile):
        threads.start()
        try:
            _fuse_in_order(threads, fuser, writer, clock, on_save)
            fuser.fuse_rest()
        except KeyboardInterrupt as exc:
            interrupted = exc
            run.stopped = "interrupted"
        except BaseException:
            threads.join()
            writer.close()
            for sink in sinks:
                with contextlib.suppress(Exception):        # (the error raised is the run's)
                    sink.discard()
            raise
        finally:
            requested = threads.stop.is_set()
            threads.join()
    if run.stopped == "end of source":
        run.stopped = threads.counts.get("end", "stopped" if requested else "end of source")
    writer.submit(_snapshot(run, fuser, threads, clock))
    writer.close()
    if fuser.mapper.outside_warning():
        warnings.warn(fuser.mapper.outside_warning(), stacklevel=2)
    for sink in sinks:
        sink.close()
    if writer.error is not None:
        raise writer.error
    if interrupted is not None:
        raise interrupted
    return run


def _observe_with(mapper: StereoMapper) -> Callable:
    def work(item: _Matched) -> None:
        item.observed = mapper.observe(item.frame)
    return work


@dataclass
class _Clock:
    """When the run started (wall and CPU), the fuser's CPU time, the stage profile."""

    profile: Profile
    start_s: float = field(default_factory=time.perf_counter)
    cpu_start_s: float = field(default_factory=time.process_time)
    fuse_cpu_s: float = 0.0


def _fuse_in_order(threads: StreamThreads, fuser: _Fuser, writer: Writer, clock: _Clock,
                   on_save: Callable[[LiveRun], None] | None) -> None:
    """The fuser: the matched frames in the order taken into the map; a snapshot every ``save_every_s``."""
    next_ticket, last_save = 0, time.perf_counter()
    while True:
        item = threads.ordered.get(next_ticket, 0.1)
        if item is None:
            if threads.stop.is_set():
                threads.slot.discard()
            if threads.errors:              # the source failed (a frame of another size...)
                raise threads.errors[0]
            if not threads.matching() and next_ticket >= threads.slot.tickets:
                return
        else:
            next_ticket += 1
            threads.in_flight.release()
            if item.error is not None:
                raise item.error
            t0 = time.thread_time()
            fuser.fuse(item)
            clock.fuse_cpu_s += time.thread_time() - t0
            reached("frame")
        if writer.error is not None:
            raise writer.error
        if threads.errors:
            raise threads.errors[0]
        now = time.perf_counter()
        if now - last_save >= fuser.live.save_every_s:
            last_save = now
            writer.submit(_snapshot(fuser.run, fuser, threads, clock))
            if on_save is not None:
                on_save(fuser.run)


def _snapshot(run: LiveRun, fuser: _Fuser, threads: StreamThreads, clock: _Clock) -> dict:
    """Bring the run's counts up to date and copy what the writer needs."""
    run.frames_in = threads.counts["in"]
    run.frames_dropped = threads.slot.dropped
    run.duration_s = time.perf_counter() - clock.start_s
    run.latency_ms = fuser.latencies.view().copy()
    mapper = fuser.mapper
    run.stamps_s = np.array(mapper.trajectory_stamps_s)
    run.T_world_from_base = np.array(mapper.trajectory_T) if mapper.trajectory_T else np.empty((0, 4, 4))
    run.grid = mapper.occupancy()
    run.cpu_s = {"process": time.process_time() - clock.cpu_start_s, "fuser": clock.fuse_cpu_s, **threads.cpu}
    run.stage_ms = clock.profile.per_frame_ms(max(run.frames_processed, 1))
    run.memory_mb, run.peak_memory_mb = rss_mb(), peak_rss_mb()
    metrics = run.metrics()
    comment = (f"mrstereo live: {run.source}; odometry {run.odometry}; {run.frames_mapped} frames mapped of "
               f"{run.frames_in}\nthe robot base in the world (REP 103), each frame's pose as known at that frame")
    return {"ros_map": run.grid.to_ros_map(), "T_world_from_base": run.T_world_from_base, "stamps_s": run.stamps_s,
            "metrics": metrics, "comment": comment}
