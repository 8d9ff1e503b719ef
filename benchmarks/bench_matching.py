"""Speed and accuracy of mrstereo's multi-range matcher vs OpenCV, measured in the same process.

Speed (default): 640x480 (Middlebury 2003 Teddy scaled up, or synthetic texture if the data
is absent), rig fx = 451 px, baseline 0.075 m, depths 0.5-15 m -> disparities 2.3-67.7 px;
a single-range StereoBM must search 80 disparities (multiple of 16). StereoBM and each
mrstereo variant run alternately; prints per variant the median time and the median of the
per-pair ratios mrstereo / StereoBM (robust to the load of a shared machine), with 1 and 2
threads (numba.set_num_threads, cv2.setNumThreads), and the minor page faults per frame.

Accuracy (``--accuracy``): bad-2 (%) dense (missing counts as bad) / among estimated pixels
on the public Middlebury/KITTI sample scenes (mrstereo.recordings.samples) for StereoBM, StereoSGBM (mrstereo.evaluation
baselines), mrstereo robust (default), mapping, paper, robust without gap filling and with
gap filling from the ends alone (ELAS-like), robust single range over the whole search, and
robust single range with the same work as the multi-range plan; then the robust variants on
the built-in corridor (plain walls and floor; 8 frames, 320x240, search from the calibration):
bad-2 among estimated pixels and density.

Near-limit sweep (``--near-sweep``): the same rig and pair, the default far bands
(1-2.5 m at decimation 2, 2.5-15 m at full resolution) and a near band from 0.5, 0.3, 0.2
or 0.15 m to 1 m at decimation 4, against the same matcher on one full-resolution range
over the same depths: where the paper's multi-range pays, and the work ratio's bound.

Each thread count also times one band search alone (80 disparities at full resolution, with the
pre-filter and the preparation of each cost) against StereoBM over the same 80 disparities:
ns per pixel x disparity.

    python benchmarks/bench_matching.py [--repeats 15] [--threads 1]
    python benchmarks/bench_matching.py --accuracy [--scale 0.5]
    python benchmarks/bench_matching.py --near-sweep [--repeats 15]
"""
from __future__ import annotations

import argparse
import os
import time
from pathlib import Path

import cv2
import numba
import numpy as np

from mrstereo.camera import Camera, StereoCamera
from mrstereo.matching import compute_disparity, make_plan, preset_config
from mrstereo._executor import keep_freed_memory
from mrstereo.recordings import samples as sample_data

# the public sample scenes (mrstereo.recordings.samples: $MRSTEREO_DATA or `mrstereo data fetch`)
SCENES = ["tsukuba", "venus", "teddy", "cones", "kitti2012-000070", "kitti2015-000000"]


def load_pair() -> tuple[np.ndarray, np.ndarray, str]:
    try:
        teddy = sample_data.fetch("teddy")
    except (OSError, ValueError) as exc:
        print(f"Teddy not available ({exc}); timing a synthetic texture instead")
        teddy = None
    if teddy is not None:
        left = cv2.imread(str(teddy / "im2.ppm"), cv2.IMREAD_GRAYSCALE)
        right = cv2.imread(str(teddy / "im6.ppm"), cv2.IMREAD_GRAYSCALE)
        return (cv2.resize(left, (640, 480), interpolation=cv2.INTER_LINEAR),
                cv2.resize(right, (640, 480), interpolation=cv2.INTER_LINEAR), "Teddy scaled to 640x480")
    rng = np.random.default_rng(0)
    img = cv2.GaussianBlur(rng.uniform(0, 255, (480, 720)).astype(np.float32), (0, 0), 1.2)
    img = cv2.normalize(img, None, 0, 255, cv2.NORM_MINMAX).astype(np.uint8)
    return img[:, 40:680], img[:, 20:660], "synthetic texture 640x480"


