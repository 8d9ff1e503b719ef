"""The live loop's rate and latency: a stereo video played at its real rate through ``cv2.VideoCapture``
(docs/live.md).

    python benchmarks/bench_live.py [--frames 150] [--rate 15] [--repeats 3]
    python benchmarks/bench_live.py --euroc [--euroc-frames 200]      # 752x480, the real EuRoC frames

640x480: the corridor rendered along an S-curve (5 cm per frame), written as one lossless
side-by-side video at ``--rate`` frames per second, replayed with ``--realtime`` (the newest frame
wins, as from a camera) through the whole chain: rectify, match, reject, 3-D, scan, visual
odometry, the growing map (tiles of 5 cm cells, as ``mrstereo map``).
The same video is then read as fast as it goes (nothing dropped): the loop's throughput.
``--euroc``: the real EuRoC frames (752x480, ``$MRSTEREO_DATA/euroc_asl_sample``) driven forth and
back to ``--euroc-frames`` frames in a 20 Hz side-by-side video, replayed in real time; the camera's
height and tilt are estimated from the floor in the first frames (a MAV's camera has no mount).

Printed per run (medians over ``--repeats``): frames processed per second, frames dropped, the
latency from a frame's arrival to the map's update (median and 95th percentile), the time per
frame of each stage (wall time summed over the threads that ran it), and the CPU time of each
thread over the run's wall time: how the cores are used. With ``--long N``: N frames of the
160x120 corridor as fast as they go, the resident memory every second (flat or not).
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from pathlib import Path

import cv2
import numpy as np

from mrstereo.camera import read_stereo
from mrstereo.pipeline.live import LiveConfig, run_live
from mrstereo.pipeline.run import PipelineConfig
from mrstereo.recordings import read_recording
from mrstereo.recordings.samples import data_root
from mrstereo.recordings.sources import FrameSource, RecordingSource, StereoFrame, VideoSource
from mrstereo.world.dataset import write_synthetic_dataset


def side_by_side_video(lefts, rights, path: Path, rate_hz: float) -> Path:
    """A lossless (FFV1) side-by-side video of the pairs: what a USB stereo camera delivers."""
    h, w = lefts[0].shape[:2]
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), rate_hz, (2 * w, h), isColor=False)
    if not writer.isOpened():
        raise RuntimeError("this OpenCV cannot write FFV1 video")
    for left, right in zip(lefts, rights):
        writer.write(np.hstack([left, right]))
    writer.release()
    return path


def corridor(folder: Path, n_frames: int, width: int, height: int, rate_hz: float):
    dataset = write_synthetic_dataset(folder / f"corridor_{width}", n_frames=n_frames, width=width, height=height,
                                      supersample=1, path="s-curve", step_m=0.05, frame_rate_hz=rate_hz,
                                      progress=False)
    return read_recording(dataset)


def raw_pairs(manifest):
    return ([cv2.imread(str(f.left), cv2.IMREAD_GRAYSCALE) for f in manifest.frames],
            [cv2.imread(str(f.right), cv2.IMREAD_GRAYSCALE) for f in manifest.frames])


def measure(make_source, out: Path, repeats: int, **kw) -> dict:
    """Medians over ``repeats`` runs of a fresh source each."""
    runs = []
    for k in range(repeats):
        with make_source() as source:
            runs.append(run_live(source, out / f"run{k}", **kw).metrics())
    med = lambda f: float(np.median([f(m) for m in runs]))      # noqa: E731
    stages = sorted({s for m in runs for s in m["stage_ms_per_frame"]})
    threads = sorted({t for m in runs for t in m["cpu_s"]})
    return {"frames_in": med(lambda m: m["frames_in"]), "processed": med(lambda m: m["frames_processed"]),
            "dropped": med(lambda m: m["frames_dropped"]), "mapped": med(lambda m: m["frames_mapped"]),
            "lost": med(lambda m: m["frames_lost"]),
            "rate_hz": med(lambda m: m["rate_hz"]), "latency_median_ms": med(lambda m: m["latency_ms"]["median"]),
            "latency_p95_ms": med(lambda m: m["latency_ms"]["p95"]),
            "cores_used": med(lambda m: m.get("cores_used", 0.0)),
            "cpu_ms_per_frame": med(lambda m: 1000.0 * m["cpu_s"]["process"] / max(m["frames_processed"], 1)),
            "peak_memory_mb": med(lambda m: m["peak_memory_mb"]),
            "stage_ms": {s: med(lambda m: m["stage_ms_per_frame"].get(s, 0.0)) for s in stages},
            "thread_share": {t: med(lambda m: m["cpu_s"].get(t, 0.0) / m["duration_s"]) for t in threads}}


def report(title: str, r: dict) -> None:
    print(f"\n{title}")
    print(f"  {r['frames_in']:.0f} frames in, {r['processed']:.0f} processed, {r['dropped']:.0f} dropped, "
          f"{r['mapped']:.0f} mapped, {r['lost']:.0f} lost")
    print(f"  rate {r['rate_hz']:.1f} Hz; latency median {r['latency_median_ms']:.0f} ms, "
          f"p95 {r['latency_p95_ms']:.0f} ms; cores used {r['cores_used']:.2f} of {os.cpu_count()}; "
          f"peak memory {r['peak_memory_mb']:.0f} MB")
    cpu = r["cpu_ms_per_frame"]
    print(f"  CPU time per processed frame {cpu:.0f} ms (all threads): on {os.cpu_count()} idle cores at most "
          f"{1000.0 * os.cpu_count() / cpu:.1f} Hz")
    print("  stage ms per frame: " + ", ".join(f"{s} {v:.1f}" for s, v in r["stage_ms"].items()))
    print("  CPU share per thread: " + ", ".join(f"{t} {v:.2f}" for t, v in r["thread_share"].items()))


class _Looped(FrameSource):
    """The pairs driven forth and back to ``n`` frames at ``rate_hz``, with increasing stamps."""

    def __init__(self, frames: list[StereoFrame], n: int, rate_hz: float, **attrs) -> None:
        self.frames, self.n, self.rate_hz, self.name = frames, n, rate_hz, "looped"
        self.__dict__.update(attrs)

    def __iter__(self):
        order = list(range(len(self.frames))) + list(range(len(self.frames) - 2, 0, -1))
        for k in range(self.n):
            f = self.frames[order[k % len(order)]]
            yield StereoFrame(index=k, stamp_s=k / self.rate_hz, left=f.left, right=f.right, rectified=f.rectified,
                              T_world_from_base=f.T_world_from_base)


def bench_corridor(tmp: Path, args) -> None:
    t0 = time.perf_counter()
    manifest = corridor(tmp, args.frames, 640, 480, args.rate)
    video = side_by_side_video(*raw_pairs(manifest), tmp / "corridor_640.mkv", args.rate)
    print(f"corridor 640x480: {args.frames} frames rendered and written in {time.perf_counter() - t0:.0f} s")
    kw = {"calibration": manifest.calibration, "mount": manifest.mount}
    source = lambda: VideoSource(video, side_by_side=True)      # noqa: E731
    report(f"640x480 at {args.rate:g} Hz in real time (--realtime), visual odometry and map",
           measure(source, tmp / "rt", args.repeats, live=LiveConfig(realtime=True, odometry="visual"), **kw))
    report("640x480 as fast as it goes (nothing dropped)",
           measure(source, tmp / "fast", args.repeats, live=LiveConfig(odometry="visual"), **kw))
    report("640x480 as fast as it goes, one matcher (--workers 1)",
           measure(source, tmp / "one", args.repeats, live=LiveConfig(odometry="visual", workers=1), **kw))


def bench_euroc(tmp: Path, args) -> None:
    root = data_root() / "euroc_asl_sample" / "mav0"
    names = sorted(p.name for p in (root / "cam0" / "data").glob("*.png"))
    if not names:
        print(f"\nEuRoC sample not found under {root} (set MRSTEREO_DATA)")
        return
    lefts = [cv2.imread(str(root / "cam0" / "data" / n), cv2.IMREAD_GRAYSCALE) for n in names]
    rights = [cv2.imread(str(root / "cam1" / "data" / n), cv2.IMREAD_GRAYSCALE) for n in names]
    order = list(range(len(names))) + list(range(len(names) - 2, 0, -1))
    order = [order[k % len(order)] for k in range(args.euroc_frames)]
    video = side_by_side_video([lefts[k] for k in order], [rights[k] for k in order], tmp / "euroc.mkv", 20.0)
    stereo = read_stereo(f"{root / 'cam0' / 'sensor.yaml'},{root / 'cam1' / 'sensor.yaml'}")
    report(f"EuRoC 752x480, {len(names)} real frames forth and back, {args.euroc_frames} frames at 20 Hz in "
           "real time, visual odometry and map",
           measure(lambda: VideoSource(video, side_by_side=True), tmp / "euroc", args.repeats, calibration=stereo,
                   live=LiveConfig(realtime=True, odometry="visual")))


def bench_long(tmp: Path, args) -> None:
    manifest = corridor(tmp, 10, 160, 120, 10.0)
    frames = list(RecordingSource(manifest))
    for title, n in (("a first run (cold: kernels compiled, allocator warming up)", args.long // 3),
                     ("the long run after it", args.long)):
        samples = []
        run = run_live(_Looped(frames, n, 10.0, calibration=manifest.calibration, mount=manifest.mount),
                       tmp / "long", config=PipelineConfig(), live=LiveConfig(save_every_s=1.0, odometry="visual"),
                       on_save=lambda r: samples.append((r.frames_processed, r.memory_mb)))
        s = np.array(samples)
        print(f"\n{title}: {run.frames_processed} frames of 160x120 in {run.duration_s:.0f} s ({run.rate_hz:.0f} Hz), "
              f"peak memory {run.peak_memory_mb:.0f} MB; resident memory [MB] by frames processed:")
        for part in np.array_split(s, 6):
            print(f"  {part[0, 0]:6.0f}-{part[-1, 0]:6.0f}: median {np.median(part[:, 1]):.0f}, "
                  f"max {part[:, 1].max():.0f}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--frames", type=int, default=150, help="Corridor frames at 640x480.")
    parser.add_argument("--rate", type=float, default=15.0, help="The corridor video's frame rate [Hz].")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--euroc", action="store_true", help="Also the EuRoC frames at 752x480.")
    parser.add_argument("--euroc-frames", type=int, default=200)
    parser.add_argument("--long", type=int, default=0, metavar="N", help="Also N frames at 160x120: memory.")
    parser.add_argument("--no-corridor", action="store_true")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="bench_live_") as tmp:
        if not args.no_corridor:
            bench_corridor(Path(tmp), args)
        if args.euroc:
            bench_euroc(Path(tmp), args)
        if args.long:
            bench_long(Path(tmp), args)


if __name__ == "__main__":
    main()
