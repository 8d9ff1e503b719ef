"""Drop-offs: maps of randomized worlds with drops, and the same test on real recordings of flat floors.

Each frame is matched once and mapped twice, with and without the drop test (the same observation without
the drop test's points, :mod:`mrstereo.geometry.drops`), so the two maps differ by the drop test only.

Randomized worlds (``random_world(seed, drops=True)``: a ledge or a drivable ramp down, holes, stairwells,
a kerb, a sunken step; the map layer's rules chosen on seeds 0-4 and 100-109, the drop test's on 100-119; reported on 200-209 and 300-309), the frames of ``write_synthetic_dataset``'s
``stops`` path (front, +45 and -45 degrees at each stop; ``--path front``: a drive looking ahead, a frame every
0.1 m or less, as a robot's camera sees it), per seed:

* **edge recall**: the true drop-edge cells (``mrstereo.world.drop_edges``) whose floor some frame's true
  disparity shows within 2.5 m (``--view``; the robot must know an edge before it is near it) that are lethal in the map, a lethal
  cell next to it counting (1-cell tolerance); **recall 4 m**: the same within the mapping range (4 m), where
  a far edge seen at a grazing angle may hide a drivable slope and is not marked;
* **false drops**: the drivable cells (reachable from the start over steps within ``max_step_m``: flat floor,
  the ramp, the kerb, the sunken step) in some frame's field of view (4 m) and more than one cell from a true edge that the drop test
  made lethal (lethal with it, not without), over those cells (**false > 0.15 m**: more than 3 cells from a
  true edge); **on ramps/kerbs**: the same on the cells off
  the plain floor;
* **crossings**: paths planned (``mrstereo.mapping.plan_path``, unknown cells allowed as Nav2 does) from the
  start to a goal in each hole or beyond the ledge that enter an undrivable cell (0 is required); **of a seen
  edge**: those that enter it within two cells of an edge cell whose floor some frame's true disparity shows
  within the mapping range (an edge the cameras saw; the others cross where no frame looked);
* **undrivable free**: the undrivable cells in view (inside a hole or stairwell, past the ledge; more than one
  cell from a true edge) that the map calls free, with and without the drop test: where a planned path can
  cross without touching a lethal cell.

``--speed``: the CPU time of a frame (``obstacles_from_pair``: rectify, match, reject, 3-D, free space) with and
without the drop test (and with it but without its weak points, ``weak_n_sigma=None``: "ratio without weak
points"; "wall ratio": the same in wall-clock time), interleaved runs, on the default corridor (320x240) and a
EuRoC frame (752x480), and the drop test's own time within the frame (the image's row texture, its point image
-- written in the triangulation pass, whose extra time over the same pass without the test counts --, the column
pass, the merge, CPU time of the thread it runs on: "drop test share", which the two frames' noise does not blur); and of a whole mapper step (the grid and its height and drop layers too) on corridor frames,
with the layers' share. ``--live N``: the live loop's rate (frames per second) with and without the test on the
real EuRoC and OpenLORIS frames driven forth and back to N frames, as fast as they go (two matchers, visual odometry,
the growing map; :func:`measure_live`): the speed of a frame where the robot uses it.

The weak votes (``--weak-n-sigma``, ``'none'``: off; ``--drop-weak-views``) were chosen on seeds 100-119; the
noise margin (``--n-sigma`` times the disparity error measured on each frame's floor; ``--disparity-sigma``: a
fixed one instead, the former default 0.25 px with ``--n-sigma 3``) and the row-texture test
(``--min-row-texture``, ``'none'``: off) on seeds 100-119 and the drives 100-109.

``--why``: also the causes of each seed's missed edge cells, and their sums (:func:`missed_causes`): not measured
by any frame (and why), measured but no drop by the column rule (which of its margins), a candidate the map
never confirmed, a frame's drop lost in the map.

``--oracle``: the same chain and maps with each frame's true disparity in place of the matcher's
(:func:`oracle_disparity`; eq. (13) and all after it unchanged): what the drop test and the map reach with a
perfect matcher, so a miss is the rules' or the geometry's, not the sensor noise's (with ``--why``, ``--n-sigma``).

``--real``: the first frames of the EuRoC ASL sample, KITTI odometry 06 and 01 and OpenLORIS: the share of cells
free without the drop test that are not free with it (at most 0.5 % on these flat floors), the drop cells, and
the share of the floor's points (within 0.08 m of floor level) without texture along the rows (median and
largest over the frames).

The map with the drop test is the pipeline's: its drop layer (``OccupancyGrid.drop``, votes that rays do not
clear) lethal beside the log-odds.

Usage::

    python benchmarks/bench_drops.py --seeds 200-209 [--frames 24]
    python benchmarks/bench_drops.py --seeds 200-209 --path front --frames 100
    python benchmarks/bench_drops.py --seeds 0-4 100-109 --why
    python benchmarks/bench_drops.py --seeds 200-209 --oracle [--n-sigma 1] [--why]
    python benchmarks/bench_drops.py --seeds 100-119 --weak-n-sigma 1.0 --drop-weak-views 3
    python benchmarks/bench_drops.py --seeds 200-209 --disparity-sigma 0.25 --n-sigma 3
    python benchmarks/bench_drops.py --real [--frames 24]
    python benchmarks/bench_drops.py --speed [--repeats 15]
    python benchmarks/bench_drops.py --live 200 --repeats 7
    python benchmarks/bench_drops.py --corridor [--data DIR]
"""
from __future__ import annotations

import argparse
import math
import tempfile
import time
from contextlib import contextmanager, nullcontext
from dataclasses import replace
from pathlib import Path

import numpy as np


def _parse_seeds(values: list[str]) -> list[int]:
    seeds: list[int] = []
    for v in values:
        for part in v.split(","):
            a, _, b = part.partition("-")
            seeds += list(range(int(a), int(b or a) + 1)) if part else []
    return seeds