def paired(fn, base, repeats: int) -> tuple[float, float, float]:
    """Median time of ``fn``, of ``base``, and median of the per-pair ratios (ms, ms, x)."""
    fn()
    base()
    t_fn, t_base, ratios = [], [], []
    for _ in range(repeats):
        t0 = time.perf_counter()
        base()
        t1 = time.perf_counter()
        fn()
        t2 = time.perf_counter()
        t_base.append(t1 - t0)
        t_fn.append(t2 - t1)
        ratios.append((t2 - t1) / (t1 - t0))
    return 1000 * float(np.median(t_fn)), 1000 * float(np.median(t_base)), float(np.median(ratios))


def per_evaluation(left, right, bm, n_disp: int, repeats: int) -> None:
    """One band search ``[0, n_disp - 1]`` at full resolution (raw winners, each cost's
    pre-filter and preparation included) vs StereoBM over the same disparities: ns per pixel
    and disparity."""
    from mrstereo.matching.cost import match_prepared, prepare_gray

    h, w = left.shape
    evaluations = h * w * n_disp

    def search():
        pair = [prepare_gray(im.astype(np.float32), kind="xsobel", cap=7, window=9, cost="zncc")
                for im in (left, right)]
        match_prepared(*pair, d_lo=0, d_hi=n_disp - 1, rows=(0, h), cols=(0, w), right_check=True)

    ms, base_ms, ratio = paired(search, lambda: bm.compute(left, right), repeats)
    print(f"  band search alone, zncc: {1e6 * ms / evaluations:.3f} ns per pixel x disparity, StereoBM "
          f"{1e6 * base_ms / evaluations:.3f}: ratio {ratio:.2f}")


def speed(repeats: int, thread_counts=(1, 2)) -> None:
    left, right, what = load_pair()
    rig = StereoCamera.ideal(Camera(fx=451.0, fy=451.0, cx=320.0, cy=240.0, width=640, height=480), 0.075)
    bm = cv2.StereoBM.create(numDisparities=80, blockSize=9)
    robust, paper = preset_config("robust"), preset_config("paper")

    def run(config):
        return lambda: compute_disparity(left, right, calibration=rig, config=config)

    runs = {
        "mrstereo robust multi-range": run(robust),
        "robust without gap filling": run(robust.replace(postfilter={"gap_fill_px": 0})),
        "mrstereo paper multi-range": run(paper),
        "mrstereo robust single-range": run(robust.replace(search={"multi_range": False})),
        "mrstereo paper single-range": run(paper.replace(search={"multi_range": False})),
    }
    plan = compute_disparity(left, right, calibration=rig).plan
    print(f"pair: {what}\n{plan.describe()}\nload average: {os.getloadavg()}\n")
    for threads in thread_counts:
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        cv2.setNumThreads(threads)
        per_evaluation(left, right, bm, 80, repeats)
        for name, fn in runs.items():
            ms, base_ms, ratio = paired(fn, lambda: bm.compute(left, right), repeats)
            print(f"threads={threads}  {name:30s} median {ms:6.1f} ms  StereoBM 80 disp 9x9 {base_ms:5.1f} ms"
                  f"  ratio {ratio:4.2f}")
        for name in ("robust", "paper"):     # the same matcher over the same depths, alternating
            multi_ms, single_ms, ratio = paired(runs[f"mrstereo {name} multi-range"],
                                                runs[f"mrstereo {name} single-range"], repeats)
            print(f"threads={threads}  {name} multi-range {multi_ms:.1f} ms vs single range {single_ms:.1f} ms: "
                  f"{1 / ratio:.2f}x faster (work {plan.work / plan.single_range_work:.2f}x)")
        print()
    faults = page_faults_per_call(runs["mrstereo robust multi-range"])
    if faults is not None:
        print(f"minor page faults per robust frame: {faults:.0f} (StereoBM: "
              f"{page_faults_per_call(lambda: bm.compute(left, right)):.0f})")
    print(f"load average after: {os.getloadavg()}")


