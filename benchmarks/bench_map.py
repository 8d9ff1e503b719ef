"""The paper's corridor-mapping experiment (section 5.2, Figs 11-14) on synthetic worlds.

For several world seeds: render a run along the corridor (front, +45 and -45 degree views at
each stop), map it with the default pipeline and compare with the ground-truth map within 4 m
of the path: occupied precision / recall (1-cell tolerance, recall over the wall faces and
obstacle outlines; "recall in view" over those some frame had in view), the corridor-profile
error (mean distance of occupied cells to the true walls), the share of cells mapped free that are truly free ("free correct"), the share of the
true free cells in view of some frame that are mapped free ("free coverage"), the share of all
true free cells within 4 m mapped free ("free recall"), recall within 1 m of the path ("near": where the
multi-range approach matters) and the share of the obstacles some frame shows within 4 m (50
pixels clear of the image border) that the map found (an occupied cell on or next to the
obstacle's footprint).

Two worlds:

* the fixed corridor (``default_scene``), 30 frames per seed; rows: multi-range + log-odds (the
  default), the paper's union fusion, a single full-resolution range of equal work;
* ``--randomized``: a different corridor per seed (``mrstereo.world.random_world``: widths,
  textures, lights, rig, sensors, obstacles). mrstereo's defaults are chosen on seeds 0-9 only;
  the report seeds are 100-119. Prints one row per seed, the mean and the worst seed.

``--variants`` also maps every seed with the mapping variants of ``VARIANTS`` (the steps from
the paper's plain ray casting to the default sensor model) on the same observations.

Usage::

    python benchmarks/bench_map.py [--seeds 0 1 2] [--frames 30]
    python benchmarks/bench_map.py --randomized --seeds 100-119 [--frames 24] [--workers 2]
    python benchmarks/bench_map.py --randomized --seeds 0-9 --variants
    python benchmarks/bench_map.py --randomized --seeds 0-9 --wall-texture stripes   # striped walls
"""
from __future__ import annotations

import argparse
import os
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

COLUMNS = ("occupied precision", "occupied recall", "recall in view", "wall profile error [cm]", "free correct",
           "free coverage", "free recall", "recall within 1 m", "obstacles found")
PROFILE = COLUMNS.index("wall profile error [cm]")      # the one column where less is better


def _parse_seeds(values: list[str]) -> list[int]:
    seeds: list[int] = []
    for v in values:
        for part in v.split(","):
            if "-" in part:
                a, b = part.split("-")
                seeds += list(range(int(a), int(b) + 1))
            elif part:
                seeds.append(int(part))
    return seeds


def variants() -> dict:
    """Named pipeline configurations: how each step of the mapping sensor model changes the map.

    The mapping steps are re-fused from the default's observations (with the free-space boundary's
    points); the last but one row maps without the boundary.
    """
    from mrstereo.pipeline.run import PipelineConfig

    base = PipelineConfig()
    m = base.mapping
    plain = replace(m, disparity_sigma_px=None, occlusion_gap_m=None, see_through_ratio=None, overhang_shadow=False,
                    map_occlusion_p=None, clear_below_m=None)
    view_tests = replace(plain, disparity_sigma_px=m.disparity_sigma_px, occlusion_gap_m=m.occlusion_gap_m,
                         see_through_ratio=m.see_through_ratio)
    shadow = replace(view_tests, overhang_shadow=m.overhang_shadow)
    return {
        "plain rays": replace(base, mapping=plain),
        "+ range uncertainty (0.25 px, 2 sigma)": replace(base, mapping=replace(
            plain, disparity_sigma_px=m.disparity_sigma_px)),
        "+ occlusion in the view, 2-D (no heights)": replace(base, mapping=replace(
            plain, disparity_sigma_px=m.disparity_sigma_px, occlusion_gap_m=m.occlusion_gap_m,
            height_tolerance_m=100.0)),
        "+ occlusion at the sight line's height": replace(base, mapping=replace(
            plain, disparity_sigma_px=m.disparity_sigma_px, occlusion_gap_m=m.occlusion_gap_m)),
        "+ floor seen through a cell clears it": replace(base, mapping=view_tests),
        "+ no clearing beyond an overhang": replace(base, mapping=shadow),
        "+ occlusion by the map (P >= 0.8)": replace(base, mapping=replace(shadow, map_occlusion_p=m.map_occlusion_p)),
        "+ clearing only below 0.8 m": replace(base, free_space=None),
        "+ free-space boundary (the default)": base,
    }