def paired_maps(manifest, *, frames: int | None = None, config=None, drops=None):
    """Map a recording's first ``frames`` frames with the drop test (``drops``, default ``DropConfig()``) and
    without it; returns the two :class:`mrstereo.evaluation.outputs.MapRun`."""
    from mrstereo.geometry.drops import DropConfig
    from mrstereo.pipeline.run import PipelineConfig, build_map

    config = PipelineConfig() if config is None else config
    if frames is not None:
        manifest = replace(manifest, frames=manifest.frames[:frames])
    obstacles = config.for_rig(manifest.calibration).obstacle_config
    drops = DropConfig() if drops is None else drops
    return tuple(build_map(manifest, config=replace(config, obstacles=replace(obstacles, drops=d)), progress=False)
                 for d in (drops, None))


@contextmanager
def oracle_disparity(manifest):
    """``--oracle``: while inside, the chain's matcher (:func:`mrstereo.matching.compute_disparity` as
    :mod:`mrstereo.geometry.pair` calls it) returns the frame's TRUE disparity (its ``gt_disparity``, of the
    rectified left image the chain receives, found by content among ``manifest``'s frames) where a perfect
    matcher has a match: NaN where the match falls outside the right image or is hidden from the right
    camera (a nearer pixel to its right lands on or left of it) or lies beyond the farthest searched
    disparity, too near beyond the nearest. Eq. (13) and all after it run as usual. Yields the indices of the
    frames substituted, one per call; an image of no frame raises. Maps built inside must run on one worker
    (``build_map``'s default)."""
    import hashlib

    from mrstereo.geometry import pair
    from mrstereo.io.images import read_pfm
    from mrstereo.matching import DisparityResult, make_plan
    from mrstereo.recordings.manifest import frame_pair

    key = lambda image: hashlib.sha1(np.ascontiguousarray(image).tobytes()).digest()        # noqa: E731
    truth = {key(frame_pair(r)[0]): (k, r.gt_disparity) for k, r in enumerate(manifest.frames)}
    used: list[int] = []
    matcher = pair.compute_disparity

    def oracle(left, right, **kwargs):
        index, path = truth[key(left)]
        used.append(index)
        d = read_pfm(path).astype(np.float32)
        plan = make_plan((d.shape[1], d.shape[0]), **kwargs)
        lo, hi = min(v.band_px[0] for v in plan.levels), max(v.band_px[1] for v in plan.levels)
        x_right = np.arange(d.shape[1], dtype=np.float32) - d
        ahead = np.minimum.accumulate(x_right[:, ::-1], axis=1)[:, ::-1]        # min over x' >= x
        hidden = np.concatenate([ahead[:, 1:], np.full((d.shape[0], 1), np.inf, np.float32)], axis=1) <= x_right
        too_near = d > hi
        d = np.where(hidden | (x_right < 0) | (d < lo) | too_near, np.nan, d).astype(np.float32)
        return DisparityResult(disparity_px=d, confidence=np.isfinite(d).astype(np.float32), plan=plan,
                               levels=(d,), too_near=too_near & ~hidden & (x_right >= 0))

    pair.compute_disparity = oracle
    try:
        yield used
    finally:
        pair.compute_disparity = matcher


def _drivable(height: np.ndarray, free: np.ndarray, start: tuple[int, int], max_step_m: float) -> np.ndarray:
    """Cells reachable from ``start`` over free cells whose floor heights differ by at most ``max_step_m``."""
    reach = np.zeros(height.shape, bool)
    stack = [start]
    reach[start] = True
    rows, cols = height.shape
    while stack:
        r, c = stack.pop()
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            rr, cc = r + dr, c + dc
            if (0 <= rr < rows and 0 <= cc < cols and not reach[rr, cc] and free[rr, cc]
                    and abs(height[rr, cc] - height[r, c]) <= max_step_m):
                reach[rr, cc] = True
                stack.append((rr, cc))
    return reach


def _in_view(grid, views) -> np.ndarray:
    """Cells inside some frame's field-of-view wedge ``(x, y, heading, half_fov, range)``."""
    centres = grid.cell_centres()
    seen = np.zeros(grid.shape, bool)
    for x, y, heading, half, reach in views:
        dx, dy = centres[..., 0] - x, centres[..., 1] - y
        bearing = np.angle(np.exp(1j * (np.arctan2(dy, dx) - heading)))
        seen |= (np.hypot(dx, dy) <= reach) & (np.abs(bearing) <= half)
    return seen


def _seen_floor(manifest, grid, height: np.ndarray, range_m: float) -> np.ndarray:
    """Cells whose floor some frame's true disparity shows within ``range_m`` of the camera (a true point at
    the cell's floor height): what the cameras could see, near blind zone and occlusions included."""
    from mrstereo.geometry import ground_from_mount, points_robot_from_disparity
    from mrstereo.geometry.ground import T_robot_from_cam_ground
    from mrstereo.io.images import read_pfm
    from mrstereo.transforms import T_from_planar

    stereo = manifest.calibration
    floor = ground_from_mount(manifest.mount, R_rect_from_cam=stereo.left.R)
    seen = np.zeros(grid.shape, bool)
    for record in manifest.frames:
        T_cam = T_robot_from_cam_ground(floor, pan_rad=record.pan_rad)
        p = points_robot_from_disparity(read_pfm(record.gt_disparity), stereo, T_cam).reshape(-1, 3)
        p = p[np.isfinite(p).all(axis=1) & (np.hypot(*(p[:, :2] - T_cam[:2, 3]).T) <= range_m)]
        T = T_from_planar(*record.pose)
        w = p @ T[:3, :3].T + T[:3, 3]
        r, c = grid.cells_from_xy(w[:, :2])
        inside = (r >= 0) & (r < grid.shape[0]) & (c >= 0) & (c < grid.shape[1])
        r, c, z = r[inside], c[inside], w[inside, 2]
        on_floor = np.abs(z - height[r, c]) < 0.02
        seen[r[on_floor], c[on_floor]] = True
    return seen


