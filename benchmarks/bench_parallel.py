"""Speed-up of mapping (`mrstereo map`) with 1 vs 2 local Dask workers, and bit-identical maps.

Usage::

    python benchmarks/bench_parallel.py [--frames 100] [--repeat 3] [--data DIR] [--width 640 --height 480]
                                        [--no-cli] [--no-processes]

Renders (once, into DIR, default a temp dir) a synthetic corridor sequence
(``mrstereo synth --frames N``; 640x480 unless ``--width/--height``) and maps it,
each configuration end to end (worker threads, or a local Dask cluster of
processes, started and stopped inside every run as ``mrstereo map --workers N
[--processes]`` does):

- ``build_map`` in this process (the default of ``mrstereo map``; numba may use
  both cores);
- ``build_map(workers=N)``, N = 1, 2: single-threaded worker threads (the
  default of ``--workers``);
- ``build_map(workers=N, processes=True)``: single-threaded worker processes;
- the command ``mrstereo map DIR -o OUT --quiet --workers N`` as a subprocess
  (Python start-up, imports and the map files included), and the same on the
  sequence's first frame alone: the command's serial part is its time on one
  frame less one frame's work (the in-process 1-worker time per frame);
- the machine's ceiling: the per-frame work (``StereoMapper.observe``) of all frames in
  one plain Python process vs half of them in each of two independent processes
  started together (no Dask, no communication; loop times without start-up; each
  single-threaded as a worker is: numba, OpenCV and BLAS).

Configurations run in interleaved rounds (load drift hits them alike). Prints
the median wall time of each, the 2-vs-1 worker ratios, and whether every
log-odds array equals the in-process one exactly. The machine may be shared:
run it when quiet.
"""
from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def _observe_range(data: Path, start: int, stop: int) -> None:
    """Child of the ceiling measurement: observe frames start..stop-1, print the loop time."""
    import cv2
    import numba
    from threadpoolctl import threadpool_limits

    from mrstereo._executor import keep_freed_memory
    from mrstereo.geometry.pair import observe_pair as observe
    from mrstereo.pipeline.mapper import PipelineConfig
    from mrstereo.recordings.manifest import read_manifest
    from mrstereo.recordings.sources import RecordingSource

    keep_freed_memory()
    numba.set_num_threads(1)
    cv2.setNumThreads(1)
    threadpool_limits(limits=1, user_api="blas")      # as the workers: OpenBLAS's idle threads spin
    m = read_manifest(data)
    config = PipelineConfig().for_rig(m.calibration)
    frames = [f for f in RecordingSource(m) if start <= f.index < stop]
    observe(frames[0], m.calibration, m.mount, config)                  # kernels loaded
    t = time.perf_counter()
    for frame in frames:
        observe(frame, m.calibration, m.mount, config)
    print(time.perf_counter() - t)


