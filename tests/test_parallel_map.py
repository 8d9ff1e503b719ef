"""mrstereo._executor.map_ordered on real dask.distributed clusters (loopback), and build_map on workers:
input order, failures named or returned, one thread per worker, the same map bit for bit."""
from __future__ import annotations

import json
import time
from functools import partial

import numpy as np
import pytest

from mrstereo._executor import ItemError, ItemFailure, map_ordered
from mrstereo.pipeline.run import build_map
from mrstereo.recordings.manifest import read_manifest


def _slow_square(x: int, *, n: int) -> int:
    time.sleep(0.01 * max(n - x, 0))          # later items finish first
    if x == 3:
        raise ValueError("three is not allowed")
    return x * x


def _threads(_):
    import os

    import cv2
    import numba
    return (numba.get_num_threads(), cv2.getNumThreads(), os.environ.get("NUMBA_NUM_THREADS"), os.getpid(),
            os.environ.get("MALLOC_TRIM_THRESHOLD_"))


@pytest.fixture(scope="module")
def threaded_cluster():
    """A real scheduler + 2 thread workers in this process (fast to start)."""
    from conftest import extra_missing

    if extra_missing("scale"):
        pytest.skip(extra_missing("scale"))
    import distributed

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1",
                                  dashboard_address=":0") as cluster, distributed.Client(cluster) as client:
        yield cluster, client


@pytest.fixture(scope="module")
def dataset(synthetic_dataset):
    return read_manifest(synthetic_dataset(seed=1, n_frames=4, width=160, height=120, supersample=1))


def test_in_process_keeps_order_and_reports_failures():
    f = partial(_slow_square, n=0)
    assert map_ordered(f, [0, 1, 2], progress=False) == [0, 1, 4]
    out = map_ordered(f, range(5), progress=False, return_exceptions=True, label=lambda x: f"number {x}")
    assert out[:3] == [0, 1, 4] and out[4] == 16
    assert isinstance(out[3], ItemFailure) and out[3].index == 3 and out[3].item == "number 3"
    assert out[3].error == "ValueError: three is not allowed" and "three is not allowed" in out[3].traceback
    with pytest.raises(ItemError, match=r"item 3 \(number 3\) failed: ValueError: three is not allowed") as info:
        map_ordered(f, range(5), progress=False, label=lambda x: f"number {x}")
    assert isinstance(info.value.__cause__, ValueError)
    assert map_ordered(f, [], progress=False) == []


def test_bad_arguments():
    with pytest.raises(ValueError, match="workers must be"):
        map_ordered(abs, [1], workers=0)
    with pytest.raises(ValueError, match="not both"):
        map_ordered(abs, [1], workers=2, scheduler="tcp://127.0.0.1:1")
    with pytest.raises(TypeError, match="func must be callable"):
        map_ordered(3, [1])
    with pytest.raises(OSError, match="cannot connect to the Dask scheduler at tcp://127.0.0.1:9"):
        map_ordered(abs, [1], scheduler="tcp://127.0.0.1:9", progress=False)


def test_existing_cluster_by_client_and_by_address(threaded_cluster):
    cluster, client = threaded_cluster
    f = partial(_slow_square, n=8)
    assert map_ordered(abs, [-1, -2], scheduler=cluster.scheduler_address, progress=False) == [1, 2]
    with pytest.raises(ItemError, match=r"item 3 \(3\) failed: ValueError"):
        map_ordered(f, range(8), scheduler=cluster.scheduler_address, progress=False)
    out = map_ordered(f, range(8), scheduler=client, progress=False, return_exceptions=True)
    assert [r for k, r in enumerate(out) if k != 3] == [k * k for k in range(8) if k != 3]
    assert isinstance(out[3], ItemFailure) and out[3].error == "ValueError: three is not allowed"
    # a task on a worker thread runs numba on one thread (numba's setting is per thread)
    assert {r[0] for r in map_ordered(_threads, range(4), scheduler=client, progress=False)} == {1}