def evaluate_seed(seed: int, frames: int, data_dir: Path, view_m: float = 2.5, config=None, drops=None,
                  why: bool = False, oracle: bool = False, path: str = "stops", every: int = 1) -> dict:
    """Render world ``seed`` with drops, map it with and without the drop test, score both (see the module).
    ``why``: also the causes of the missed edge cells (:func:`missed_causes`) under ``"why"``. ``oracle``: the
    true disparity instead of the matcher's (:func:`oracle_disparity`; the frames substituted under
    ``"oracle frames"``). ``path``: ``"stops"`` (three views at each stop) or ``"front"`` (a drive looking ahead,
    a frame every 0.1 m or less: as far as the world's path holds ``frames`` frames). ``every``: only every
    so many of the rendered frames (the same drive at a lower frame rate)."""
    from scipy.ndimage import binary_dilation

    from mrstereo.geometry.drops import DropConfig
    from mrstereo.mapping import plan_path
    from mrstereo.mapping.metrics import views_of_poses
    from mrstereo.world import drop_edges, floor_heights, ground_truth_map, random_world, read_manifest
    from mrstereo.world import write_synthetic_dataset

    world = random_world(seed, drops=True)
    ds = data_dir / f"drops_seed{seed}_{frames}f{'' if path == 'stops' else '_' + path}"
    if not (ds / "manifest.yaml").is_file():
        chords = np.hypot(*np.diff(world.waypoints_xy, axis=0).T).sum()      # (the path's curve is longer)
        write_synthetic_dataset(ds, seed=seed, n_frames=frames, progress=False, randomize=True, drops=True,
                                path=path, step_m=min(0.1, math.floor(1000 * chords / max(frames - 1, 1)) / 1000))
    manifest = read_manifest(ds)
    manifest = replace(manifest, frames=manifest.frames[::every])
    t0 = time.process_time()
    with oracle_disparity(manifest) if oracle else nullcontext([]) as used:
        run, plain = paired_maps(manifest, config=config, drops=drops)
    cpu = time.process_time() - t0
    grid = run.grid.grid
    step = DropConfig().max_step_m
    edges = drop_edges(world.scene, grid, max_step_m=step)
    height = floor_heights(world.scene, grid)
    free = ground_truth_map(world.scene, grid).occupancy == 0.0
    start = tuple(int(v[0]) for v in grid.cells_from_xy(np.array([manifest.frames[0].pose[:2]])))
    drivable = _drivable(np.nan_to_num(height, nan=-9.0), free, start, step)
    views = views_of_poses([f.pose for f in manifest.frames], [f.pan_rad for f in manifest.frames],
                           manifest.calibration, range_m=run.range_m, mount=run.mount)
    seen = _seen_floor(manifest, grid, height, view_m)
    seen_far = _seen_floor(manifest, grid, height, run.range_m)
    lethal_plain = plain.grid.to_ros_map().occupied
    target, far = edges & seen, edges & seen_far
    ros_map = run.grid.to_ros_map()
    near_lethal = binary_dilation(ros_map.occupied, np.ones((3, 3), bool))
    in_view = _in_view(grid, views)
    away = drivable & in_view & ~binary_dilation(edges, np.ones((3, 3), bool))
    below = free & ~drivable & in_view & ~binary_dilation(edges, np.ones((3, 3), bool))   # inside holes, past ledges
    off_plain = away & (np.abs(np.nan_to_num(height)) > 1e-6)
    away_far = away & ~binary_dilation(edges, np.ones((7, 7), bool))
    added = ros_map.occupied & ~lethal_plain
    crossings, crossings_seen, goals = 0, 0, _goals(world)
    seen_edge = binary_dilation(far, np.ones((5, 5), bool))
    for goal in goals:
        plan = plan_path(ros_map, manifest.frames[0].pose[:2], goal, unknown_is_obstacle=False)
        if plan.success:
            r, c = grid.cells_from_xy(plan.path_xy)
            inside = grid.inside(r, c)
            r, c = r[inside], c[inside]
            entered = np.flatnonzero(free[r, c] & ~drivable[r, c])
            crossings += int(len(entered) > 0)
            crossings_seen += int(len(entered) > 0 and seen_edge[r[entered[0]], c[entered[0]]])
    with oracle_disparity(manifest) if oracle else nullcontext([]):
        causes = missed_causes(manifest, grid, target & ~near_lethal, run.range_m, config, drops) if why else None
    return {"seed": seed, "edge cells in view": int(target.sum()),
            "recall": float((near_lethal & target).sum() / max(target.sum(), 1)),
            "recall 4 m": float((near_lethal & far).sum() / max(far.sum(), 1)),
            "false drops": float((added & away).sum() / max(away.sum(), 1)),
            "false > 0.15 m": float((added & away_far).sum() / max(away_far.sum(), 1)),
            "on ramps/kerbs": float((added & off_plain).sum() / max(off_plain.sum(), 1)),
            "crossings": crossings, "of a seen edge": crossings_seen,
            "undrivable free": float((ros_map.free & below).sum() / max(below.sum(), 1)),
            "undrivable free without": float((plain.grid.to_ros_map().free & below).sum() / max(below.sum(), 1)),
            "drop cells": int(run.grid.drop.sum()),
            "ramp/kerb cells": int(off_plain.sum()), "goals": len(goals), "cpu s": cpu,
            "kinds": [world.summary["drops"]["end"]["kind"]] + [p["kind"] for p in world.summary["drops"]["patches"]],
            **({"oracle frames": len(used)} if oracle else {}), **({"why": causes} if why else {})}


CAUSES = ("a: no pixel sees it", "a: out of disparity range", "a: image border", "a: uniform (eq. 13)", "a: matcher invalid",
          "b: no texture along the rows (min_row_texture)",
          "b: within a step plus a max_slope_deg slope of the floor before",
          "b: within the noise margin (n_sigma sigma_h)", "b: within both (slope and noise) together",
          "b: a run shorter than support",
          "b: the far rim not seen spreading over edge_reach_m", "b: other (the mismatch test, the face rules)",
          "b: floor only, nothing below measured near",
          "c: candidate not confirmed", "d: weak points in a frame, too few views in the map",
          "d: drop points in a frame, lost in the map")
