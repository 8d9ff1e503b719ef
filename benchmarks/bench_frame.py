"""The whole frame, from the raw pair to the grid update: mrstereo vs the chain a user builds from OpenCV.

Default mode (whole frame). The same frames (a ``mrstereo synth --seed 5`` corridor, 10
frames, rendered by this script into a temporary folder) at 640x480 and 320x240, in this
process, alternating frame by frame, with one thread and two (``numba.set_num_threads``,
``cv2.setNumThreads``; NUMBA_NUM_THREADS must allow 2):

* mrstereo: :class:`mrstereo.StereoMapper` on the raw pair with the given pose (rectify with the
  calibration, multi-range matching of the ``mapping`` preset, eq. 13 rejection, floor from
  the mount, eq. 14-16, obstacle/floor split, scan) then the grid cells it hits and clears and the
  log-odds update, as ``mrstereo map`` runs it.
* OpenCV: ``cv2.remap`` x2 with maps built once, ``StereoBM`` (9x9, ``numDisparities`` the
  multiple of 16 covering mrstereo's near limit), ``cv2.reprojectImageTo3D``, the same height
  band and range limit in the robot frame, ``np.add.at`` of the obstacle points into a grid of
  the same cells (hits only: no free-space rays, no sensor model).

Prints per size and thread count the median time per frame of each chain, the median of the
per-frame ratios mrstereo / OpenCV, and a per-stage table (median ms per frame).

``--scenes``: the matcher alone (robust preset) vs StereoBM over the same search on the
shared real scenes (Middlebury, KITTI: mrstereo.recordings.samples, ``$MRSTEREO_DATA``), each resized to
cover 640x480 and centre-cropped; plus the OpenLORIS T265 fisheye frames rectified with
their calibration and centre-cropped. Prints per scene and the median and range over scenes.

Timings are medians of alternated runs and robust to a steady load, not to a changing one:
quote numbers measured on a quiet machine only. ``--cpu`` times the stages in CPU time of the
calling thread instead (one thread): on a busy machine it still counts each chain's own work
(not the time other processes took), though shared caches still slow both chains.

``--cost nssd`` (or ``zncc``) runs the matcher with that window cost in both modes
(default: the preset's).

    python benchmarks/bench_frame.py [--repeats 3] [--frames 10] [--sizes 640x480,320x240] [--cpu] [--odometry]
    python benchmarks/bench_frame.py --scenes [--repeats 5] [--cpu] [--near-guard 0] [--cost nssd]
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import os
import tempfile
import time
from pathlib import Path

import cv2
import numba
import numpy as np

from mrstereo.io import read_image
from mrstereo._executor import keep_freed_memory
from mrstereo.mapping import GridSpec
from mrstereo.matching import make_plan
from mrstereo.pipeline.mapper import PipelineConfig, StereoMapper
from mrstereo.profiling import Profile, profiling
from mrstereo.recordings.manifest import read_manifest
from mrstereo.transforms import T_from_planar

STAGES = ("rectify", "match", "reject", "3-D", "free space", "grid")
CLOCK = time.perf_counter
"""The clock of every stage time: wall-clock, or with ``--cpu`` the calling thread's CPU time."""


def thread_counts() -> list[int]:
    if CLOCK is not time.perf_counter:
        return [1]                     # CPU time of the calling thread: one thread only
    return [t for t in (1, 2) if t <= numba.config.NUMBA_NUM_THREADS]


def set_threads(n: int) -> None:
    numba.set_num_threads(n)
    cv2.setNumThreads(n)


# ----------------------------------------------------------------------------- whole frame
class MrstereoChain:
    """mrstereo from the raw pair to the log-odds grid, stage times from :mod:`mrstereo.profiling`;
    with ``odometry`` also the visual odometry's step on the frame (its own stage, fed the rectified
    pair and the frame's disparity; a new track at frame 0 of every pass)."""

    def __init__(self, manifest, config: PipelineConfig, odometry: bool = False):
        self.manifest, self.config = manifest, config
        self.mapper = StereoMapper(manifest.calibration, manifest.mount, config, check_mount=False)
        plan = make_plan(manifest.calibration.size, calibration=manifest.calibration)
        self.max_disparity_px = max(level.band_px[1] for level in plan.levels)     # the search's near limit
        self.odometry, self.vo = odometry, None

    def __call__(self, k: int, left, right) -> dict[str, float]:
        record = self.manifest.frames[k]
        with profiling(Profile(clock=CLOCK)) as prof:
            [frame] = self.mapper.step(left, right, pose=record.T_world_from_base, pan_rad=record.pan_rad)
        if self.odometry:
            from mrstereo.odometry import StereoOdometry

            stereo = self.manifest.calibration
            if k == 0 or self.vo is None:
                self.vo = StereoOdometry(stereo)
            left_rect, right_rect = stereo.rectify(left, right)       # (done inside the chain above too)
            t0 = CLOCK()
            mount = self.manifest.mount.T_base_from_rectified(stereo.left.R, record.pan_rad)
            self.vo.step(left_rect, right_rect, T_base_from_cam=mount, disparity_px=frame.disparity_px)
            prof.add("odometry", CLOCK() - t0)
        return {name: 1000.0 * prof.seconds.get(name, 0.0) for name in STAGES + ("odometry",)}