def test_build_map_on_a_thread_cluster_is_bit_identical(dataset, threaded_cluster):
    _, client = threaded_cluster
    local = build_map(dataset, progress=False)
    remote = build_map(dataset, progress=False, scheduler=client)
    assert [o.index for o in remote.observations] == [0, 1, 2, 3]
    assert np.array_equal(local.grid.log_odds, remote.grid.log_odds, equal_nan=True)
    assert local.grid.n_updates == remote.grid.n_updates == 4


@pytest.mark.slow
@pytest.mark.extra("scale")
def test_two_worker_processes_single_threaded_and_bit_identical(dataset):
    """A LocalCluster of 2 processes (workers=2, processes=True): one numba and OpenCV thread each; the same map."""
    from mrstereo._executor import dask_client

    local = build_map(dataset, progress=False)
    with dask_client(workers=2, processes=True) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        info = map_ordered(_threads, range(4), scheduler=client, progress=False)
        parallel = build_map(dataset, progress=False, scheduler=client)
    assert all(r[:3] == (1, 1, "1") for r in info)
    assert all(r[4] is None for r in info)      # distributed's 64 KiB trim threshold slows frames 2.3x
    assert len({r[3] for r in info}) <= 2
    assert np.array_equal(local.grid.log_odds, parallel.grid.log_odds, equal_nan=True)
    for a, b in zip(local.observations, parallel.observations):
        assert a.index == b.index and np.array_equal(a.obstacle_points_world, b.obstacle_points_world)


@pytest.mark.extra("scale")
def test_workers_option_runs_a_local_cluster():
    assert map_ordered(partial(_slow_square, n=0), [0, 1, 2], workers=1, progress=False) == [0, 1, 4]
    assert map_ordered(partial(_slow_square, n=0), [0, 1, 2], workers=1, processes=True, progress=False) == [0, 1, 4]


@pytest.mark.extra("scale")
def test_two_worker_threads_single_threaded_and_bit_identical(dataset):
    """workers=2 (the default): two worker threads in this process, one numba and OpenCV thread each while
    the cluster runs, OpenCV's setting restored after; the same map and observations."""
    import os

    import cv2

    from mrstereo._executor import dask_client

    local = build_map(dataset, progress=False)
    before = cv2.getNumThreads()
    with dask_client(workers=2) as client:
        assert len(client.scheduler_info()["workers"]) == 2
        info = map_ordered(_threads, range(4), scheduler=client, progress=False)
    assert cv2.getNumThreads() == before
    assert all(r[:2] == (1, 1) and r[3] == os.getpid() for r in info)
    parallel = build_map(dataset, progress=False, workers=2)
    assert np.array_equal(local.grid.log_odds, parallel.grid.log_odds, equal_nan=True)
    for a, b in zip(local.observations, parallel.observations):
        assert a.index == b.index and np.array_equal(a.floor_points_world, b.floor_points_world)
        assert np.array_equal(a.obstacle_points_world, b.obstacle_points_world)


def test_cli_map_on_a_scheduler_matches_in_process(dataset, threaded_cluster, tmp_path, capsys):
    from mrstereo.cli import entry

    cluster, _ = threaded_cluster
    assert entry(["map", str(dataset.root), "-o", str(tmp_path / "a"), "--quiet"]) == 0
    # what map prints under each name is the metrics.json value of that name (docs/glossary.md)
    printed = capsys.readouterr().out
    metrics = json.loads((tmp_path / "a" / "metrics.json").read_text())
    for name, key in (("precision", "precision"), ("free correct", "free_precision"),
                      ("free coverage", "free_coverage")):
        assert f"{name} {metrics[key]:.3f}" in printed, (name, printed)
    assert entry(["map", str(dataset.root), "-o", str(tmp_path / "b"), "--quiet",
                  "--scheduler", cluster.scheduler_address]) == 0
    assert np.array_equal(np.load(tmp_path / "a" / "log_odds.npy"), np.load(tmp_path / "b" / "log_odds.npy"),
                          equal_nan=True)
    capsys.readouterr()
    assert entry(["map", str(dataset.root), "-o", str(tmp_path / "c"), "--workers", "2",
                  "--scheduler", cluster.scheduler_address]) == 2
    assert "give --workers or --scheduler, not both" in capsys.readouterr().err


