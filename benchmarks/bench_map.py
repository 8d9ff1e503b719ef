"""The paper's corridor-mapping experiment (section 5.2, Figs 11-14) on the synthetic world.

For several world seeds: render a 30-frame run along the 12 m corridor (front, +45 and -45
degree views), map it with the default pipeline and compare with the ground-truth map:
occupied precision / recall (1-cell tolerance, recall over the visible wall faces and obstacle
outlines), the corridor-profile error (mean distance of occupied cells to the true walls) and
the share of free cells mapped free, within 4 m of the path; and the same within 1 m of the
path ("near": where the multi-range approach matters). Rows:

* multi-range + log-odds (the default),
* multi-range + the paper's union fusion,
* a single full-resolution range of equal work + log-odds (the near blind zone).

Usage::

    python benchmarks/bench_map.py [--seeds 0 1 2] [--frames 30]
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from mrstereo.mapping import read_ros_map
from mrstereo.mapping.metrics import map_metrics
from mrstereo.pipeline import MapRun, PipelineConfig, build_map, fuse
from mrstereo.world import read_manifest, write_synthetic_dataset


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2])
    parser.add_argument("--frames", type=int, default=30)
    args = parser.parse_args()
    rows: dict[str, list] = {}
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            t0 = time.perf_counter()
            manifest = read_manifest(write_synthetic_dataset(Path(tmp) / f"seed{seed}", seed=seed,
                                                             n_frames=args.frames, progress=False))
            gt = read_ros_map(manifest.ground_truth_map)
            path = np.array([f.pose for f in manifest.frames])
            config = PipelineConfig()
            runs = {"multi-range, log-odds": build_map(manifest, config=config, progress=False)}
            runs["multi-range, union (paper)"] = fuse(runs["multi-range, log-odds"].observations, grid=config.grid,
                                                      config=config.with_fusion("union").mapping)
            single = config.single_range_equal_work(manifest.calibration)
            runs[f"single range 0-{single.max_disparity_px:.0f} px, equal work"] = build_map(
                manifest, config=single, progress=False)
            for name, run in runs.items():
                grid = run.grid if isinstance(run, MapRun) else run
                far = map_metrics(grid, gt, path_xy=path, within_m=4.0)
                near = map_metrics(grid, gt, path_xy=path, within_m=1.0)
                rows.setdefault(name, []).append((far.precision, far.recall, far.mean_distance_m * 100,
                                                  far.free_accuracy, near.recall))
            print(f"seed {seed}: {time.perf_counter() - t0:.1f} s", flush=True)
    print(f"\n{len(args.seeds)} seeds x {args.frames} frames, 320x240; mean (min..max) over seeds\n")
    print("| run | occupied precision | occupied recall | wall profile error [cm] | free correct | "
          "recall within 1 m |")
    print("|---|---|---|---|---|---|")
    for name, values in rows.items():
        v = np.array(values)
        cells = [f"{m:.3f} ({lo:.3f}..{hi:.3f})" if k != 2 else f"{m:.1f} ({lo:.1f}..{hi:.1f})"
                 for k, (m, lo, hi) in enumerate(zip(v.mean(0), v.min(0), v.max(0)))]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