def _metrics(grid, gt, path, views, obstacles) -> tuple:
    from mrstereo.mapping.grid import dilate_cells
    from mrstereo.mapping.metrics import map_metrics

    far = map_metrics(grid, gt, path_xy=path, within_m=4.0, views=views)
    near = map_metrics(grid, gt, path_xy=path, within_m=1.0)
    # an obstacle is found when an occupied cell lies on its footprint or within one cell of it
    occupied = dilate_cells(grid.to_ros_map().occupied, 1)
    found = np.mean([(occupied & cells).any() for cells in obstacles]) if obstacles else np.nan
    return (far.precision, far.recall, far.recall_in_view, far.mean_distance_m * 100, far.free_precision,
            far.free_coverage, far.free_recall, near.recall, found)


def seen_obstacles(manifest, footprints: dict, *, range_m: float, min_pixels: int = 50, border_px: int = 10) -> list:
    """The footprints of the obstacles some frame shows: at least ``min_pixels`` pixels of the
    obstacle's label within ``range_m`` and ``border_px`` or more from the image border (where a
    matching window fits) in one frame's true label and disparity images. A low box beside the
    first stop may show only a few rows at the bottom of one frame, or nothing."""
    from mrstereo.io import read_image, read_pfm

    bf = manifest.calibration.baseline_m * manifest.calibration.focal_px
    seen: set[int] = set()
    for frame in manifest.frames:
        labels = read_image(frame.gt_labels)
        with np.errstate(divide="ignore", invalid="ignore"):
            near = bf / read_pfm(frame.gt_disparity) <= range_m
        near[:border_px] = near[-border_px:] = False
        near[:, :border_px] = near[:, -border_px:] = False
        counts = np.bincount(labels[near].ravel(), minlength=max(footprints, default=0) + 1)
        seen |= {label for label in footprints if counts[label] >= min_pixels}
    return [cells for label, cells in footprints.items() if label in seen]


def evaluate_seed(seed: int, *, randomized: bool, frames: int, data_dir: str | None, with_variants: bool,
                  fixed_rows: bool, wall_texture: str | None = None) -> tuple[int, dict, float]:
    """Render (or reuse) one world, map it, return {row name: metrics tuple}, the time taken and how
    many obstacles the frames show."""
    from mrstereo.mapping import read_ros_map
    from mrstereo.mapping.fusion import fuse
    from mrstereo.mapping.metrics import views_of_poses
    from mrstereo.pipeline.run import PipelineConfig, build_map
    from mrstereo.world import default_scene, obstacle_footprints, random_world, read_manifest, write_synthetic_dataset

    t0 = time.perf_counter()
    root = Path(data_dir) if data_dir else Path(tempfile.mkdtemp(prefix="bench_map_"))
    ds = root / f"{'random' if randomized else 'corridor'}_seed{seed}_{frames}f{'_' + wall_texture if wall_texture else ''}"
    if not (ds / "manifest.yaml").is_file():
        write_synthetic_dataset(ds, seed=seed, n_frames=frames, progress=False, randomize=randomized,
                                wall_texture=wall_texture)
    manifest = read_manifest(ds)
    gt = read_ros_map(manifest.ground_truth_map)
    path = np.array([f.pose for f in manifest.frames])
    config = PipelineConfig()
    views = views_of_poses(path, [f.pan_rad for f in manifest.frames], manifest.calibration,
                           range_m=config.for_rig(manifest.calibration).obstacles.max_range_m)
    scene = random_world(seed).scene if randomized else default_scene(seed)
    footprints = obstacle_footprints(scene, gt.grid)
    obstacles = seen_obstacles(manifest, footprints, range_m=config.obstacles.max_range_m)
    rows: dict[str, tuple] = {}
    run = build_map(manifest, config=config, progress=False)
    rows["multi-range, log-odds (default)"] = _metrics(run.grid, gt, path, views, obstacles)
    if fixed_rows:
        union = fuse(run.observations, grid=config.grid, config=config.with_fusion("union").mapping)
        rows["multi-range, union (the paper's fusion)"] = _metrics(union, gt, path, views, obstacles)
        single = config.single_range_equal_work(manifest.calibration)
        grid = build_map(manifest, config=single, progress=False).grid
        rows[f"single range 0-{single.max_disparity_px:.0f} px, equal work"] = _metrics(grid, gt, path, views, obstacles)
    if with_variants:
        for name, variant in variants().items():
            if replace(variant, mapping=config.mapping) == config:     # only the mapping differs: re-fuse
                grid = fuse(run.observations, grid=config.grid, config=variant.mapping)
            else:
                grid = build_map(manifest, config=variant, progress=False).grid
            rows[f"variant: {name}"] = _metrics(grid, gt, path, views, obstacles)
    return seed, rows, time.perf_counter() - t0, f"{len(obstacles)} of {len(footprints)} obstacles shown"


