"""Speed of the mapping stage next to the matching it follows.

Prints medians (ms) of:
- OccupancyGrid.update with N points of a corridor view (walls + floor), log-odds and union;
- the same rays traced naively, one cv2.line per point (what a simple implementation does);
- OpenCV StereoBM on a 640x480 pair, 96 disparities (the cost of one frame's matching);
- A* (plan_path) corner to corner on the default 240x120 grid, empty and with walls.

``--euroc``: the real frames of the EuRoC sample (``$MRSTEREO_DATA/euroc_asl_sample``, 752x480, about
100 000 obstacle points a frame) through the chain of ``mrstereo map`` and ``mrstereo scan``, one thread:
per frame the CPU time (``time.process_time``) of the stages ``match``, ``grid`` (the points into the world
frame and the update of the growing map; ``grid.layers``: its height and drop layers, part of ``grid``) and
``scan`` (the virtual laser scan), medians over the frames and repeats, and grid + scan as a share of
matching (issue 33's budget: at most 15 %).

Run: python benchmarks/bench_mapping.py [--points 100000] [--repeat 15]
     python benchmarks/bench_mapping.py --euroc [--repeat 3]
"""
from __future__ import annotations

import argparse
import time

import cv2
import numpy as np

from mrstereo.mapping import GridSpec, MappingConfig, OccupancyGrid, RosMap, plan_path


def median_ms(fn, repeat: int) -> float:
    fn()                                       # warm-up (numba compile / caches)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return 1e3 * float(np.median(times))


