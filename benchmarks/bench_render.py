"""Render time of one synthetic stereo frame with all its ground truth, on one core.

Target: a 320x240 frame (raw + rectified pairs, 2x2 supersampling, GT disparity,
depth and labels) in under 0.5 s with NUMBA_NUM_THREADS=1.

    NUMBA_NUM_THREADS=1 python benchmarks/bench_render.py [--repeats 7]

Prints the median of the runs after a warm-up (JIT compilation, ray tables);
for scale it also times OpenCV's rectification (cv2.remap) of the same pair.
"""
from __future__ import annotations

import argparse
import os

os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import time  # noqa: E402

import numpy as np  # noqa: E402


def _median_s(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=7)
    args = parser.parse_args()

    import cv2
    import numba

    from mrstereo.world import default_scene, default_stereo, render_stereo_frame

    cv2.setNumThreads(1)
    print(f"numba threads: {numba.get_num_threads()}, OpenCV threads: {cv2.getNumThreads()}")
    scene = default_scene(0)
    for width, height, budget in ((320, 240, 0.5), (640, 480, None)):
        stereo = default_stereo(width, height)
        frame = render_stereo_frame(scene, stereo, pose=(1.0, 0.0, 0.0))          # warm-up
        seeds = iter(range(1, 10**6))
        render = _median_s(lambda: render_stereo_frame(scene, stereo, pose=(1.0, 0.0, 0.0), seed=next(seeds)),
                           args.repeats)
        stereo.rectify(frame.raw_left, frame.raw_right)
        rectify = _median_s(lambda: stereo.rectify(frame.raw_left, frame.raw_right), args.repeats)
        verdict = "" if budget is None else (" (OK, budget 0.5 s)" if render < budget else " (OVER the 0.5 s budget)")
        print(f"{width}x{height}: render frame + GT median {render * 1e3:.1f} ms{verdict}; "
              f"cv2.remap rectification of the pair {rectify * 1e3:.2f} ms "
              f"(render / rectify = {render / rectify:.0f}x)")


if __name__ == "__main__":
    main()