def _fmt(k: int, v: float) -> str:
    return f"{v:.1f}" if k == PROFILE else f"{v:.3f}"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", nargs="+", default=None, help="seeds, e.g. 0 1 2 or 100-119")
    parser.add_argument("--frames", type=int, default=None, help="frames per seed (30 fixed, 24 randomized)")
    parser.add_argument("--randomized", action="store_true", help="randomized worlds instead of the fixed corridor")
    parser.add_argument("--variants", action="store_true", help="also map with the mapping variants")
    parser.add_argument("--workers", type=int, default=1, help="seeds mapped in parallel processes")
    parser.add_argument("--data", default=None, help="keep rendered datasets here (reused when present)")
    parser.add_argument("--wall-texture", default=None,
                        help="randomized worlds with this wall material instead of the drawn one "
                             "(paint, tiles, stripes, blotch, wood): a development variant of the same seeds")
    args = parser.parse_args()
    if args.wall_texture and not args.randomized:
        parser.error("--wall-texture needs --randomized")
    seeds = _parse_seeds(args.seeds) if args.seeds else ([100 + k for k in range(20)] if args.randomized
                                                          else [0, 1, 2])
    frames = args.frames or (24 if args.randomized else 30)
    kwargs = dict(randomized=args.randomized, frames=frames, data_dir=args.data, with_variants=args.variants,
                  fixed_rows=not args.randomized, wall_texture=args.wall_texture)
    per_seed: dict[int, dict] = {}
    t0 = time.perf_counter()
    if args.workers > 1:
        os.environ.setdefault("NUMBA_NUM_THREADS", "1")
        with ProcessPoolExecutor(args.workers) as pool:
            futures = [pool.submit(evaluate_seed, s, **kwargs) for s in seeds]
            for f in futures:
                seed, rows, dt, shown = f.result()
                per_seed[seed] = rows
                print(f"seed {seed}: {dt:.1f} s, {shown}", flush=True)
    else:
        for s in seeds:
            seed, rows, dt, shown = evaluate_seed(s, **kwargs)
            per_seed[seed] = rows
            print(f"seed {seed}: {dt:.1f} s, {shown}", flush=True)
    wall = time.perf_counter() - t0
    world = "randomized worlds" if args.randomized else "the fixed corridor"
    if args.wall_texture:
        world += f" with {args.wall_texture} walls"
    print(f"\n{world}, seeds {seeds[0]}..{seeds[-1]} ({len(seeds)}), {frames} frames each, 320x240, "
          f"{wall:.0f} s wall with {args.workers} worker(s)\n")
    names = list(per_seed[seeds[0]])
    if args.randomized:
        print("| seed | " + " | ".join(COLUMNS) + " |")
        print("|---" * (len(COLUMNS) + 1) + "|")
        default = names[0]
        for s in seeds:
            print(f"| {s} | " + " | ".join(_fmt(k, v) for k, v in enumerate(per_seed[s][default])) + " |")
        print()
    print("| run | " + " | ".join(COLUMNS) + " |")
    print("|---" * (len(COLUMNS) + 1) + "|")
    for name in names:
        v = np.array([per_seed[s][name] for s in seeds], dtype=float)
        mean = np.nanmean(v, 0)
        worst = np.nanmin(v, 0)
        worst[PROFILE] = np.nanmax(v[:, PROFILE])
        cells = [f"{_fmt(k, m)} (worst {_fmt(k, w)})" for k, (m, w) in enumerate(zip(mean, worst))]
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
