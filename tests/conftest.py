"""Shared test fixtures: synthetic datasets, the public sample scenes and how tests skip without them.

* ``synthetic_dataset(**params)``: a rendered corridor dataset, made once per session for each set of
  parameters and shared by every test that asks for it.
* Tests that need a real scene either take the ``sample_data`` fixture (``sample_data("tsukuba")``
  returns its folder), or ``middlebury_scene`` (a Middlebury pair with its ground truth), or carry
  ``@pytest.mark.sample_data("tsukuba", ...)`` and build paths with
  :func:`mrstereo.recordings.samples.local_path`. Without the files they skip with a reason that names the
  environment variable and the fetch command; nothing is downloaded during a test run. CI
  (``.ci/run``) points ``MRSTEREO_DATA`` at a local copy.
* ``@pytest.mark.extra("scale")`` (or ``"viz"``): the test needs an optional extra of pyproject.toml and
  skips without it, with the install command (CI installs them all: README, Quick start).
* ``slow`` (pyproject.toml) marks the tests that take many seconds: ``python -m pytest -m "not slow"``
  skips them.
* The suite runs on parallel workers (pytest-xdist, ``-n auto --dist worksteal`` in pyproject.toml: a worker
  that runs out of tests takes some of the other's; ``-n 0`` runs it in one process), the ``slow`` tests first. The workers share the synthetic datasets (each made once, under a file
  lock, in the run's temporary root) and numba's compiled kernels: on a cold cache each kernel is compiled by
  one worker, the other waits for it and loads it from the cache (a kernel's cache index and code are saved
  whole for the other worker). Before their first test the two workers compile the matcher's slow kernels
  in two shares at once (``_compile_matcher_share``), not one after the other.

Helpers for writing ROS bags live in ``_bags.py``.
"""
from __future__ import annotations

import contextlib
import fcntl
import hashlib
import os

import cv2
import numpy as np
import pytest

from mrstereo.recordings import samples as data


def skip_reason(name: str) -> str | None:
    """Why the scene ``name`` cannot be used (None when all its files are present)."""
    missing = data.missing_files(name)
    if not missing:
        return None
    return (f"sample data {name!r} not found ({missing[0]} is missing): set {data.ENV_VAR} to a local copy "
            f"or run `mrstereo data fetch {name}`")


# the optional extras of pyproject.toml and the modules each installs
EXTRAS = {"scale": ("dask", "distributed"), "viz": ("rerun", "foxglove")}


def extra_missing(name: str) -> str | None:
    """Why the tests of the extra ``name`` cannot run (None when its packages are installed)."""
    import importlib.util

    missing = [m for m in EXTRAS[name] if importlib.util.find_spec(m) is None]
    return f"needs the {name} extra ({', '.join(missing)} not installed): pip install -e \".[{name}]\"" \
        if missing else None


def pytest_runtest_setup(item):
    for marker in item.iter_markers("sample_data"):
        for name in marker.args:
            reason = skip_reason(name)
            if reason:
                pytest.skip(reason)
    for marker in item.iter_markers("extra"):
        for name in marker.args:
            reason = extra_missing(name)
            if reason:
                pytest.skip(reason)


# Middlebury scenes: sample data name, left, right, ground truth, ground-truth divisor, search range
MIDDLEBURY = {
    "tsukuba": ("tsukuba", "scene1.row3.col3.ppm", "scene1.row3.col4.ppm", "truedisp.row3.col3.pgm", 16.0, 16),
    "teddy": ("teddy", "im2.ppm", "im6.ppm", "disp2.pgm", 4.0, 64),
}


@pytest.fixture
def middlebury_scene(sample_data):
    """``middlebury_scene(name) -> (left, right, truth, max_disparity_px)``: a gray pair of :data:`MIDDLEBURY`
    and its true disparity, NaN where unknown or occluded (non-occluded mask of the scene where it has one)."""
    def get(name: str):
        sample, left, right, gt, divisor, max_d = MIDDLEBURY[name]
        folder = sample_data(sample)
        read = lambda p: cv2.imread(str(folder / p), cv2.IMREAD_GRAYSCALE)     # noqa: E731
        truth = read(gt).astype(np.float32) / divisor        # 0 = unknown
        truth[truth == 0] = np.nan
        if (folder / "nonocc.png").is_file():
            truth[read("nonocc.png") != 255] = np.nan
        return read(left), read(right), truth, max_d
    return get


@pytest.fixture
def sample_data():
    """``sample_data(name) -> Path`` of a complete local scene; skips the test otherwise."""
    def get(name: str):
        reason = skip_reason(name)
        if reason:
            pytest.skip(reason)
        return data.local_path(name)
    return get


def pytest_collection_modifyitems(config, items):
    """The ``slow`` tests run first, the others in their order: the parallel workers start the longest tests
    early and end together, instead of one running a long test alone at the end of the run."""
    items.sort(key=lambda item: item.get_closest_marker("slow") is None)


