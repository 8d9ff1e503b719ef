"""The thresholds of mrstereo.rejection.streams measured: every real pair of the sample data and synthetic
corridors, as recorded, with the left stream duplicated and with the streams swapped.

Prints one row per pair (identical share, share of negative disparities, median disparity, verdict) and the
false alarms (a recorded pair flagged) and misses (a duplicated or swapped pair not flagged) per source:

    MRSTEREO_DATA=/path/to/data python benchmarks/bench_sanity.py [--synthetic N]
"""
from __future__ import annotations

import argparse
import glob
import os
import sys
import tempfile
from pathlib import Path

from mrstereo.camera import read_stereo
from mrstereo.io import matching_image, read_image
from mrstereo.rejection.streams import check_pair
from mrstereo.recordings.samples import data_root


def _pairs(root: Path):
    """(source, left, right, stereo or None): rectified pairs have no calibration here."""
    rectified = [("middlebury tsukuba", "middlebury2001/tsukuba/scene1.row3.col3.ppm",
                  "middlebury2001/tsukuba/scene1.row3.col4.ppm"),
                 ("middlebury venus", "middlebury2001/venus/im2.ppm", "middlebury2001/venus/im6.ppm"),
                 ("middlebury teddy", "middlebury2003/teddy/im2.ppm", "middlebury2003/teddy/im6.ppm"),
                 ("middlebury cones", "middlebury2003/cones/im2.png", "middlebury2003/cones/im6.png"),
                 ("kitti 2012", "kitti2012/000070/image_0/000070_10.png", "kitti2012/000070/image_1/000070_10.png"),
                 ("kitti 2015", "kitti2015/000000/image_2/000000_10.png", "kitti2015/000000/image_3/000000_10.png")]
    for source, a, b in rectified:
        if (root / a).is_file():
            yield source, root / a, root / b, None
    for a in sorted(glob.glob(str(root / "kitti_odometry_06/sequences/06/image_0/*.png"))):
        yield "kitti odometry 06", Path(a), Path(a.replace("image_0", "image_1")), None
    euroc = root / "euroc_asl_sample/mav0"
    if euroc.is_dir():
        stereo = read_stereo(f"{euroc}/cam0/sensor.yaml,{euroc}/cam1/sensor.yaml")
        for a in sorted((euroc / "cam0/data").glob("*.png")):
            yield "euroc", a, euroc / "cam1/data" / a.name, stereo
    loris = root / "openloris_sample"
    if loris.is_dir():
        stereo = read_stereo(loris / "sensors.yaml")
        for a in sorted((loris / "fisheye1").glob("*.png")):
            yield "openloris", a, loris / "fisheye2" / a.name, stereo


def _synthetic(n: int, folder: Path):
    from mrstereo.recordings.manifest import read_manifest
    from mrstereo.world.dataset import write_synthetic_dataset

    for seed in range(n):
        ds = read_manifest(write_synthetic_dataset(folder / f"s{seed}", seed=seed, n_frames=3, width=320,
                                                   height=240, randomize=seed % 2 == 1, progress=False))
        for record in ds.frames:
            yield f"synthetic{' randomized' if seed % 2 else ''}", record.left, record.right, ds.calibration


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--synthetic", type=int, default=4, help="synthetic worlds (every second one randomized)")
    args = parser.parse_args()
    root = data_root() if not os.environ.get("MRSTEREO_DATA") else Path(os.environ["MRSTEREO_DATA"])
    counts: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        pairs = list(_pairs(root)) + list(_synthetic(args.synthetic, Path(tmp)))
        print(f"{'source':24s} {'case':10s} {'equal':>6s} {'other':>6s} {'median':>7s}  verdict")
        for source, a, b, stereo in pairs:
            left, right = matching_image(read_image(a)), matching_image(read_image(b))
            for case, (l, r) in (("recorded", (left, right)), ("duplicated", (left, left)),
                                 ("swapped", (right, left))):
                c = check_pair(l, r, stereo, rectified=stereo is None)
                verdict = "identical" if c.identical else "swapped" if c.swapped else "ok"
                wrong = (verdict != "ok") if case == "recorded" else (verdict != {"duplicated": "identical",
                                                                                  "swapped": "swapped"}[case])
                n, bad = counts.get((source, case), (0, 0))
                counts[(source, case)] = (n + 1, bad + wrong)
                print(f"{source:24s} {case:10s} {c.identical_share:6.3f} {c.exchanged_share:6.2f} "
                      f"{c.median_disparity_px:7.1f}  {verdict}{'  <-- WRONG' if wrong else ''}")
    print("\nper source: pairs, false alarms (recorded) / misses (duplicated, swapped)")
    for (source, case), (n, bad) in counts.items():
        print(f"{source:24s} {case:10s} {n:3d} pairs, {bad} wrong")
    return 0


if __name__ == "__main__":
    sys.exit(main())