def test_fuse_uses_the_frames_cells_only_when_they_fit(dataset):
    from dataclasses import replace

    from mrstereo.mapping import GridSpec
    from mrstereo.mapping.fusion import fuse
    from mrstereo.mapping.occupancy import view_cells
    from mrstereo.pipeline.run import PipelineConfig

    config = PipelineConfig(grid=GridSpec())
    config = replace(config, mapping=replace(config.mapping, map_occlusion_p=None))   # cells per frame
    run = build_map(dataset, progress=False, config=config)
    cells = [replace(o, cells=view_cells(o.obstacle_points_world, o.floor_points_world, o.sensor_origin_world,
                                         grid=config.grid, config=config.mapping,
                                         baseline_focal_m_px=o.baseline_focal_m_px)) for o in run.observations]
    assert all(o.cells.fits(config.grid, config.mapping) for o in cells)
    np.testing.assert_array_equal(fuse(cells, grid=config.grid, config=config.mapping).log_odds, run.grid.log_odds)
    other = replace(config.mapping, min_points_per_cell=1)        # other cells: the stored ones must not be used
    fused_other = fuse(cells, grid=config.grid, config=other).log_odds
    np.testing.assert_array_equal(fused_other, fuse(run.observations, grid=config.grid, config=other).log_odds)
    assert not np.array_equal(fused_other, run.grid.log_odds, equal_nan=True)



def test_cli_processes_needs_workers(dataset, tmp_path, capsys):
    from mrstereo.cli import entry

    assert entry(["map", str(dataset.root), "-o", str(tmp_path / "a"), "--quiet", "--processes"]) == 2
    assert "--processes only with --workers" in capsys.readouterr().err
    assert not (tmp_path / "a").exists()


@pytest.mark.extra("scale")
def test_worker_threads_fall_back_to_processes_without_a_thread_safe_numba_layer(monkeypatch):
    import mrstereo._executor as parallel

    monkeypatch.setattr(parallel, "numba_thread_safe", lambda: False)
    with pytest.warns(UserWarning, match="workqueue threading layer"):
        info = map_ordered(_threads, range(2), workers=1, progress=False)
    import os
    assert all(r[3] != os.getpid() for r in info)          # ran in a worker process


def test_chunked_tasks_keep_order_and_per_item_failures(threaded_cluster):
    from mrstereo._executor import _chunk_size

    _, client = threaded_cluster
    assert _chunk_size(client, 40) == 2 and _chunk_size(client, 5) == 1 and _chunk_size(client, 10_000) == 8
    f = partial(_slow_square, n=0)
    out = map_ordered(f, range(41), scheduler=client, progress=False, return_exceptions=True)
    assert [o for k, o in enumerate(out) if k != 3] == [k * k for k in range(41) if k != 3]
    assert isinstance(out[3], ItemFailure) and out[3].index == 3 and "three is not allowed" in out[3].traceback
    with pytest.raises(ItemError, match=r"item 3 \(3\) failed: ValueError"):
        map_ordered(f, range(41), scheduler=client, progress=False)


def _loaded(x: int) -> tuple:
    import threading

    if x == 5:
        raise OSError("cannot read item five")
    return x, threading.current_thread().name


def _use_loaded(value) -> tuple:
    import threading

    import cv2
    import numba

    x, reader = value if isinstance(value, tuple) else (value, None)
    if x == 2:
        raise ValueError("two is not allowed")
    time.sleep(0.002 * (x % 3))                    # finish out of order
    return x * x, reader, threading.current_thread().name, numba.get_num_threads(), cv2.getNumThreads()