def near_sweep(repeats: int) -> None:
    left, right, what = load_pair()
    rig = StereoCamera.ideal(Camera(fx=451.0, fy=451.0, cx=320.0, cy=240.0, width=640, height=480), 0.075)
    numba.set_num_threads(1)
    cv2.setNumThreads(1)
    print(f"pair: {what}; single thread; multi-range bands (near-1, 1-2.5, 2.5-15 m) vs one range near-15 m\n")
    print("| near limit | max disparity | work ratio | bound 1/work | preset | multi-range | single range | faster |")
    print("|---|---|---|---|---|---|---|---|")
    for near in (0.5, 0.3, 0.2, 0.15):
        edges = (near, 1.0, 2.5, 15.0)
        plan = make_plan((640, 480), calibration=rig, depth_bands_m=edges, config=preset_config("robust"))
        work = plan.work / plan.single_range_work
        for name in ("robust", "paper"):
            config = preset_config(name)
            multi_ms, single_ms, ratio = paired(
                lambda: compute_disparity(left, right, calibration=rig, depth_bands_m=edges, config=config),
                lambda: compute_disparity(left, right, calibration=rig, depth_bands_m=(near, 15.0),
                                          config=config.replace(search={"multi_range": False})), repeats)
            print(f"| {near:g} m | {plan.levels[-1].band_px[1]:.0f} px | {work:.2f} | {1 / work:.1f}x | {name} | "
                  f"{multi_ms:.1f} ms | {single_ms:.1f} ms | {1 / ratio:.2f}x |", flush=True)


def page_faults_per_call(fn, calls: int = 10) -> float | None:
    """Minor page faults per call of ``fn`` (fresh pages the allocator maps; each costs
    about 1-2 us). None where the ``resource`` module is missing (Windows)."""
    try:
        import resource
    except ImportError:
        return None
    fn()
    before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
    for _ in range(calls):
        fn()
    return (resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before) / calls


def rescaled(scene, factor: float):
    """The scene resized by ``factor`` (area filter; GT nearest, disparities times ``factor``)."""
    import dataclasses

    import cv2

    h, w = scene.gt_disparity_px.shape
    size = (int(round(w * factor)), int(round(h * factor)))

    def resize(image, interpolation=cv2.INTER_AREA):
        return cv2.resize(image, size, interpolation=interpolation)

    mask = scene.nonocc_mask
    if mask is not None:
        mask = resize(mask.astype(np.uint8), cv2.INTER_NEAREST) > 0
    return dataclasses.replace(scene, left=resize(scene.left), right=resize(scene.right), nonocc_mask=mask,
                               gt_disparity_px=resize(scene.gt_disparity_px, cv2.INTER_NEAREST) * factor,
                               max_disparity_px=int(np.ceil(scene.max_disparity_px * factor)))


