"""Accuracy and speed of mrstereo against OpenCV StereoBM / StereoSGBM on the shared real scenes.

Usage: python benchmarks/bench_accuracy.py [--repeats 3] [--methods m1,m2] [DIR ...]

Prints the markdown report of the first run, then per method the median (over repeats) of the
summed time over all scenes and its ratio to StereoBM and StereoSGBM measured in the same run.
Timing on a shared 2-core machine is noisy: run it twice and compare.
"""
from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from mrstereo.evaluation.report import METHODS, evaluate_scenes

DATA = Path(__file__).resolve().parents[2] / "shared" / "data"
DEFAULT_SCENES = ["middlebury2001/tsukuba", "middlebury2001/venus", "middlebury2003/teddy",
                  "middlebury2003/cones", "kitti2012/000070", "kitti2015/000000"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dirs", nargs="*", type=Path)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--methods", default=",".join(METHODS))
    args = parser.parse_args()
    dirs = args.dirs or [DATA / s for s in DEFAULT_SCENES]
    methods = tuple(m for m in args.methods.split(",") if m)
    totals = {m: [] for m in methods}
    first = None
    for _ in range(max(1, args.repeats)):
        report = evaluate_scenes(dirs, methods=methods, progress=False)
        first = first or report
        for m in methods:
            totals[m].append(sum(r.seconds for r in report.rows if r.method == m))
    print(first.to_markdown())
    medians = {m: statistics.median(v) for m, v in totals.items()}
    print(f"## Time over {len(dirs)} scenes (median of {args.repeats} runs)\n")
    print("| method | seconds | x StereoBM | x StereoSGBM |\n|---|---|---|---|")
    for m, sec in medians.items():
        ratio = {b: (f"{sec / medians[b]:.2f}" if b in medians else "-") for b in ("StereoBM", "StereoSGBM")}
        print(f"| {m} | {sec:.3f} | {ratio['StereoBM']} | {ratio['StereoSGBM']} |")


if __name__ == "__main__":
    main()