class OpenCVChain:
    """remap x2 -> StereoBM -> reprojectImageTo3D -> height band -> np.add.at into a grid."""

    def __init__(self, manifest, config: PipelineConfig, max_disparity_px: float):
        stereo = manifest.calibration
        self.manifest, self.config = manifest, config
        self.maps = [cv2.initUndistortRectifyMap(info.camera.K, info.camera.dist_coeffs, info.R, info.P,
                                                 stereo.size, cv2.CV_32FC1) for info in (stereo.left, stereo.right)]
        self.n_disp = 16 * math.ceil(max_disparity_px / 16)
        self.bm = cv2.StereoBM.create(numDisparities=self.n_disp, blockSize=9)
        f, b = stereo.focal_px, stereo.baseline_m
        self.Q = np.array([[1, 0, 0, -stereo.cx_px], [0, 1, 0, -stereo.cy_px], [0, 0, 0, f],
                           [0, 0, 1 / b, stereo.doffs_px / b]], dtype=np.float64)
        self.counts = np.zeros(config.grid.shape, dtype=np.int32)

    def __call__(self, k: int, left, right) -> dict[str, float]:
        record, grid, obst = self.manifest.frames[k], self.config.grid, self.config.obstacle_config
        T_rc = self.manifest.mount.T_base_from_rectified(self.manifest.calibration.left.R, record.pan_rad)
        t = [CLOCK()]
        left_r = cv2.remap(left, *self.maps[0], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        right_r = cv2.remap(right, *self.maps[1], cv2.INTER_LINEAR, borderMode=cv2.BORDER_REPLICATE)
        t.append(CLOCK())
        disp16 = self.bm.compute(left_r, right_r)
        t.append(CLOCK())
        disp = disp16.astype(np.float32) / 16.0
        xyz = cv2.reprojectImageTo3D(disp, self.Q)
        valid = disp > 0
        pts = xyz[valid] @ T_rc[:3, :3].T + T_rc[:3, 3]
        band = ((pts[:, 2] > obst.min_obstacle_height_m) & (pts[:, 2] < obst.max_obstacle_height_m)
                & (np.hypot(pts[:, 0], pts[:, 1]) <= obst.max_range_m))
        t.append(CLOCK())
        T_wr = T_from_planar(*record.pose)
        pts = pts[band] @ T_wr[:3, :3].T + T_wr[:3, 3]
        col = np.floor((pts[:, 0] - grid.origin_x_m) / grid.resolution_m).astype(np.intp)
        row = np.floor((pts[:, 1] - grid.origin_y_m) / grid.resolution_m).astype(np.intp)
        rows, cols = self.counts.shape
        inside = (row >= 0) & (row < rows) & (col >= 0) & (col < cols)
        np.add.at(self.counts, (row[inside], col[inside]), 1)
        t.append(CLOCK())
        ms = 1000.0 * np.diff(t)
        return {"rectify": ms[0], "match": ms[1], "reject": 0.0, "3-D": ms[2], "free space": 0.0, "grid": ms[3]}


def load_frames(manifest) -> list[tuple[np.ndarray, np.ndarray]]:
    def gray(path):
        image = read_image(path)
        return image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)

    return [(gray(f.left), gray(f.right)) for f in manifest.frames]