"""The causes of a missed edge cell (:func:`missed_causes`), in the order they are tested (last first)."""
RULES = ("texture", "slope", "noise", "both", "short", "rim")
"""The variants of the drop test that tell the "b" causes apart, in :data:`CAUSES`' order."""


def missed_causes(manifest, grid, missed: np.ndarray, range_m: float, config=None, drops=None,
                  near_m: float = 0.4) -> dict[str, int]:
    """Why each ``missed`` edge cell is not lethal in the map: each frame observed again (the mapper's chain,
    :func:`mrstereo.geometry.pair.scan_from_pair`, the given mount and pose); the pixels whose TRUE point
    (true disparity) lies in the cell or next to it are the cell's pixels. In the order tested:

    * **d**: some frame's drop points (edge or below) fell in the cell or next to it, but the map lost them (too
      few per cell and view for a vote, votes taken back by floor seen there later); else some frame's weak
      points did, from too few views (``drop_weak_views``, ``drop_weak_share``) for the map;
    * **c**: some frame's drop candidate had its edge ``S -> E`` there, but the map never confirmed it;
    * **b**: some frame measured a cell's pixel (a disparity after eq. 13): with points below the floor
      (``z < -2 max_step_m``) measured within ``near_m`` of the cell in that frame the column rule judged them
      drivable or a mismatch: the same frame's drop test finds the cell with ``max_slope_deg = 0`` (the
      allowance of a step plus a drivable slope from the floor before), else with ``n_sigma = 0`` (the noise
      margin), else with both at 0, else with ``support = 1`` (a run too short), else with ``edge_reach_m = 0`` (the floor after a
      steep face not seen spreading on: the far rim), else none (the mismatch test, the face rules); without, only the floor was
      measured, nothing below it near;
    * **a**: no frame measured any of the cell's pixels (or no frame's true disparity has any: out of view);
      the reason most of its pixels share: the true
      disparity beyond the matcher's range (too near) or below 1 px, the pixel's match outside the right
      image (``x - d < 0``), the matcher's disparity rejected by eq. (13) (uniform), or none from the
      matcher (its left-right and uniqueness checks, occlusion).
    """
    from mrstereo.geometry import ground_from_mount, points_robot_from_disparity
    from mrstereo.geometry.drops import find_drops
    from mrstereo.geometry.ground import T_robot_from_cam_ground
    from mrstereo.geometry.pair import scan_from_pair
    from mrstereo.io.images import read_pfm
    from mrstereo.pipeline.run import PipelineConfig
    from mrstereo.recordings.manifest import frame_pair
    from mrstereo.rejection import row_texture
    from mrstereo.transforms import T_from_planar

    config = PipelineConfig() if config is None else config
    drops = drops if drops is not None else __import__("mrstereo.geometry.drops", fromlist=["DropConfig"]).DropConfig()
    stereo = manifest.calibration
    obstacles = replace(config.for_rig(stereo).obstacle_config, drops=drops)
    options = {**replace(config, obstacles=obstacles).pair_options()}
    floor = ground_from_mount(manifest.mount, R_rect_from_cam=stereo.left.R)
    cells = np.argwhere(missed)
    n = len(cells)
    stats = {k: np.zeros(n, np.int64) for k in ("pixels", "range", "border", "uniform", "invalid", "measured",
                                                 "below", "detected", "weak", "candidate", *RULES)}
    near_cells = int(np.ceil(near_m / grid.resolution_m))

    hits = lambda world_xy, radius: _near(grid, cells, world_xy, radius)      # noqa: E731
    for record in manifest.frames:
        left, right, rectified = frame_pair(record)
        pair = scan_from_pair(left, right, stereo, rectified=rectified, mount=manifest.mount,
                              pan_rad=record.pan_rad, **options).frame
        obs = pair.obstacles
        T = T_from_planar(*record.pose)
        world = lambda p: p[:, :2] @ T[:2, :2].T + T[:2, 3]           # noqa: E731
        truth = read_pfm(record.gt_disparity)
        T_cam = T_robot_from_cam_ground(floor, pan_rad=record.pan_rad)
        true_xy = world(points_robot_from_disparity(truth, stereo, T_cam).reshape(-1, 3))
        r, c = grid.cells_from_xy(true_xy)
        ok = np.isfinite(true_xy).all(axis=1)
        key = np.full(grid.shape, -1, np.int64)
        cols = truth.shape[1]
        x = np.arange(truth.size) % cols
        measured = np.isfinite(pair.disparity_px).ravel()
        raw = np.isfinite(pair.raw_disparity_px).ravel()
        d = truth.ravel()
        reason = {"range": (d > pair.max_disparity_px) | (d < 1.0), "border": x - d < 0,
                  "uniform": raw & ~measured, "invalid": ~raw}
        reason["border"] &= ~reason["range"]
        reason["uniform"] &= ~reason["range"] & ~reason["border"]
        reason["invalid"] &= ~reason["range"] & ~reason["border"]
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                key[:] = -1
                rr, cc = cells[:, 0] + dr, cells[:, 1] + dc
                inside = grid.inside(rr, cc)
                key[rr[inside], cc[inside]] = np.flatnonzero(inside)
                sel = ok & grid.inside(r, c)
                k = np.full(len(d), -1, np.int64)
                k[sel] = key[r[sel], c[sel]]
                mine = k >= 0
                stats["pixels"] += np.bincount(k[mine], minlength=n)
                stats["measured"] += np.bincount(k[mine & measured], minlength=n)
                for name, mask in reason.items():
                    stats[name] += np.bincount(k[mine & mask], minlength=n)
        pts = obs.points_robot
        low = pts[pts[:, 2] < -2.0 * drops.max_step_m]
        measured_now = stats["measured"] > 0
        stats["below"] += hits(world(low), near_cells) & measured_now
        stats["detected"] += hits(world(obs.drop_points_robot), 1)
        stats["weak"] += hits(world(obs.drop_weak_points_robot), 1)
        bf = float(stereo.baseline_m) * float(stereo.focal_px)
        untextured = (None if drops.min_row_texture is None else
                      row_texture(pair.left_rect, window_px=options["rejection"].window_px) < drops.min_row_texture)
        for name, variant in (("texture", drops), ("slope", replace(drops, max_slope_deg=0.0)),
                              ("noise", replace(drops, n_sigma=0.0)),
                              ("both", replace(drops, n_sigma=0.0, max_slope_deg=0.0)),
                              ("short", replace(drops, support=1)), ("rim", replace(drops, edge_reach_m=0.0))):
            found = find_drops(obs.points_robot_image, obs.T_robot_from_cam, bf, config=variant,
                               floor_top_m=obstacles.min_obstacle_height_m, max_range_m=obstacles.max_range_m,
                               untextured=None if name == "texture" else untextured)
            stats[name] += hits(world(found.points_robot), 1)
        cand = obs.drop_candidates_robot
        f = np.linspace(0.0, 1.0, 6)[:, None, None]
        edge = (cand[None, :, 0:2] + f * (cand[None, :, 2:4] - cand[None, :, 0:2])).reshape(-1, 2)
        stats["candidate"] += hits(world(edge), 1)
    return _tally(stats)