@pytest.mark.parametrize("workers", [None, 1, 3])
def test_worker_threads_and_prefetch_keep_order_and_name_failures(workers, monkeypatch):
    """workers=N: a pool of single-threaded threads of this process (no Dask); prefetch runs on a reader
    thread ahead of func, in order; a failing prefetch or func is that item's failure."""
    import threading

    import cv2

    monkeypatch.setenv("MRSTEREO_MAX_WORKERS", "3")          # more threads than the 2 cores of CI
    before = cv2.getNumThreads()
    out = map_ordered(_use_loaded, range(12), workers=workers, prefetch=_loaded, progress=False,
                      return_exceptions=True, label=lambda x: f"item {x}")
    assert cv2.getNumThreads() == before
    assert isinstance(out[2], ItemFailure) and "two is not allowed" in out[2].error and out[2].item == "item 2"
    assert isinstance(out[5], ItemFailure) and out[5].error == "OSError: cannot read item five"
    good = [o for k, o in enumerate(out) if k not in (2, 5)]
    assert [o[0] for o in good] == [k * k for k in range(12) if k not in (2, 5)]
    assert all(o[1] == "mrstereo-reader" for o in good)
    if workers is None:
        assert all(o[2] == threading.current_thread().name for o in good)
    else:
        assert {o[2] for o in good} <= {f"mrstereo-worker_{k}" for k in range(workers)}
        assert all(o[3:] == (1, 1) for o in good)
    with pytest.raises(ItemError, match=r"item 3 \(5\) failed: OSError: cannot read item five"):
        map_ordered(_use_loaded, [0, 1, 3, 5, 6], workers=workers, prefetch=_loaded, progress=False)
    assert map_ordered(_use_loaded, [], workers=workers, prefetch=_loaded, progress=False) == []


def test_cli_map_with_worker_threads_starts_no_dask_cluster(dataset, tmp_path):
    """`mrstereo map --workers 2` in a fresh process: the same map as in-process, without importing distributed."""
    import subprocess
    import sys

    code = ("import sys; from mrstereo.cli import entry; "
            f"rc = entry(['map', {str(dataset.root)!r}, '-o', {str(tmp_path / 'w')!r}, '--quiet', '--workers', '2']); "
            "print(rc, 'distributed' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip().splitlines()[-1] == "0 False"
    local = build_map(dataset, progress=False)
    np.testing.assert_array_equal(np.load(tmp_path / "w" / "log_odds.npy"), local.grid.log_odds)
    assert (tmp_path / "w" / "map.png").stat().st_size > 1000


@pytest.fixture
def idle_cluster(monkeypatch):
    """A real scheduler nobody joined (no workers), and a short wait for one."""
    from conftest import extra_missing

    if extra_missing("scale"):
        pytest.skip(extra_missing("scale"))
    import distributed

    from mrstereo import _executor

    monkeypatch.setattr(_executor, "WORKER_TIMEOUT_S", 0.5)
    with distributed.LocalCluster(n_workers=0, processes=False, protocol="tcp://", host="127.0.0.1",
                                  dashboard_address=":0") as cluster:
        yield cluster


@pytest.mark.parametrize("command", ["map", "batch"])
def test_cli_on_a_scheduler_without_workers_is_one_line(command, dataset, idle_cluster, tmp_path, capsys):
    from mrstereo.cli import entry

    address = idle_cluster.scheduler_address
    out = tmp_path / "out"
    assert entry([command, str(dataset.root), "-o", str(out), "--quiet", "--scheduler", address]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [f"mrstereo: error: scheduler {address}: no worker joined in 0.5 s"], lines
    assert not out.exists()


def _sleep_then(x: int) -> int:
    time.sleep(0.3)
    return x


def test_a_cluster_that_loses_all_its_workers_fails_naming_its_scheduler(monkeypatch):
    """Its only worker leaves mid-run: the tasks would wait for a worker forever."""
    from conftest import extra_missing

    if extra_missing("scale"):
        pytest.skip(extra_missing("scale"))
    import threading

    import distributed

    from mrstereo import _executor

    monkeypatch.setattr(_executor, "WORKER_TIMEOUT_S", 0.5)
    monkeypatch.setattr(_executor, "_POLL_S", 0.1)
    with distributed.LocalCluster(n_workers=1, threads_per_worker=1, processes=False, protocol="tcp://",
                                  host="127.0.0.1", dashboard_address=":0") as cluster, \
            distributed.Client(cluster) as client:
        client.wait_for_workers(1)
        leave = threading.Timer(0.5, lambda: cluster.scale(0))
        leave.start()
        try:
            with pytest.raises(RuntimeError, match=rf"scheduler {cluster.scheduler_address}: all workers left "
                                                   r"and none joined in 0.5 s"):
                map_ordered(_sleep_then, range(40), scheduler=client, progress=False)
        finally:
            leave.join()
        assert not client.scheduler_info()["workers"]