def pytest_configure(config):
    _one_blas_thread()
    if hasattr(config, "workerinput"):           # an xdist worker: each kernel compiled by one worker only
        _lock_numba_cache_files(config.workerinput["testrunuid"])
        _compile_each_kernel_once()
        _compile_matcher_share(int(config.workerinput["workerid"].removeprefix("gw")),
                               int(config.workerinput["workercount"]))


def _matcher_parts():
    """The matcher's slow kernels (tens of seconds each on a cold cache) in two shares of about equal
    compile time, each a list of calls on a tiny pair: the same signatures as the tests' calls."""
    from mrstereo.matching.cost import match_checked, match_prepared, prepare, prepare_gray, refine_candidates
    from mrstereo.matching.warmup import warm_pair

    images = [image.astype(np.float32) for image in warm_pair()]
    h, w = images[0].shape
    span = dict(rows=(0, h), cols=(0, w))
    checks = dict(lr_max_diff_px=1.0, uniqueness_ratio=0.1, max_cost=0.6, subpixel=True)
    coarse = np.full((h, w), 6.0, np.float32)
    dense, sparse = np.ones((h, w), bool), np.zeros((h, w), bool)
    sparse[10, 10:12] = True

    def pair(dtype=None):
        if dtype is None:                       # the default pre-filter: exact float32 sums
            return [prepare_gray(image, kind="xsobel", cap=7, window=9, cost="zncc") for image in images]
        return [prepare(image + 0.5, window=9, cost="zncc", dtype=dtype) for image in images]

    return ([lambda: match_checked(*pair(), d_lo=0, d_hi=8, **span, **checks),                  # band_checked
             lambda: refine_candidates(*pair(), coarse, dense, half_px=3, max_cost=0.6),        # refine_strips
             lambda: refine_candidates(*pair(), coarse, sparse, half_px=3, max_cost=0.6),       # refine_pixels
             lambda: match_prepared(*pair(np.float64), d_lo=0, d_hi=8, **span, right_check=False)],  # float images
            [lambda: match_prepared(*pair(), d_lo=0, d_hi=8, **span, right_check=True),         # band_winners
             lambda: refine_candidates(*pair(), coarse, dense, half_px=3, max_cost=0.6,         # refine_boxes
                                       boxes=[(0, h, 0, w)]),
             # band_checked's float64 twin last: a kernel's signatures compile one at a time (one lock)
             lambda: match_checked(*pair(np.float64), d_lo=0, d_hi=8, **span, **checks)])


def _compile_matcher_share(worker: int, workers: int) -> None:
    """Before its first test, each of the first two workers compiles (or loads) one share of the matcher's
    slow kernels (:func:`_matcher_parts`), so that both compile at once.

    Nearly every test runs the matcher: on a cold cache, without this, the first worker to need a kernel
    compiles it while the other waits on that kernel's lock (:func:`_compile_each_kernel_once`), kernel
    after kernel, minutes in all. On a warm cache each share only loads (a second).
    """
    if worker < 2 and workers > 1:
        for part in _matcher_parts()[worker]:
            part()


def _one_blas_thread() -> None:
    """BLAS (OpenBLAS under numpy and scipy) on one thread, in this process and the commands it starts: the
    parallel workers are the parallelism. Two workers with two BLAS threads each on two cores spend most of a
    large solve in OpenBLAS's busy waits (the 54-view calibration's LSMR: 13 s of CPU, 4 s on one thread)."""
    from threadpoolctl import threadpool_limits

    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    threadpool_limits(limits=1, user_api="blas")


def _lock_numba_cache_files(run_id: str) -> None:
    """Hold a lock file shared by the run's workers while numba reads or writes a kernel's cache files.

    numba's cache index (one per function) is read, extended and rewritten, then the code file written,
    without a lock between processes: two workers saving two signatures of one kernel at once can pair an
    index entry with the other's code. The lock makes each save (index and code) whole for the others;
    the compiling itself stays parallel.
    """
    from numba.core.caching import IndexDataCacheFile

    path = os.path.join(os.environ.get("TMPDIR", "/tmp"), f"mrstereo-tests-{run_id}.numba.lock")
    fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o600)

    def locked(method):
        def call(self, *args):          # under numba's compiler lock: one thread of this process at a time
            fcntl.flock(fd, fcntl.LOCK_EX)
            try:
                return method(self, *args)
            finally:
                fcntl.flock(fd, fcntl.LOCK_UN)
        return call

    IndexDataCacheFile.save = locked(IndexDataCacheFile.save)
    IndexDataCacheFile.load = locked(IndexDataCacheFile.load)