def _near(grid, cells: np.ndarray, world_xy: np.ndarray, radius: int) -> np.ndarray:
    """Per cell of ``cells`` (K, 2): does some point of ``world_xy`` (N, 2) lie within ``radius`` cells of it?"""
    if len(world_xy) == 0:
        return np.zeros(len(cells), bool)
    r, c = grid.cells_from_xy(world_xy)
    occupied = np.zeros((grid.shape[0] + 2 * radius + 2, grid.shape[1] + 2 * radius + 2), bool)
    inside = (r >= -radius) & (r < grid.shape[0] + radius) & (c >= -radius) & (c < grid.shape[1] + radius)
    occupied[r[inside] + radius, c[inside] + radius] = True
    window = np.lib.stride_tricks.sliding_window_view(occupied, (2 * radius + 1, 2 * radius + 1))
    return window[cells[:, 0], cells[:, 1]].any(axis=(1, 2))


def _tally(stats: dict[str, np.ndarray]) -> dict[str, int]:
    """The cause of each cell from its counts over the frames (:func:`missed_causes`), counted per cause."""
    n = len(stats["pixels"])
    counts = dict.fromkeys(CAUSES, 0)
    for i in range(n):
        if stats["detected"][i]:
            counts[CAUSES[15]] += 1
        elif stats["weak"][i]:
            counts[CAUSES[14]] += 1
        elif stats["candidate"][i]:
            counts[CAUSES[13]] += 1
        elif stats["measured"][i] and not stats["below"][i]:
            counts[CAUSES[12]] += 1
        elif stats["measured"][i]:
            rule = next((k for k, name in enumerate(RULES) if stats[name][i]), len(RULES))
            counts[CAUSES[5 + rule]] += 1
        else:
            share = [stats[k][i] for k in ("range", "border", "uniform", "invalid")]
            counts[CAUSES[1 + int(np.argmax(share)) if stats["pixels"][i] else 0]] += 1
    return counts


def _goals(world) -> list[tuple[float, float]]:
    """Goals past a drop: the centre of each hole or stairwell, and beyond the ledge."""
    drops = world.summary["drops"]
    goals = [((p["rect_m"][0] + p["rect_m"][1]) / 2, (p["rect_m"][2] + p["rect_m"][3]) / 2)
             for p in drops["patches"] if p["kind"] in ("hole", "stairwell")]
    if drops["end"]["kind"] == "ledge":
        goals.append((drops["end"]["x_m"] + 0.6, 0.0))
    return goals


def evaluate_real(frames: int, config=None, drops=None) -> list[dict]:
    """Flat floors of real recordings: the share of free cells the drop test changes."""
    from mrstereo.mapping.rosmap import ros_map_on_grid
    from mrstereo.recordings import read_recording
    from mrstereo.recordings.samples import data_root

    rows = []
    for name, path in REAL:
        root = data_root() / path
        if not root.exists():
            rows.append({"recording": name, "missing": str(root)})
            continue
        t0 = time.process_time()
        with _floor_untextured() as untextured:
            run, plain = paired_maps(read_recording(root), frames=frames, config=config, drops=drops)
        a, b = (r.grid.to_ros_map() for r in (run, plain))
        b = ros_map_on_grid(b, a.grid)           # the map with drops may reach farther: compare on its window
        free = b.free
        changed = free & ~a.free
        rows.append({"recording": name, "free cells": int(free.sum()), "changed": int(changed.sum()),
                     "share changed": float(changed.sum() / max(free.sum(), 1)),
                     "drop cells": int(run.grid.drop.sum()),
                     "floor untextured (median, max)": (f"{np.median(untextured):.3f}, {np.max(untextured):.3f}"
                                                        if untextured else "-"),
                     "cpu s": time.process_time() - t0})
    return rows


@contextmanager
def _floor_untextured(floor_top_m: float = 0.08):
    """While inside, each frame's drop test records the share of its floor-level points (``|z| < floor_top_m``)
    without texture along the rows (``DropConfig.min_row_texture``: never below the floor for the test, still
    floor), for the frames with more than 100 such points; yields the list of shares."""
    from mrstereo.geometry import obstacles

    shares: list[float] = []
    find = obstacles.find_drops

    def recorded(points, *args, untextured=None, **kwargs):
        floor = np.abs(points[..., 2]) < floor_top_m          # (NaN: False)
        if untextured is not None and floor.sum() > 100:
            shares.append(float(untextured[floor].mean()))
        return find(points, *args, untextured=untextured, **kwargs)

    obstacles.find_drops = recorded
    try:
        yield shares
    finally:
        obstacles.find_drops = find


REAL = (("EuRoC ASL sample", "euroc_asl_sample"), ("KITTI odometry 06", "kitti_odometry_06"),
        ("KITTI odometry 01", "kitti_odometry_01"), ("OpenLORIS", "openloris_sample"))
"""The real recordings with a floor in the data folder (``MRSTEREO_DATA``)."""