def whole_frame(sizes, n_frames: int, repeats: int, seed: int, odometry: bool = False, cost: str | None = None
                ) -> None:
    from mrstereo.matching import preset_config
    from mrstereo.world.dataset import write_synthetic_dataset

    config = PipelineConfig()
    if config.grid is None:          # both chains on one fixed grid (the default map grows in tiles)
        config = dataclasses.replace(config, grid=GridSpec())
    if cost is not None:
        config = dataclasses.replace(config, matching=preset_config(config.preset).replace(cost={"kind": cost}))
    print(f"whole frame, raw pair -> grid update; synthetic corridor seed {seed}, {n_frames} frames, "
          f"{repeats} repeats; {'CPU time of the thread' if CLOCK is time.thread_time else 'wall-clock'}; "
          f"load average {os.getloadavg()}")
    for width, height in sizes:
        with tempfile.TemporaryDirectory(prefix="bench-frame-") as tmp:
            folder = write_synthetic_dataset(Path(tmp) / "corridor", seed=seed, n_frames=n_frames, width=width,
                                             height=height, progress=False, path="front" if odometry else "stops")
            manifest = read_manifest(folder)
            frames = load_frames(manifest)
        mr = MrstereoChain(manifest, config, odometry=odometry)
        for k, (left, right) in enumerate(frames):       # warm-up: numba compile / cache load, every frame
            mr(k, left, right)
        cv = OpenCVChain(manifest, config, mr.max_disparity_px)
        for k, (left, right) in enumerate(frames):
            cv(k, left, right)
        print(f"\n{width}x{height}: mrstereo preset '{config.preset}', cost {cost or 'of the preset'} (search up to {mr.max_disparity_px:.0f} px) vs "
              f"StereoBM {cv.n_disp} disparities 9x9")
        for threads in thread_counts():
            set_threads(threads)
            t_mr, t_cv, ratios = [], [], []
            for rep in range(repeats):
                for k, (left, right) in enumerate(frames):
                    order = (cv, mr) if (rep + k) % 2 == 0 else (mr, cv)     # alternate who runs first
                    times = {id(chain): chain(k, left, right) for chain in order}
                    a, b = times[id(mr)], times[id(cv)]
                    t_mr.append(a)
                    t_cv.append(b)
                    ratios.append(sum(v for n, v in a.items() if n in STAGES) / sum(b.values()))
            total_mr = float(np.median([sum(v for n, v in a.items() if n in STAGES) for a in t_mr]))
            total_cv = float(np.median([sum(b.values()) for b in t_cv]))
            print(f"  threads={threads}: mrstereo {total_mr:.1f} ms/frame, OpenCV chain {total_cv:.1f} ms/frame, "
                  f"ratio mrstereo/OpenCV {np.median(ratios):.2f} (range {min(ratios):.2f}-{max(ratios):.2f})")
            print("    | stage | mrstereo ms | OpenCV ms |\n    |---|---|---|")
            for name in STAGES + (("odometry",) if odometry else ()):
                print(f"    | {name} | {np.median([a[name] for a in t_mr]):.2f} | "
                      f"{np.median([b.get(name, 0.0) for b in t_cv]):.2f} |")
        set_threads(max(thread_counts()))
    print(f"\nload average after: {os.getloadavg()}")


# ----------------------------------------------------------------------------- matcher on real scenes
SCENES = ["tsukuba", "venus", "teddy", "cones", "kitti2012-000070", "kitti2015-000000"]


def to_640x480(image, scale: float):
    """Resize by ``scale`` (area / linear) and centre-crop to 640x480."""
    if scale != 1.0:
        size = (int(round(image.shape[1] * scale)), int(round(image.shape[0] * scale)))
        image = cv2.resize(image, size, interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR)
    h, w = image.shape[:2]
    top, left = (h - 480) // 2, (w - 640) // 2
    return np.ascontiguousarray(image[top:top + 480, left:left + 640])


def real_scenes() -> list[tuple[str, np.ndarray, np.ndarray, float]]:
    """(name, left, right, max disparity px) at 640x480; scenes that are not available are skipped."""
    from mrstereo.evaluation import load_scene
    from mrstereo.recordings import samples as sample_data

    out = []
    for name in SCENES:
        try:
            s = load_scene(sample_data.fetch(name))
        except (OSError, ValueError) as exc:
            print(f"  {name}: skipped ({exc})")
            continue
        h, w = s.left.shape[:2]
        scale = max(640 / w, 480 / h)
        gray = [x if x.ndim == 2 else cv2.cvtColor(x, cv2.COLOR_BGR2GRAY) for x in (s.left, s.right)]
        out.append((name, to_640x480(gray[0], scale), to_640x480(gray[1], scale),
                    float(s.max_disparity_px) * scale))
    try:
        from mrstereo.camera.formats import import_calibration

        root = sample_data.fetch("openloris-sample")
        stereo = import_calibration(root / "sensors.yaml").stereo
        near_m = 0.5
        for path in sorted((root / "fisheye1").glob("*.png")):
            left, right = (cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in (path, root / "fisheye2" / path.name))
            left, right = stereo.rectify(left, right)
            out.append((f"openloris {path.stem}", to_640x480(left, 1.0), to_640x480(right, 1.0),
                        stereo.focal_px * stereo.baseline_m / near_m))
    except (ImportError, OSError, ValueError) as exc:
        print(f"  openloris-sample: skipped ({exc})")
    return out


