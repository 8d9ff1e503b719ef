"""Speed-up of build_map (mrstereo map) with 1 vs 2 local Dask workers, and bit-identical maps.

Usage::

    python benchmarks/bench_parallel.py [--frames 100] [--repeat 2] [--data DIR] [--width 640 --height 480]

Renders (once, into DIR, default a temp dir) a synthetic corridor sequence
(``mrstereo synth --frames N``, 320x240 unless ``--width/--height``) and maps it:

- in this process (the default of ``mrstereo map``; numba may use both cores);
- ``workers=1`` and ``workers=2``: end to end, each call starting and stopping
  its LocalCluster of single-threaded worker processes (what ``mrstereo map
  --workers N`` costs);
- on a started, warmed-up cluster of 1 and 2 workers (the per-frame work alone).

Prints the median wall time of each, the 2-vs-1 worker ratios, and whether
every log-odds array equals the in-process one exactly. The machine is shared:
run it when quiet and more than once.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def main(argv=None) -> int:
    from mrstereo.parallel import dask_client, map_ordered
    from mrstereo.pipeline import build_map
    from mrstereo.world.dataset import read_manifest, write_synthetic_dataset

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--data", type=Path, default=None, help="dataset directory (rendered if absent)")
    ap.add_argument("--width", type=int, default=320, help="image width of the rendered sequence")
    ap.add_argument("--height", type=int, default=240, help="image height of the rendered sequence")
    args = ap.parse_args(argv)

    data = args.data or Path(tempfile.gettempdir()) / f"mrstereo-bench-parallel-{args.frames}"
    if not (data / "manifest.yaml").is_file():
        print(f"rendering {args.frames} frames into {data} ...", file=sys.stderr)
        write_synthetic_dataset(data, seed=0, n_frames=args.frames, width=args.width, height=args.height,
                                progress=True)
    manifest = read_manifest(data)
    n = len(manifest.frames)

    def timed(**kw):
        t = time.perf_counter()
        run = build_map(manifest, progress=False, **kw)
        return time.perf_counter() - t, run.grid.log_odds

    print(f"{n} frames of {manifest.calibration.size[0]}x{manifest.calibration.size[1]}; load average "
          f"{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores", flush=True)
    _, reference = timed()                          # warm-up: numba kernels loaded / compiled
    with dask_client(workers=1) as c1, dask_client(workers=2) as c2:
        for client in (c1, c2):                     # load the kernels in every worker
            map_ordered(abs, range(-4, 0), scheduler=client, progress=False)
            build_map(manifest, progress=False, scheduler=client)
        configs = {"in-process (default)": {}, "workers=1 (end to end)": {"workers": 1},
                   "workers=2 (end to end)": {"workers": 2}, "1 started worker (frames only)": {"scheduler": c1},
                   "2 started workers (frames only)": {"scheduler": c2}}
        times = {name: [] for name in configs}
        identical = True
        for _ in range(args.repeat):                # interleaved rounds: load drift hits every config alike
            for name, kw in configs.items():
                dt, lo = timed(**kw)
                times[name].append(dt)
                identical &= bool(np.array_equal(lo, reference, equal_nan=True))
    rows = {name: statistics.median(t) for name, t in times.items()}
    for name, t in times.items():
        print(f"{name:34s} median {rows[name]:7.2f} s  ({n / rows[name]:5.2f} frames/s)  runs: "
              + ", ".join(f"{v:.2f}" for v in t), flush=True)
    e2e = rows["workers=1 (end to end)"] / rows["workers=2 (end to end)"]
    print(f"speed-up 2 vs 1 workers, end to end : {e2e:.2f}x")
    print(f"speed-up 2 vs 1 workers, frames only: "
          f"{rows['1 started worker (frames only)'] / rows['2 started workers (frames only)']:.2f}x")
    print(f"workers=2 vs in-process             : {rows['in-process (default)'] / rows['workers=2 (end to end)']:.2f}x")
    print(f"log-odds identical in every run     : {identical}")
    print(f"load average at the end: {os.getloadavg()[0]:.2f}")
    return 0 if identical else 1


if __name__ == "__main__":
    sys.exit(main())