def evaluate_corridor(data_dir: Path) -> list[dict]:
    """The corridor's precision bounds with and without the drop test: the 12-frame s-curve drive of
    tests/test_live.py (visual odometry from the raw images; bound: 0.6 of the occupied cells on true walls) and
    the demo's 6-frame corridor (``MapMetrics.precision``; bound 0.8), both on the paper's 12 m x 6 m window."""
    from mrstereo.geometry.drops import DropConfig
    from mrstereo.mapping import GridSpec, read_ros_map
    from mrstereo.pipeline.run import PipelineConfig, build_map
    from mrstereo.recordings import read_recording
    from mrstereo.world import write_synthetic_dataset

    rows = []
    for name, folder, options, run_kw in (
            ("live s-curve, 12 frames", "scurve", dict(n_frames=12, supersample=1, path="s-curve", step_m=0.1),
             dict(odometry="visual", prefer_raw=True)),
            ("demo corridor, 6 frames", "demo", dict(n_frames=6), {})):
        ds = data_dir / folder
        if not (ds / "manifest.yaml").is_file():
            write_synthetic_dataset(ds, progress=False, **options)
        manifest = read_recording(ds)
        gt = read_ros_map(manifest.ground_truth_map)
        for drops in (None, DropConfig()):
            run = build_map(manifest, config=PipelineConfig(grid=GridSpec(), drops=drops), progress=False, **run_kw)
            ours = run.grid.to_ros_map()
            rows.append({"map": name, "drops": drops is not None,
                         "occupied on true walls": float((gt.occupied & ours.occupied).sum() / max(ours.occupied.sum(), 1)),
                         "precision": float(run.metrics.precision), "recall": float(run.metrics.recall),
                         "drop cells": int(run.grid.drop.sum())})
    return rows


def measure_speed(repeats: int) -> list[dict]:
    """Median CPU seconds of one frame with and without the drop test (interleaved), per input (the test's own
    time: its pass over the points and the row texture of the image it needs); the ratios are
    medians of each round's ratio (a round runs every configuration once, so slow spells of the machine
    cancel)."""
    from mrstereo.geometry import ObstacleConfig, obstacles, pair
    from mrstereo.geometry.drops import DropConfig
    from mrstereo.geometry.pair import obstacles_from_pair
    from mrstereo.recordings import read_recording
    from mrstereo.recordings.manifest import frame_pair
    from mrstereo.recordings.samples import data_root
    from mrstereo.world import default_scene, default_stereo, render_stereo_frame

    stereo = default_stereo()
    frame = render_stereo_frame(default_scene(0), stereo, pose=(1.0, 0.0, 0.0))
    inputs = [("corridor 320x240", frame.left_rect, frame.right_rect, stereo, True, None)]
    euroc = data_root() / "euroc_asl_sample"
    if euroc.exists():
        manifest = read_recording(euroc)
        left, right, rectified = frame_pair(manifest.frames[0])
        inputs.append(("EuRoC 752x480", left, right, manifest.calibration, rectified, manifest.mount))
    rows = []
    spent, triangulation = [0.0], [0.0]
    with (_timed(obstacles, "_with_drops", spent), _timed(pair, "row_texture", spent),
          _timed(obstacles._kernels, "obstacle_points", triangulation)):
        for name, left, right, calib, rectified, mount in inputs:
            configs = {"with": ObstacleConfig(drops=DropConfig()), "without": ObstacleConfig(),
                       "no weak": ObstacleConfig(drops=DropConfig(weak_n_sigma=None))}
            times: dict[str, list[float]] = {key: [] for key in [*configs, "test"]}
            walls: dict[str, list[float]] = {key: [] for key in configs}
            for k in range(repeats + 1):
                own = {}
                for key in list(configs)[::1 if k % 2 else -1]:
                    spent[0] = triangulation[0] = 0.0
                    t0, w0 = time.process_time(), time.perf_counter()
                    obstacles_from_pair(left, right, calib, rectified=rectified, mount=mount, config=configs[key])
                    if k:                                           # the first round compiles
                        times[key].append(time.process_time() - t0)
                        walls[key].append(time.perf_counter() - w0)
                        own[key] = spent[0] + triangulation[0]
                if k:       # the test's point image is written in the triangulation pass: its extra time counts
                    times["test"].append(own["with"] - own["without"])
            a, b, c, test = (float(np.median(times[key])) for key in times)
            paired = [float(np.median(np.divide(times[key], times["without"]))) for key in ("with", "no weak")]
            rows.append({"input": name, "with drops cpu s": a, "without cpu s": b, "ratio": paired[0],
                         "ratio without weak points": paired[1],
                         "wall ratio": float(np.median(np.divide(walls["with"], walls["without"]))),
                         "drop test cpu s": test, "drop test share": test / a})
    return rows + [_mapper_speed(repeats)]