def _ceiling(data: Path, n: int) -> tuple[float, float]:
    """Wall time of the frames' work in one process, and in two independent processes."""
    def start(a, b):
        return subprocess.Popen([sys.executable, __file__, "--observe-range", str(data), str(a), str(b)],
                                stdout=subprocess.PIPE, text=True)
    one = float(start(0, n).communicate()[0])
    pair = [start(0, n // 2), start(n // 2, n)]
    return one, max(float(p.communicate()[0]) for p in pair)


def main(argv=None) -> int:
    if argv is None and len(sys.argv) == 5 and sys.argv[1] == "--observe-range":
        _observe_range(Path(sys.argv[2]), int(sys.argv[3]), int(sys.argv[4]))
        return 0
    from mrstereo._executor import keep_freed_memory
    from mrstereo.pipeline.run import build_map
    from mrstereo.recordings.manifest import read_manifest
    from mrstereo.world.dataset import write_synthetic_dataset

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--data", type=Path, default=None, help="dataset directory (rendered if absent)")
    ap.add_argument("--width", type=int, default=640, help="image width of the rendered sequence")
    ap.add_argument("--height", type=int, default=480, help="image height of the rendered sequence")
    ap.add_argument("--no-cli", action="store_true", help="skip the `mrstereo map` subprocess runs")
    ap.add_argument("--no-processes", action="store_true", help="skip the worker-process runs")
    ap.add_argument("--no-ceiling", action="store_true", help="skip the two-independent-processes runs")
    args = ap.parse_args(argv)
    keep_freed_memory()            # as the `mrstereo` command does

    data = args.data or Path(tempfile.gettempdir()) / f"mrstereo-bench-parallel-{args.frames}-{args.width}"
    if not (data / "manifest.yaml").is_file():
        print(f"rendering {args.frames} frames of {args.width}x{args.height} into {data} ...", file=sys.stderr)
        write_synthetic_dataset(data, seed=0, n_frames=args.frames, width=args.width, height=args.height,
                                progress=True)
    manifest = read_manifest(data)
    n = len(manifest.frames)
    out_root = Path(tempfile.mkdtemp(prefix="mrstereo-bench-parallel-out-"))
    cli = shutil.which("mrstereo")

    def in_python(**kw):
        def run():
            return build_map(manifest, progress=False, **kw).grid.log_odds
        return run

    def command(workers, folder=data):
        def run():
            out = Path(tempfile.mkdtemp(dir=out_root))
            subprocess.run([cli, "map", str(folder), "-o", str(out), "--quiet", "--workers", str(workers)],
                           check=True, stdout=subprocess.DEVNULL)
            return np.load(out / "log_odds.npy")
        return run

    one_frame = data.parent / f"{data.name}-first-frame"
    if not args.no_cli and cli is not None and not (one_frame / "manifest.yaml").is_file():
        write_synthetic_dataset(one_frame, seed=0, n_frames=1, width=args.width, height=args.height, progress=False)

    configs = {"in-process (default)": in_python(),
               "1 worker thread": in_python(workers=1), "2 worker threads": in_python(workers=2)}
    if not args.no_processes:
        configs.update({"1 worker process": in_python(workers=1, processes=True),
                        "2 worker processes": in_python(workers=2, processes=True)})
    if not args.no_cli and cli is not None:
        configs.update({"`mrstereo map --workers 1`": command(1), "`mrstereo map --workers 2`": command(2)})

    print(f"{n} frames of {manifest.calibration.size[0]}x{manifest.calibration.size[1]}; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    reference = configs["in-process (default)"]()     # warm-up: numba kernels loaded / compiled
    timed_alone = {}
    if not args.no_cli and cli is not None:
        timed_alone["`mrstereo map --workers 1`, first frame only"] = command(1, one_frame)
    times = {name: [] for name in [*configs, *timed_alone]}
    ceiling = []
    identical = True
    for _ in range(args.repeat):
        for name, run in configs.items():
            t = time.perf_counter()
            log_odds = run()
            times[name].append(time.perf_counter() - t)
            identical &= bool(np.array_equal(log_odds, reference, equal_nan=True))
        for name, run in timed_alone.items():
            t = time.perf_counter()
            run()
            times[name].append(time.perf_counter() - t)
        if not args.no_ceiling:
            ceiling.append(_ceiling(data, n))
    shutil.rmtree(out_root, ignore_errors=True)
    med = {name: statistics.median(t) for name, t in times.items()}
    for name, t in times.items():
        frames = 1 if name in timed_alone else n
        print(f"{name:30s} median {med[name]:7.2f} s  ({frames / med[name]:5.1f} frames/s)  runs: "
              + ", ".join(f"{v:.2f}" for v in t), flush=True)
    for one, two in (("1 worker thread", "2 worker threads"), ("1 worker process", "2 worker processes"),
                     ("`mrstereo map --workers 1`", "`mrstereo map --workers 2`")):
        if one in med:
            rounds = [a / b for a, b in zip(times[one], times[two])]
            print(f"speed-up 2 vs 1: {two:28s} {med[one] / med[two]:.2f}x (ratio of medians); per round: median "
                  f"{statistics.median(rounds):.2f}x, " + ", ".join(f"{r:.2f}x" for r in rounds))
    print(f"2 worker threads vs in-process: {med['in-process (default)'] / med['2 worker threads']:.2f}x")
    cli_one = "`mrstereo map --workers 1`"
    alone = "`mrstereo map --workers 1`, first frame only"
    if alone in med:
        frame = med["1 worker thread"] / n
        print(f"serial part of the command: {med[alone]:.2f} s on one frame less one frame's work ({frame:.3f} s) = "
              f"{med[alone] - frame:.2f} s")
    if cli_one in med:
        # What the command does besides build_map (Python start-up, imports, reading the manifest,
        # map files and figure) is serial: it bounds the command's speed-up (Amdahl).
        fixed = med[cli_one] - med["1 worker thread"]
        work = med["1 worker thread"]
        print(f"command's own serial cost (start-up, imports, outputs): {fixed:.2f} s of {med[cli_one]:.2f} s; "
              f"even with 2.00x on build_map the command could reach {(fixed + work) / (fixed + work / 2):.2f}x")
    if ceiling:
        one, two = (statistics.median(c[k] for c in ceiling) for k in (0, 1))
        print(f"ceiling, per-frame work alone: 1 process {one:.2f} s, 2 independent processes {two:.2f} s: "
              f"{one / two:.2f}x (runs: " + ", ".join(f"{a / b:.2f}x" for a, b in ceiling) + ")")
    print(f"log-odds identical in every run: {identical}")
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return 0 if identical else 1


if __name__ == "__main__":
    sys.exit(main())