def _compile_each_kernel_once() -> None:
    """A worker compiles a cached kernel only while it holds that kernel's lock file (``<index>.nbi.lock`` in
    numba's cache folder, beside the kernel's cache index: one file per kernel, kept from run to run).

    On a cold cache both workers soon need the same kernels (the matcher's, the renderer's): without the lock
    each compiles every one of them itself, twice the compile time of the run. With it the second worker
    waits for the first one's compile and then loads the kernel from numba's cache (``Dispatcher.compile``
    looks in the cache before it compiles). A kernel's compile takes the locks of the kernels it calls while
    it holds its own; kernels do not call each other in a cycle, so two workers never wait for each other.
    """
    from numba.core.compiler_lock import global_compiler_lock
    from numba.core.dispatcher import Dispatcher

    fds: dict[str, int] = {}
    held: set[str] = set()
    compile_ = Dispatcher.compile

    def compile_once(self, sig):
        cache_file = getattr(self._cache, "_cache_file", None)          # None: a kernel numba does not cache
        if cache_file is None:
            return compile_(self, sig)
        name = os.path.join(cache_file._cache_path, cache_file._index_name + ".lock")     # beside the kernel's index
        with global_compiler_lock:                                       # one thread of this process at a time
            if name in held:                                             # a kernel that calls itself
                return compile_(self, sig)
            if name not in fds:
                fds[name] = os.open(name, os.O_RDWR | os.O_CREAT, 0o600)
            fcntl.flock(fds[name], fcntl.LOCK_EX)
            held.add(name)
            try:
                return compile_(self, sig)
            finally:
                held.discard(name)
                fcntl.flock(fds[name], fcntl.LOCK_UN)

    Dispatcher.compile = compile_once


@contextlib.contextmanager
def _file_lock(path):
    with open(path, "a") as f:
        fcntl.flock(f, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(f, fcntl.LOCK_UN)


@pytest.fixture(scope="session")
def shared_root(tmp_path_factory):
    """A folder every worker of this run sees (the run's temporary root under xdist), for data made once."""
    base = tmp_path_factory.getbasetemp()
    root = (base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "shared"
    root.mkdir(exist_ok=True)
    return root


@pytest.fixture(scope="session")
def shared_data(shared_root):
    """``shared_data(name, make) -> Path``: ``make(folder)`` run once per test run (all workers) for ``name``
    under a file lock; ``make`` writes the new folder it is given (and returns nothing). Read it, never change it."""
    def get(name: str, make):
        folder = shared_root / name
        with _file_lock(shared_root / f"{name}.lock"):
            if not folder.exists():
                staging = shared_root / f".{name}.{os.getpid()}"
                staging.mkdir()
                make(staging)
                staging.rename(folder)
        return folder
    return get


@pytest.fixture(scope="session")
def synthetic_dataset(shared_data):
    """``synthetic_dataset(**params) -> Path``: a dataset of :func:`mrstereo.world.write_synthetic_dataset`,
    rendered once per test run (shared by the parallel workers) for each set of ``params`` (its folder is
    ``corridor<seed>``).

    Every test that asks for the same parameters gets the same folder: read it, never change it (copy it
    first). At the end of the session each dataset is checked to be unchanged.
    """
    from mrstereo.world.dataset import write_synthetic_dataset

    made: dict[tuple, tuple] = {}

    def make(**params):
        key = tuple(sorted(params.items()))
        if key not in made:
            name = f"synthetic-{hashlib.sha1(repr(key).encode()).hexdigest()[:12]}"
            corridor = f"corridor{params.get('seed', 0)}"
            folder = shared_data(name, lambda new: write_synthetic_dataset(new / corridor, progress=False, **params))
            made[key] = (folder / corridor, _digest(folder / corridor))
        return made[key][0]

    yield make
    changed = [str(path) for path, digest in made.values() if _digest(path) != digest]
    assert not changed, f"a test changed the shared synthetic datasets {changed}; copy a dataset before changing it"


def _digest(folder) -> dict[str, tuple[int, int]]:
    """Size and modification time of every file under ``folder``: what a test that writes into it changes."""
    return {str(p.relative_to(folder)): (p.stat().st_size, p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def kitti_two_frames(tmp_path):
    """A KITTI odometry folder ``tmp_path/kitti`` with the first two frames of the sample's sequence 06, its
    calib.txt, times.txt and poses (to change at will); skips without the sample."""
    import shutil

    source = data.data_root() / "kitti_odometry_06"
    if not (source / "poses" / "06.txt").is_file():
        pytest.skip(f"KITTI odometry sample not found under {source} (set {data.ENV_VAR})")
    root = tmp_path / "kitti"
    seq = root / "sequences" / "06"
    for sub in ("image_0", "image_1"):
        (seq / sub).mkdir(parents=True)
        for name in ("000000.png", "000001.png"):
            shutil.copy(source / "sequences" / "06" / sub / name, seq / sub / name)
    for name in ("calib.txt", "times.txt"):
        shutil.copy(source / "sequences" / "06" / name, seq / name)
    (root / "poses").mkdir()
    shutil.copy(source / "poses" / "06.txt", root / "poses" / "06.txt")
    return root