def measure_live(repeats: int, n_frames: int) -> list[dict]:
    """The live loop's rate with and without the drop test: the real frames of the EuRoC and OpenLORIS samples
    driven forth and back to ``n_frames`` frames, as fast as they go (``mrstereo live`` without ``--realtime``:
    two matchers busy, nothing dropped; visual odometry, the growing map; freed memory kept for reuse as the
    command keeps it), runs with and without it alternating; the ratio is the median of each round's (without /
    with), and the same for the process's CPU time per frame (with / without)."""
    from bench_live import _Looped

    from mrstereo.geometry.drops import DropConfig
    from mrstereo.pipeline.live import LiveConfig, run_live
    from mrstereo.pipeline.run import PipelineConfig
    from mrstereo.recordings import read_recording
    from mrstereo.recordings.samples import data_root
    from mrstereo.recordings.sources import RecordingSource

    rows = []
    for name in ("euroc_asl_sample", "openloris_sample"):
        if not (data_root() / name).exists():
            print(f"{name} not found under {data_root()} (set MRSTEREO_DATA)")
            continue
        manifest = read_recording(data_root() / name)
        frames = list(RecordingSource(manifest))
        rates: dict[str, list[float]] = {"with": [], "without": []}
        cpu: dict[str, list[float]] = {"with": [], "without": []}
        with tempfile.TemporaryDirectory(prefix="bench_drops_live_") as tmp:
            for k in range(repeats + 1):
                for key in ("with", "without") if k % 2 else ("without", "with"):
                    source = _Looped(frames, n_frames, 20.0, calibration=manifest.calibration, mount=manifest.mount)
                    run = run_live(source, Path(tmp) / f"{key}{k}", calibration=manifest.calibration,
                                   mount=manifest.mount, config=PipelineConfig(drops=DropConfig() if key == "with"
                                                                               else None),
                                   live=LiveConfig(odometry="visual"))
                    if k:                                           # the first round compiles
                        rates[key].append(run.rate_hz)
                        metrics = run.metrics()
                        cpu[key].append(1000.0 * metrics["cpu_s"]["process"] / max(metrics["frames_processed"], 1))
        ratios = np.divide(rates["without"], rates["with"])
        size = "x".join(map(str, manifest.calibration.size))
        rows.append({"input": f"live, {name} {size}, {len(frames)} frames to {n_frames}",
                     "with drops Hz": float(np.median(rates["with"])),
                     "without Hz": float(np.median(rates["without"])), "ratio": float(np.median(ratios)),
                     "ratio min": float(ratios.min()), "ratio max": float(ratios.max()),
                     "cpu ms per frame with": float(np.median(cpu["with"])),
                     "without": float(np.median(cpu["without"])),
                     "cpu ratio": float(np.median(np.divide(cpu["with"], cpu["without"])))})
    return rows


@contextmanager
def _timed(owner, name: str, spent: list[float]):
    """Within the block ``owner.name`` adds the CPU seconds of each call to ``spent[0]``: of the calling thread
    (``time.thread_time``), where the call runs; the matcher's OpenMP workers spinning down after it (numba's
    ``omp`` layer) would land in a process-wide clock and double a short call's time."""
    original = getattr(owner, name)

    def timed(*args, **kwargs):
        t0 = time.thread_time()
        try:
            return original(*args, **kwargs)
        finally:
            spent[0] += time.thread_time() - t0

    setattr(owner, name, timed)
    try:
        yield
    finally:
        setattr(owner, name, original)


def _mapper_speed(repeats: int) -> dict:
    """Median CPU seconds of a whole mapper step (the chain, the grid, the height and drop layers) with and
    without the drop test, two mappers stepped through the same corridor frames in turn (20 stops 0.25 m apart,
    from the first again beyond 20 repeats); and of the layers'
    update alone (``OccupancyGrid.add_layers``) within the step with the test."""
    from mrstereo.geometry.drops import DropConfig
    from mrstereo.mapping.occupancy import OccupancyGrid
    from mrstereo.pipeline.mapper import PipelineConfig, StereoMapper
    from mrstereo.transforms import T_from_planar
    from mrstereo.world import default_scene, default_stereo, render_stereo_frame

    stereo = default_stereo()
    scene = default_scene(0)
    stops = [(0.5 + 0.25 * k, 0.0, 0.0) for k in range(20)]     # short of the box standing 6 m out, then again
    rendered = [render_stereo_frame(scene, stereo, pose=p) for p in stops[:repeats + 1]]
    poses = [stops[k % len(stops)] for k in range(repeats + 1)]
    frames = [rendered[k % len(stops)] for k in range(repeats + 1)]
    mappers = {key: StereoMapper(stereo, stereo.mount, PipelineConfig(drops=d), check_mount=False)
               for key, d in (("with", DropConfig()), ("without", None))}
    times: dict[str, list[float]] = {"with": [], "without": [], "layers": []}
    spent = [0.0]
    with _timed(OccupancyGrid, "add_layers", spent):
        for k, (pose, frame) in enumerate(zip(poses, frames)):
            for key in ("with", "without") if k % 2 else ("without", "with"):
                spent[0] = 0.0
                t0 = time.process_time()
                mappers[key].step(frame.left_rect, frame.right_rect, rectified=True, pose=T_from_planar(*pose))
                if k:                                           # the first round compiles
                    times[key].append(time.process_time() - t0)
                    if key == "with":
                        times["layers"].append(spent[0])
    a, b, layers = (float(np.median(times[key])) for key in ("with", "without", "layers"))
    ratio = float(np.median(np.divide(times["with"], times["without"])))        # per round (see measure_speed)
    return {"input": "mapper step, corridor 320x240", "with drops cpu s": a, "without cpu s": b, "ratio": ratio,
            "layers cpu s": layers, "layers share": layers / a}