def corridor_view(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Half the points on walls at y = +-1.5 m (1-6 m ahead), half on the floor."""
    k = n // 2
    wall = np.c_[rng.uniform(1.0, 6.0, k), np.where(rng.random(k) < 0.5, 1.5, -1.5)
                 + rng.normal(0.0, 0.03, k), rng.uniform(0.0, 2.0, k)]
    floor = np.c_[rng.uniform(0.5, 6.0, k), rng.uniform(-1.4, 1.4, k), np.zeros(k)]
    return wall, floor


def naive_cv2_lines(wall: np.ndarray, floor: np.ndarray, grid: GridSpec, sensor_xy) -> np.ndarray:
    """One cv2.line per point into a free mask, then hits: no deduplication."""
    rows, cols = grid.shape
    free = np.zeros((rows, cols), np.uint8)
    s = (int((sensor_xy[0] - grid.origin_x_m) / grid.resolution_m),
         int((sensor_xy[1] - grid.origin_y_m) / grid.resolution_m))
    r, c = grid.cells_from_xy(np.vstack([wall, floor])[:, :2])
    for ri, ci in zip(r.tolist(), c.tolist()):
        cv2.line(free, s, (ci, ri), 1, 1, lineType=cv2.LINE_4)
    return free


def euroc_stages(repeat: int) -> None:
    """Per-frame CPU time of match, grid and scan on the EuRoC sample's frames (one thread)."""
    import math
    import os
    from pathlib import Path

    import numba

    from mrstereo.pipeline.mapper import StereoMapper
    from mrstereo.pipeline.run import PipelineConfig, build_map
    from mrstereo.profiling import Profile, profiling
    from mrstereo.recordings.layouts import read_recording
    from mrstereo.recordings.sources import RecordingSource

    cv2.setNumThreads(1)
    numba.set_num_threads(1)
    root = Path(os.environ.get("MRSTEREO_DATA", "data")) / "euroc_asl_sample"
    manifest = read_recording(root)
    stereo = manifest.calibration
    config = PipelineConfig()
    mount = build_map(manifest, progress=False).mount          # the floor found once: every round maps with it
    with RecordingSource(manifest) as source:
        frames = list(source)
    samples: dict[str, list[float]] = {"match": [], "grid": [], "grid.layers": [], "scan": []}
    points = []
    for k in range(repeat + 1):                     # the first round compiles and warms up
        mapper = StereoMapper(stereo, mount, config, check_mount=False)
        for frame in frames:
            profile = Profile(clock=time.process_time)
            with profiling(profile):
                mapped = mapper.step_frame(frame)
            if k and mapped:
                for name in samples:
                    samples[name].append(1e3 * profile.seconds.get(name, math.nan))
                points.append(len(mapped[-1].obstacle_points_robot))
    med = {name: float(np.median(v)) for name, v in samples.items()}
    print(f"EuRoC sample, {len(frames)} frames {stereo.size[0]}x{stereo.size[1]} x {repeat} repeats, one thread, "
          f"CPU time (process_time); median {int(np.median(points))} obstacle points a frame")
    for name, ms in med.items():
        print(f"{name:<11} {ms:8.2f} ms/frame")
    share = (med["grid"] + med["scan"]) / med["match"]
    print(f"grid + scan {med['grid'] + med['scan']:.2f} ms = {100 * share:.1f} % of matching")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--repeat", type=int, default=15)
    parser.add_argument("--euroc", action="store_true", help="the stages of real EuRoC frames (see above)")
    args = parser.parse_args()
    if args.euroc:
        euroc_stages(min(args.repeat, 3) if args.repeat == 15 else args.repeat)
        return
    rng = np.random.default_rng(0)
    wall, floor = corridor_view(args.points, rng)
    sensor = (0.2, 0.0)
    grid_lo = OccupancyGrid()
    grid_un = OccupancyGrid(config=MappingConfig(fusion="union"))
    t_lo = median_ms(lambda: grid_lo.update(wall, floor, sensor), args.repeat)
    t_un = median_ms(lambda: grid_un.update(wall, floor, sensor), args.repeat)
    small = max(1, args.points // 10)
    t_naive = median_ms(lambda: naive_cv2_lines(wall[:small], floor[:small], GridSpec(), sensor), 3)
    t_naive *= args.points / small           # extrapolated linearly

    cv2.setNumThreads(2)
    left = rng.integers(0, 255, (480, 640), dtype=np.uint8)
    right = np.roll(left, -20, axis=1)
    bm = cv2.StereoBM.create(numDisparities=96, blockSize=15)
    t_bm = median_ms(lambda: bm.compute(left, right), args.repeat)

    spec = GridSpec()
    empty = RosMap(occupancy=np.zeros(spec.shape), grid=spec)
    occ = np.zeros(spec.shape)
    for col in (60, 120, 180):                 # three walls with alternating openings
        occ[:, col] = 1.0
        occ[(10, 100)[col // 60 % 2]:(20, 110)[col // 60 % 2], col] = 0.0
    walls = RosMap(occupancy=occ, grid=spec)
    start, goal = (0.3, -2.7), (11.7, 2.7)
    t_astar = median_ms(lambda: plan_path(empty, start, goal, robot_radius_m=0.0), args.repeat)
    t_astar_w = median_ms(lambda: plan_path(walls, start, goal, robot_radius_m=0.1), args.repeat)
    res_w = plan_path(walls, start, goal, robot_radius_m=0.1)

    print(f"grid {spec.shape[1]}x{spec.shape[0]} cells, {args.points} points per update")
    print(f"update log-odds                 {t_lo:8.2f} ms")
    print(f"update union                    {t_un:8.2f} ms")
    print(f"naive cv2.line per point        {t_naive:8.2f} ms (extrapolated from {2 * small})"
          f"   ratio {t_naive / t_lo:6.1f}x slower")
    print(f"StereoBM 640x480, 96 disp       {t_bm:8.2f} ms   update/matching = {t_lo / t_bm:5.2f}")
    print(f"A* empty map, corner to corner  {t_astar:8.2f} ms")
    print(f"A* three walls (+inflation)     {t_astar_w:8.2f} ms   "
          f"({res_w.expanded_cells} cells expanded, {res_w.length_m:.2f} m)")


if __name__ == "__main__":
    main()
