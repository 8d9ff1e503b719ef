"""ROS bags read as streams: the temporary directory and the memory of reading and mapping a bag (docs/dataset.md).

    python benchmarks/bench_bag_stream.py [--euroc-frames 95] [--frames 100 2000] [--size 320 240] [--map]

1. A ROS 2 bag of ``--euroc-frames`` EuRoC pairs (752x480 mono8 and camera_info: the real frames of
   ``$MRSTEREO_DATA/euroc_asl_sample`` driven forth and back). Printed: the size of the dataset
   ``mrstereo export`` writes of it (what every command wrote to the temporary directory before bags
   were streams), then for ``mrstereo info BAG``, ``mrstereo live BAG -o OUT`` (the map of the bag,
   read as a stream) and ``mrstereo map BAG -o OUT``: the peak size of the temporary directory (TMPDIR
   pointed at an empty folder, its size polled every 10 ms), the image files written outside OUT and the
   command's peak resident memory.
2. Synthetic bags of ``--frames`` pairs (the corridor at ``--size``, with odometry, frames driven forth and
   back): the peak resident memory of a fresh process that reads every frame (BagSource), and with
   ``--map`` of ``mrstereo map BAG -o OUT`` (``--map-command live``: of ``mrstereo live BAG -o OUT``).
"""
from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from _bags import DT_NS, T0_NS, BagWriter  # noqa: E402

from mrstereo.io import read_image  # noqa: E402
from mrstereo.recordings import read_recording  # noqa: E402
from mrstereo.recordings.samples import data_root  # noqa: E402

IMAGE_SUFFIXES = (".png", ".pgm", ".ppm", ".jpg", ".pfm", ".tif", ".tiff")


def forth_and_back(n: int, count: int) -> list[int]:
    period = list(range(count)) + list(range(count - 2, 0, -1)) or [0]
    return [period[k % len(period)] for k in range(n)]


def write_bag(path: Path, manifest, n: int, *, odom: bool) -> Path:
    """``n`` pairs of the manifest's raw images (forth and back), camera_info and (``odom``) odometry."""
    topics = {"/cam/left/image_raw": "sensor_msgs/msg/Image", "/cam/right/image_raw": "sensor_msgs/msg/Image",
              "/cam/left/camera_info": "sensor_msgs/msg/CameraInfo",
              "/cam/right/camera_info": "sensor_msgs/msg/CameraInfo"}
    if odom:
        topics["/odom"] = "nav_msgs/msg/Odometry"
    frames = manifest.frames
    images = {}
    with BagWriter(path, False, topics) as bag:
        m = bag.msgs
        for k, i in enumerate(forth_and_back(n, len(frames))):
            t = T0_NS + k * DT_NS
            if i not in images:
                images[i] = tuple(read_image(p) for p in (frames[i].left, frames[i].right))
            for side, image in zip(("left", "right"), images[i]):
                bag.put(f"/cam/{side}/camera_info", m.camera_info(getattr(manifest.calibration, side), t, side), t)
                bag.put(f"/cam/{side}/image_raw", m.image(image, t, side), t)
            if odom:
                bag.put("/odom", m.planar_odometry(frames[i].pose, t), t)
    return path


def tree_bytes(folder: Path) -> int:
    total = 0
    for base, _, files in os.walk(folder):
        for name in files:
            try:
                total += os.path.getsize(os.path.join(base, name))
            except OSError:
                pass
    return total


def image_files(folder: Path, *, outside: Path | None = None) -> set[Path]:
    found = set()
    for base, _, files in os.walk(folder):
        for name in files:
            path = Path(base) / name
            if path.suffix.lower() in IMAGE_SUFFIXES and (outside is None or outside not in path.parents):
                found.add(path)
    return found


def measured(command: list[str], work: Path) -> dict:
    """Run ``command`` with TMPDIR an empty folder: peak tmp size [bytes], peak RSS [kB], new image files
    under ``work`` outside ``work/out``, wall time."""
    tmp = Path(tempfile.mkdtemp(prefix="tmpdir-", dir=work))
    before = image_files(work)
    peak = [0]
    done = threading.Event()

    def poll():
        while not done.is_set():
            peak[0] = max(peak[0], tree_bytes(tmp))
            time.sleep(0.01)

    poller = threading.Thread(target=poll, daemon=True)
    poller.start()
    env = dict(os.environ, TMPDIR=str(tmp))
    start = time.perf_counter()
    result = subprocess.run(["/usr/bin/time", "-f", "%M", *command], env=env, capture_output=True, text=True)
    wall = time.perf_counter() - start
    done.set()
    poller.join()
    peak[0] = max(peak[0], tree_bytes(tmp))
    if result.returncode != 0:
        raise SystemExit(f"{' '.join(command)} failed:\n{result.stderr[-2000:]}")
    rss_kb = int(result.stderr.strip().splitlines()[-1])
    written = image_files(work, outside=work / "out") - before - image_files(tmp)
    return {"tmp_peak": peak[0], "rss_kb": rss_kb, "outside": len(written), "wall": wall}