def main() -> None:
    from mrstereo.geometry.drops import DropConfig

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", nargs="+", default=["200-209"], help="seeds, e.g. 0-4 or 200-209")
    parser.add_argument("--frames", type=int, default=24, help="frames per world or recording")
    parser.add_argument("--view", type=float, default=2.5, help="range [m] of the edges the recall counts")
    parser.add_argument("--path", choices=("stops", "front"), default="stops",
                        help="the worlds' frames: three views at each stop, or a drive looking ahead (a frame "
                             "every 0.1 m or less)")
    parser.add_argument("--every", type=int, default=1,
                        help="only every so many of the frames: the same path at a lower frame rate")
    parser.add_argument("--drop-min-points", type=int, default=None, help="MappingConfig.drop_min_points")
    parser.add_argument("--drop-clear-points", type=int, default=None, help="MappingConfig.drop_clear_points")
    parser.add_argument("--drop-max-votes", type=int, default=None, help="MappingConfig.drop_max_votes")
    parser.add_argument("--drop-low", dest="drop_low_m", type=float, default=None, help="MappingConfig.drop_low_m")
    parser.add_argument("--drop-weak-views", type=int, default=None, help="MappingConfig.drop_weak_views")
    parser.add_argument("--drop-weak-share", type=float, default=None, help="MappingConfig.drop_weak_share")
    parser.add_argument("--no-robot-floor", action="store_true",
                        help="DropConfig(robot_floor=False): only the map's memory confirms a drop with no floor "
                             "measured before it in its column")
    parser.add_argument("--n-sigma", type=float, default=DropConfig.n_sigma, help="DropConfig.n_sigma")
    parser.add_argument("--disparity-sigma", type=float, default=None,
                        help="a fixed disparity error [px] for the noise margin (DropConfig.disparity_sigma_px with "
                             "noise_from_floor=False); default: measured on each frame's floor")
    parser.add_argument("--weak-n-sigma", type=lambda v: None if v.lower() == "none" else float(v),
                        default=DropConfig.weak_n_sigma, help="DropConfig.weak_n_sigma ('none': no weak votes)")
    parser.add_argument("--fattening-px", type=int, default=DropConfig.fattening_px, help="DropConfig.fattening_px")
    parser.add_argument("--min-row-texture", type=lambda v: None if v.lower() == "none" else float(v),
                        default=DropConfig.min_row_texture,
                        help="DropConfig.min_row_texture ('none': every pixel takes part in the test)")
    parser.add_argument("--why", action="store_true",
                        help="also the causes of the missed edge cells, per seed and summed (missed_causes)")
    parser.add_argument("--oracle", action="store_true",
                        help="the frames' true disparity instead of the matcher's (oracle_disparity)")
    parser.add_argument("--real", action="store_true", help="the real recordings instead of the worlds")
    parser.add_argument("--data", default=None, help="keep rendered datasets here (reused when present)")
    parser.add_argument("--speed", action="store_true", help="CPU time of a frame with and without the drop test")
    parser.add_argument("--corridor", action="store_true", help="the corridor maps' precision with and without it")
    parser.add_argument("--live", type=int, default=0, metavar="N",
                        help="the live loop's rate with and without it, N frames a run")
    parser.add_argument("--repeats", type=int, default=15, help="--speed, --live: runs of each")
    args = parser.parse_args()
    if args.live < 0 or args.repeats < 1:
        parser.error("--live must be at least 0 and --repeats at least 1")
    if args.speed or args.live:
        from mrstereo._executor import keep_freed_memory

        keep_freed_memory()          # as the mrstereo command does: frame-sized arrays reused, not faulted in anew
    if args.speed:
        for row in measure_speed(args.repeats):
            print("  ".join(f"{k}: {v:.4f}" if isinstance(v, float) else f"{k}: {v}" for k, v in row.items()))
        return
    if args.live:
        for row in measure_live(args.repeats, args.live):
            print("  ".join(f"{k}: {v:.4f}" if isinstance(v, float) else f"{k}: {v}" for k, v in row.items()),
                  flush=True)
        return
    from mrstereo.pipeline.run import PipelineConfig

    tuned = {k: getattr(args, k) for k in ("drop_min_points", "drop_clear_points", "drop_max_votes", "drop_low_m",
                                           "drop_weak_views", "drop_weak_share") if getattr(args, k) is not None}
    base = PipelineConfig()
    try:                                        # a bad tuning value: one line naming it, exit 2
        fixed = {} if args.disparity_sigma is None else {"noise_from_floor": False,
                                                         "disparity_sigma_px": args.disparity_sigma}
        drops = DropConfig(robot_floor=not args.no_robot_floor, n_sigma=args.n_sigma,
                           weak_n_sigma=args.weak_n_sigma, fattening_px=args.fattening_px,
                           min_row_texture=args.min_row_texture, **fixed)
        config = replace(base, mapping=replace(base.mapping, **tuned))
    except (TypeError, ValueError) as error:
        parser.error(str(error))
    if args.corridor:
        data = Path(args.data) if args.data else Path(tempfile.mkdtemp(prefix="bench_drops_"))
        for row in evaluate_corridor(data):
            print("  ".join(f"{k}: {v:.3f}" if isinstance(v, float) else f"{k}: {v}" for k, v in row.items()),
                  flush=True)
        return
    if args.real:
        for row in evaluate_real(args.frames, config, drops):
            print("  ".join(f"{k}: {v:.4f}" if isinstance(v, float) else f"{k}: {v}" for k, v in row.items()),
                  flush=True)
        return
    data = Path(args.data) if args.data else Path(tempfile.mkdtemp(prefix="bench_drops_"))
    data.mkdir(parents=True, exist_ok=True)
    rows = []
    for seed in _parse_seeds(args.seeds):
        row = evaluate_seed(seed, args.frames, data, args.view, config, drops, why=args.why, oracle=args.oracle,
                            path=args.path, every=args.every)
        rows.append(row)
        print("  ".join(f"{k}: {v:.3f}" if isinstance(v, float) else f"{k}: {v}" for k, v in row.items()), flush=True)
    edge = sum(r["edge cells in view"] for r in rows)
    print(f"all: edge recall {sum(r['recall'] * r['edge cells in view'] for r in rows) / max(edge, 1):.3f} "
          f"(min {min(r['recall'] for r in rows):.3f}), false drops max "
          f"{max(r['false drops'] for r in rows):.4f} (mean {np.mean([r['false drops'] for r in rows]):.4f}; "
          f"> 0.15 m from an edge: {max(r['false > 0.15 m'] for r in rows):.4f}), on ramps/kerbs max "
          f"{max(r['on ramps/kerbs'] for r in rows):.4f} (mean {np.mean([r['on ramps/kerbs'] for r in rows]):.4f}), "
          f"crossings {sum(r['crossings'] for r in rows)} of {sum(r['goals'] for r in rows)} goals "
          f"({sum(r['of a seen edge'] for r in rows)} of a seen edge), undrivable "
          f"cells free {np.mean([r['undrivable free'] for r in rows]):.3f} (without the test "
          f"{np.mean([r['undrivable free without'] for r in rows]):.3f}; mean of the seeds)")
    if args.why:
        missed = sum(sum(r["why"].values()) for r in rows)
        print(f"missed edge cells: {missed}")
        for cause in CAUSES:
            total = sum(r["why"][cause] for r in rows)
            print(f"  {cause}: {total} ({total / max(missed, 1):.2f})")


if __name__ == "__main__":
    main()