def accuracy(scale: float = 1.0) -> None:
    from mrstereo.evaluation import disparity_metrics, load_scene, stereo_bm, stereo_sgbm

    robust = preset_config("robust")

    def mr(config=None, preset="robust"):
        return lambda s: compute_disparity(s.left, s.right, max_disparity_px=s.max_disparity_px, config=config,
                                           preset=preset).disparity_px

    def equal_work(s):
        h, w = s.gt_disparity_px.shape
        work = compute_disparity(s.left[:32], s.right[:32], max_disparity_px=s.max_disparity_px).plan.work / 32
        d_eq = max(1, int(work / w) - 1)
        return compute_disparity(s.left, s.right, disparity_bands_px=[(0, d_eq)],
                                 config=robust.replace(search={"multi_range": False})).disparity_px

    methods = {
        "OpenCV StereoBM": lambda s: stereo_bm(s.left, s.right, max_disparity_px=s.max_disparity_px),
        "OpenCV StereoSGBM": lambda s: stereo_sgbm(s.left, s.right, max_disparity_px=s.max_disparity_px),
        "mrstereo robust (default)": mr(),
        "mrstereo mapping (the mapping chain's)": mr(preset="mapping"),
        "mrstereo paper": mr(preset="paper"),
        "robust without the near guard": mr(robust.replace(near_guard=None)),
        "robust without gap filling": mr(robust.replace(postfilter={"gap_fill_px": 0})),
        "robust, gap filling from the ends alone (support 1)": mr(robust.replace(postfilter={"gap_fill_support_px": 1})),
        "robust, single range": mr(robust.replace(search={"multi_range": False})),
        "robust, single range, equal work": equal_work,
    }
    scenes = [load_scene(sample_data.fetch(name)) for name in SCENES]
    if scale != 1.0:
        scenes = [rescaled(s, scale) for s in scenes]
    print(f"bad-2 % dense / among estimated; mean over the first five scenes (KITTI 2015 reported beside); "
          f"scenes scaled by {scale:g}: " + ", ".join(f"{s.name} D={s.max_disparity_px}" for s in scenes) + "\n")
    print("| method | mean dense | mean est | " + " | ".join(s.name for s in scenes) + " |")
    print("|---" * (3 + len(scenes)) + "|")
    for name, run in methods.items():
        cells = []
        for s in scenes:
            m = disparity_metrics(run(s), s.gt_disparity_px, nonocc_mask=s.nonocc_mask)
            cells.append((m.dense.bad_2_pct, m.estimated.bad_2_pct))
        first = np.array(cells[:5])
        print(f"| {name} | {first[:, 0].mean():.1f} | {first[:, 1].mean():.1f} | "
              + " | ".join(f"{a:.1f}/{b:.1f}" for a, b in cells) + " |", flush=True)
    corridor({"robust (default)": robust, "mapping": preset_config("mapping"),
              "robust without gap filling": robust.replace(postfilter={"gap_fill_px": 0}),
              "robust, gap filling from the ends alone": robust.replace(postfilter={"gap_fill_support_px": 1})})


def corridor(configs: dict) -> None:
    """bad-2 among estimated pixels and density on 8 frames of the built-in corridor (seed 0)."""
    import tempfile

    from mrstereo.io import read_disparity, read_image
    from mrstereo.recordings.manifest import read_manifest
    from mrstereo.world.dataset import write_synthetic_dataset

    with tempfile.TemporaryDirectory() as tmp:
        manifest = read_manifest(write_synthetic_dataset(Path(tmp) / "corridor", seed=0, n_frames=8, progress=False))
        frames = [(read_image(f.left_rect, gray=True), read_image(f.right_rect, gray=True),
                   read_disparity(f.gt_disparity)) for f in manifest.frames]
    print("\ncorridor (seed 0, 8 frames, 320x240, `calibration=`): bad-2 % among estimated / density %")
    for name, config in configs.items():
        wrong = estimated = known = 0
        for left, right, gt in frames:
            d = compute_disparity(left, right, calibration=manifest.calibration, config=config).disparity_px
            ok = np.isfinite(gt) & (gt > 0)
            est = ok & np.isfinite(d)
            known, estimated = known + ok.sum(), estimated + est.sum()
            wrong += (np.abs(d - gt)[est] > 2.0).sum()
        print(f"  {name}: {100 * wrong / estimated:.2f} / {100 * estimated / known:.1f}", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=15)
    parser.add_argument("--threads", default="1,2", help="speed: thread counts, e.g. 1")
    parser.add_argument("--accuracy", action="store_true", help="bad-2 table on the sample scenes")
    parser.add_argument("--scale", type=float, default=1.0,
                        help="with --accuracy: resize the scenes (e.g. 0.5: other search ranges)")
    parser.add_argument("--near-sweep", action="store_true",
                        help="multi-range vs one range as the near limit shrinks")
    args = parser.parse_args()
    keep_freed_memory()          # as the mrstereo command does (for mrstereo and OpenCV alike)
    if args.accuracy:
        accuracy(args.scale)
    elif args.near_sweep:
        near_sweep(args.repeats)
    else:
        speed(args.repeats, tuple(int(t) for t in args.threads.split(",")))


if __name__ == "__main__":
    main()