READ_ALL = ("import resource, sys; from mrstereo.recordings.bag import BagSource\n"
            "n = sum(1 for _ in BagSource(sys.argv[1]))\n"
            "print(n, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--euroc-frames", type=int, default=95)
    parser.add_argument("--frames", type=int, nargs="+", default=[100, 2000])
    parser.add_argument("--size", type=int, nargs=2, default=[320, 240], metavar=("W", "H"))
    parser.add_argument("--map", action="store_true", help="also map the synthetic bags")
    parser.add_argument("--map-command", choices=["map", "live"], default="map", help="what maps them")
    parser.add_argument("--skip-map-command", action="store_true", help="do not run mrstereo map on the EuRoC bag")
    parser.add_argument("--skip-euroc", action="store_true", help="only the synthetic bags")
    args = parser.parse_args()
    print(f"load: {os.getloadavg()[0]:.2f} {os.getloadavg()[1]:.2f} on {os.cpu_count()} cores")
    with tempfile.TemporaryDirectory(prefix="bench-bag-") as top:
        top = Path(top)
        if not args.skip_euroc:
            _euroc(top, args)
        w, h = args.size
        synthetic = read_recording(_corridor(top / "corridor", w, h))
        for n in args.frames:
            folder = top / f"synthetic{n}"
            folder.mkdir()
            bag = write_bag(folder / "bag", synthetic, n, odom=True)
            child = subprocess.run([sys.executable, "-c", READ_ALL, str(bag)], capture_output=True, text=True,
                                   check=True)
            count, rss = child.stdout.split()
            line = (f"synthetic bag of {n} pairs ({w}x{h}, {tree_bytes(bag) / 1e6:.0f} MB): read {count} frames, "
                    f"peak RSS {int(rss) / 1024:.0f} MB")
            if args.map:
                r = measured(["mrstereo", args.map_command, str(bag), "-o", str(folder / "out" / "m"), "--quiet"],
                             folder)
                line += (f"; mapped ({args.map_command}): peak RSS {r['rss_kb'] / 1024:.0f} MB, "
                         f"tmp dir peak {r['tmp_peak'] / 1e6:.3f}"
                         f" MB, image files outside the output {r['outside']}, {r['wall']:.0f} s")
            print(line, flush=True)
            shutil.rmtree(folder)


def _euroc(top: Path, args) -> None:
    euroc = read_recording(data_root() / "euroc_asl_sample")
    work = top / "euroc"
    work.mkdir()
    bag = write_bag(work / "euroc_bag", euroc, args.euroc_frames, odom=False)
    print(f"EuRoC ROS 2 bag: {args.euroc_frames} pairs of 752x480, {tree_bytes(bag) / 1e6:.1f} MB")
    from mrstereo.recordings.bag import export_bag

    export_bag(bag, top / "exported", progress=False)
    print(f"  its export (what every command wrote to the temporary directory before): "
          f"{tree_bytes(top / 'exported') / 1e6:.1f} MB")
    commands = [("info", ["mrstereo", "info", str(bag)]),
                ("live", ["mrstereo", "live", str(bag), "-o", str(work / "out" / "live")]),
                ("map", ["mrstereo", "map", str(bag), "-o", str(work / "out" / "map"), "--quiet"])]
    for name, command in commands:
        if name == "map" and args.skip_map_command:
            continue
        r = measured(command, work)
        print(f"  mrstereo {name:5s}: tmp dir peak {r['tmp_peak'] / 1e6:7.3f} MB, image files outside the output "
              f"{r['outside']}, peak RSS {r['rss_kb'] / 1024:.0f} MB, {r['wall']:.0f} s")


def _corridor(folder: Path, width: int, height: int) -> Path:
    from mrstereo.world.dataset import write_synthetic_dataset

    return write_synthetic_dataset(folder, seed=7, n_frames=40, width=width, height=height, supersample=1,
                                   progress=False)


if __name__ == "__main__":
    main()