def paired(fn, base, repeats: int) -> tuple[float, float, float]:
    """Median ms of ``fn``, of ``base``, and the median per-pair ratio, run alternately."""
    fn()
    base()
    t_fn, t_base, ratios = [], [], []
    for i in range(repeats):
        for f, store in ((base, t_base), (fn, t_fn)) if i % 2 == 0 else ((fn, t_fn), (base, t_base)):
            t0 = CLOCK()
            f()
            store.append(CLOCK() - t0)
        ratios.append(t_fn[-1] / t_base[-1])
    return 1000 * float(np.median(t_fn)), 1000 * float(np.median(t_base)), float(np.median(ratios))


def scenes(repeats: int, near_guard: float | None = None, cost: str | None = None) -> None:
    from mrstereo.matching import compute_disparity, preset_config

    config = preset_config("robust")
    if cost is not None:
        config = config.replace(cost={"kind": cost})
    if near_guard is not None:
        config = config.replace(near_guard={"reach": near_guard} if near_guard > 0 else None)
    clock = "CPU time of the calling thread" if CLOCK is not time.perf_counter else "wall-clock"
    reach = 0 if config.near_guard is None else config.near_guard.reach
    print(f"matcher alone (robust preset, cost {config.cost.kind}, near guard reach {reach:g}) vs StereoBM 9x9 over the same search, "
          f"640x480; {repeats} repeats, {clock}; load average {os.getloadavg()}")
    pairs = real_scenes()
    for threads in thread_counts():
        set_threads(threads)
        print(f"\nthreads={threads}\n| scene | search px | StereoBM disparities | mrstereo ms | StereoBM ms | ratio |")
        print("|---|---|---|---|---|---|")
        ratios = []
        for name, left, right, max_d in pairs:
            n_disp = 16 * math.ceil(max_d / 16)
            bm = cv2.StereoBM.create(numDisparities=n_disp, blockSize=9)
            ms, base_ms, ratio = paired(lambda: compute_disparity(left, right, max_disparity_px=max_d, config=config),
                                        lambda: bm.compute(left, right), repeats)
            ratios.append(ratio)
            print(f"| {name} | {max_d:.0f} | {n_disp} | {ms:.1f} | {base_ms:.1f} | {ratio:.2f} |", flush=True)
        if ratios:
            print(f"ratio mrstereo/StereoBM over {len(ratios)} scenes: median {np.median(ratios):.2f}, "
                  f"range {min(ratios):.2f}-{max(ratios):.2f}")
    print(f"\nload average after: {os.getloadavg()}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3, help="passes over the frames (scenes: runs per scene)")
    parser.add_argument("--frames", type=int, default=10, help="frames of the synthetic corridor")
    parser.add_argument("--seed", type=int, default=5, help="seed of the synthetic corridor")
    parser.add_argument("--sizes", default="640x480,320x240", help="image sizes, e.g. 640x480,320x240")
    parser.add_argument("--scenes", action="store_true", help="the matcher alone on the shared real scenes")
    parser.add_argument("--odometry", action="store_true",
                        help="whole frame along the straight `front` path, with the visual odometry's step as a "
                             "stage of its own (not counted in the ratio to the OpenCV chain)")
    parser.add_argument("--cpu", action="store_true",
                        help="stage times (scenes: run times) as CPU time of the calling thread, one thread only "
                             "(robust to other processes on a busy machine; wall-clock by default)")
    parser.add_argument("--near-guard", type=float, default=None,
                        help="scenes: the reach of the matcher's too-near guard (0 = without the guard; default the preset's)")
    parser.add_argument("--cost", choices=("nssd", "zncc"), default=None,
                        help="the matcher's window cost (default: the preset's)")
    args = parser.parse_args()
    keep_freed_memory()          # as the mrstereo command does (for both chains of this process)
    if args.cpu:
        global CLOCK
        CLOCK = time.thread_time
    if args.scenes:
        scenes(args.repeats, near_guard=args.near_guard, cost=args.cost)
    else:
        sizes = [tuple(int(v) for v in s.lower().split("x")) for s in args.sizes.split(",")]
        whole_frame(sizes, args.frames, args.repeats, args.seed, odometry=args.odometry, cost=args.cost)


if __name__ == "__main__":
    main()
