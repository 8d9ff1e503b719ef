"""Scale-out: an ordered parallel map, in-process or on a Dask cluster.

Per-frame work of the chain (rectify, match, reject, triangulate) is independent from frame to
frame; fusion into the grid is an ordered reduction. :func:`map_ordered` runs the independent
part in this process, on a pool of worker threads (the hot loops release the GIL), on a local
Dask cluster's processes, or on an existing ``dask.distributed`` cluster. Results come back in
input order, so a reduction over them is the same for every worker count; inside workers numba
and OpenCV run on one thread each so that N workers on N cores do not oversubscribe them.
User guide: docs/scale-out.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import contextlib
import functools
import logging
import os
import resource
import sys
import threading
import traceback as _traceback
import uuid
import warnings
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from . import _checks
from ._interrupt import reached

__all__ = ["ItemFailure", "ItemError", "map_ordered", "dask_client", "limit_threads", "keep_freed_memory",
           "LatestFrame", "Ordered", "Writer", "Growing", "rss_mb", "peak_rss_mb", "StreamThreads", "read_ahead",
           "quiet_stderr"]

_WORKER_ENV = {"NUMBA_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1",
               "OPENBLAS_NUM_THREADS": "1"}


@dataclass(frozen=True)
class ItemFailure:
    """One item whose call raised (returned in its slot when ``return_exceptions=True``).

    Attributes
    ----------
    index : int
        Position of the item in the input.
    item : str
        A short description of the item (``label(item)``, else its ``repr``).
    error : str
        ``"ExceptionType: message"``.
    traceback : str
        The formatted traceback from the worker.
    """

    index: int
    item: str
    error: str
    traceback: str = ""

    def to_dict(self) -> dict:
        return {"index": self.index, "item": self.item, "error": self.error}


class ItemError(RuntimeError):
    """Raised by :func:`map_ordered` when an item fails (``return_exceptions=False``).

    Its message names the item; ``failure`` holds the :class:`ItemFailure` (the original
    exception is ``__cause__`` when raised in this process).
    """

    def __init__(self, failure: ItemFailure):
        super().__init__(f"item {failure.index} ({failure.item}) failed: {failure.error}")
        self.failure = failure


def limit_threads() -> None:
    """Run numba and OpenCV kernels on one thread in the calling thread / process.

    Called at the start of every task (``numba.set_num_threads`` is thread-local); the process-wide
    ``cv2.setNumThreads`` only in worker processes (:func:`dask_client` sets it for thread workers).
    """
    import numba

    numba.set_num_threads(1)
    if os.environ.get("MRSTEREO_WORKER_PROCESS") == "1":
        import cv2
        cv2.setNumThreads(1)
        keep_freed_memory()


# glibc mallopt parameters: M_TRIM_THRESHOLD, M_TOP_PAD, M_MMAP_THRESHOLD
_MALLOPT = ((-1, 256 << 20), (-2, 64 << 20), (-3, 64 << 20))
_malloc_tuned = False


def keep_freed_memory() -> bool:
    """Let glibc's malloc keep freed memory for reuse instead of returning it to the system.

    The chain's image-sized arrays then stay in the heap from frame to frame instead of costing
    fresh pages (page faults) every frame. Process-wide, so made only in processes mrstereo owns
    (the command, its Dask workers), never on import. Returns False without glibc.
    """
    global _malloc_tuned
    if _malloc_tuned:
        return True
    import ctypes
    import sys

    if not sys.platform.startswith("linux"):
        return False
    try:
        mallopt = ctypes.CDLL("libc.so.6").mallopt
    except (OSError, AttributeError):
        return False
    mallopt.argtypes = (ctypes.c_int, ctypes.c_int)
    _malloc_tuned = all(mallopt(param, value) == 1 for param, value in _MALLOPT)
    return _malloc_tuned


def _label(item: Any, label: Callable[[Any], str] | None) -> str:
    if label is not None:
        try:
            return str(label(item))
        except Exception:                       # a bad label must not hide the real error
            pass
    text = repr(item)
    return text if len(text) <= 200 else text[:197] + "..."


class _Task:
    """Picklable wrapper run on the worker: limit threads, then ``func`` on each item of a chunk.

    Returns, per item, ``(True, result)`` or ``(False, (exception, traceback text))``, so one
    failing item does not lose the others of its chunk.
    """

    def __init__(self, func: Callable):
        self.func = func

    def __call__(self, chunk: Sequence) -> list:
        limit_threads()
        out = []
        for item in chunk:
            try:
                out.append((True, self.func(item)))
            except Exception as exc:
                out.append((False, (exc, _traceback.format_exc())))
        return out


@contextlib.contextmanager
def dask_client(*, workers: int | None = None, scheduler=None, processes: bool = False) -> Iterator[Any]:
    """A ``distributed.Client`` for ``workers`` local workers or an existing ``scheduler``.

    Parameters
    ----------
    workers : int, optional
        Start a ``LocalCluster(n_workers=workers, threads_per_worker=1)`` for
        the duration of the block.
    processes : bool
        With ``workers``: worker processes on loopback (tcp://127.0.0.1)
        instead of worker threads in this process (the default; OpenCV is
        limited to one thread meanwhile).
    scheduler : str or distributed.Client, optional
        Address of a running scheduler (``tcp://127.0.0.1:8786``), or a client
        to reuse (it is not closed at the end).

    Yields
    ------
    distributed.Client
    """
    require_scale()
    from distributed import Client, LocalCluster

    if (workers is None) == (scheduler is None):
        raise ValueError("give exactly one of workers or scheduler")
    if scheduler is not None:
        if isinstance(scheduler, Client):
            yield scheduler
            return
        if not isinstance(scheduler, str) or not scheduler.strip():
            raise ValueError(f"scheduler must be an address like 'tcp://127.0.0.1:8786', got {scheduler!r}")
        _check_reachable(scheduler.strip())
        try:
            client = Client(scheduler.strip(), timeout="10s")
        except (OSError, TimeoutError) as exc:
            raise OSError(f"cannot connect to the Dask scheduler at {scheduler}: {exc}") from None
        try:
            _wait_for_workers(client, "no worker joined")
            yield client
        finally:
            client.close()
        return
    import dask

    workers = _checks.workers("workers", workers)
    if not processes and not numba_thread_safe():
        warnings.warn("numba's workqueue threading layer cannot run kernels from several threads at once: "
                      "using worker processes (install tbb or have libgomp for worker threads)", stacklevel=3)
        processes = True
    if not processes:
        yield from _thread_client(workers)
        return
    env = dict(_WORKER_ENV, MRSTEREO_WORKER_PROCESS="1")
    # distributed's nannies set MALLOC_TRIM_THRESHOLD_=65536 in their workers, which also fixes
    # glibc's mmap threshold: every image-sized temporary would cost fresh page faults. The workers
    # tune malloc themselves (limit_threads -> keep_freed_memory).
    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}), \
            quiet_stderr():
        cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                               dashboard_address=":0", env=env, silence_logs=logging.CRITICAL)
    with cluster, Client(cluster) as client:
        reached("cluster")
        yield client


def require_scale() -> None:
    """Raise RuntimeError naming the extra when Dask is not installed (``--processes``, ``--scheduler``)."""
    import importlib.util

    if any(importlib.util.find_spec(m) is None for m in ("dask", "distributed")):
        raise RuntimeError('--processes and --scheduler need Dask (dask, distributed): pip install "mrstereo[scale]"')


@contextlib.contextmanager
def quiet_stderr() -> Iterator[None]:
    """Processes started in the block (Dask workers, a viewer) write their stderr to /dev/null.

    Ctrl-C signals the whole process group: workers still importing would each print a traceback
    over the command's one line (their failures reach this process through Dask anyway).
    """
    try:
        saved = os.dup(2)
    except OSError:
        yield
        return
    try:
        sys.stderr.flush()
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, 2)
        os.close(devnull)
        yield
    finally:
        sys.stderr.flush()
        os.dup2(saved, 2)
        os.close(saved)


def numba_thread_safe() -> bool:
    """Whether numba's threading layer runs parallel kernels from several threads at once.

    The tbb and omp layers do; workqueue aborts the process on concurrent launches. This starts
    numba's thread pool (choosing the layer) without compiling a kernel where numba allows it.
    """
    import numba

    try:
        from numba.np.ufunc.parallel import _launch_threads

        _launch_threads()
    except (ImportError, AttributeError):
        import numpy as np

        _probe_kernel()(np.zeros(2))
    return numba.threading_layer() != "workqueue"


@functools.cache
def _probe_kernel():
    """A tiny parallel kernel (built on first use, not on import)."""
    import numba

    @numba.njit(parallel=True, nogil=True, cache=True)
    def probe(out):
        for i in numba.prange(out.shape[0]):
            out[i] = i

    return probe


@contextlib.contextmanager
def _single_threaded_kernels() -> Iterator[None]:
    """OpenCV and the BLAS behind numpy's matmul on one thread for the block (both restored after).

    For worker threads of this process: OpenBLAS's own thread pool, whose idle threads spin, and
    OpenCV's (process-wide) would oversubscribe the cores the worker threads already fill.
    """
    import cv2
    from threadpoolctl import threadpool_limits

    cv_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
    finally:
        cv2.setNumThreads(cv_threads)


def _thread_client(workers: int) -> Iterator[Any]:
    """A Dask client of ``workers`` single-threaded worker threads in this process."""
    from distributed import Client, LocalCluster

    with _single_threaded_kernels(), \
            LocalCluster(n_workers=workers, threads_per_worker=1, processes=False, dashboard_address=None,
                         silence_logs=logging.CRITICAL) as cluster, Client(cluster) as client:
        yield client


SCHEDULER_TIMEOUT_S = 5.0
"""How long a scheduler address may take to accept a connection, and then to greet it as Dask does."""


def _check_reachable(address: str) -> None:
    """Fail within seconds (not after the client's retries, or never) when no Dask scheduler answers at a
    tcp:// address: nothing listens, the peer accepts and stays silent, or it speaks another protocol
    (an HTTP server, whose reply Dask's reader would take for a frame length of exabytes).

    A Dask server's greeting (an 8-byte length, then that many bytes) is awaited ``SCHEDULER_TIMEOUT_S``.
    """
    import socket
    import struct
    from urllib.parse import urlsplit

    if "://" not in address:
        address = "tcp://" + address
    parts = urlsplit(address)
    if parts.scheme not in ("tcp", "tls") or parts.hostname is None:
        return
    try:
        port = parts.port or 8786
    except ValueError:
        raise ValueError(f"scheduler address {address!r} has a bad port") from None
    try:
        sock = socket.create_connection((parts.hostname, port), timeout=SCHEDULER_TIMEOUT_S)
    except OSError as exc:
        raise OSError(f"cannot connect to the Dask scheduler at {address}: {exc.strerror or exc}") from None
    if parts.scheme == "tls":               # the greeting is encrypted: the client's own timeout applies
        sock.close()
        return
    with sock:
        greeting = b""
        try:
            while len(greeting) < 8:
                chunk = sock.recv(8 - len(greeting))
                if not chunk:
                    break
                greeting += chunk
        except OSError:                     # socket.timeout included
            raise OSError(f"no Dask scheduler at {address}: it accepts connections but sent no Dask handshake "
                          f"within {SCHEDULER_TIMEOUT_S:g} s") from None
    if len(greeting) < 8:
        raise OSError(f"no Dask scheduler at {address}: it closed the connection without a Dask handshake")
    length = struct.unpack("<Q", greeting)[0]
    if not 0 < length < (1 << 20):
        text = greeting.decode("ascii", "replace").strip()
        raise OSError(f"no Dask scheduler at {address}: it speaks another protocol (it sent {text!r})")


def map_ordered(func: Callable[[Any], Any], items: Iterable[Any], *, workers: int | None = None,
                scheduler=None, processes: bool = False, progress: bool = True, desc: str = "working",
                return_exceptions: bool = False, label: Callable[[Any], str] | None = None,
                unit: str = "item", prefetch: Callable[[Any], Any] | None = None) -> list:
    """``[func(item) for item in items]``, in parallel, results in input order.

    Parameters
    ----------
    func : callable
        A picklable function of one item (a module-level function or a
        ``functools.partial`` of one) when it runs on workers.
    items : iterable
        Inputs, each picklable (keep them small: paths rather than images).
    workers : int, optional
        Run on this many single-threaded workers: threads of this process, or with
        ``processes=True`` the processes of a local Dask cluster made for the call.
    scheduler : str or distributed.Client, optional
        Run on an existing Dask cluster. With neither ``workers`` nor
        ``scheduler`` everything runs in this process, one item after another.
    processes : bool
        With ``workers``: worker processes instead of worker threads
        (:func:`dask_client`).
    progress : bool
        Show a tqdm bar (stderr) that advances as items finish.
    desc, unit : str
        The bar's label and unit.
    return_exceptions : bool
        False: the first failing item raises :class:`ItemError` naming it.
        True: a failing item's slot holds an :class:`ItemFailure` and the
        others go on.
    label : callable, optional
        ``label(item) -> str`` names an item in errors (default ``repr``).
    prefetch : callable, optional
        In this process only: ``func`` gets ``prefetch(item)``, computed a few items ahead
        by a reader thread (on Dask workers it gets the item, so it must accept both).

    Returns
    -------
    list
        One result (or ``ItemFailure``) per item, in input order.
    """
    from tqdm.auto import tqdm

    if not callable(func):
        raise TypeError(f"func must be callable, got {type(func).__name__}")
    if prefetch is not None and not callable(prefetch):
        raise TypeError(f"prefetch must be callable, got {type(prefetch).__name__}")
    if workers is not None and scheduler is not None:
        raise ValueError("give workers or scheduler, not both")
    if workers is not None:
        workers = _checks.workers("workers", workers)
    items = list(items)

    def new_bar():
        return tqdm(total=len(items), desc=desc, unit=unit, disable=not progress or not items)

    if workers is None and scheduler is None:
        with new_bar() as bar:
            return _map_local(func, items, bar, return_exceptions, label, prefetch)
    if not items:
        return []
    if scheduler is None and not processes and numba_thread_safe():
        with new_bar() as bar:
            return _map_threads(func, items, workers, bar, return_exceptions, label, prefetch)
    with dask_client(workers=workers, scheduler=scheduler, processes=processes) as client, new_bar() as bar:
        return _map_dask(client, func, items, bar, return_exceptions, label, desc)


def _failure(k: int, items: Sequence, label, exc: BaseException, tb: str, return_exceptions: bool) -> ItemFailure:
    """Item ``k``'s failure for its slot (``return_exceptions``), else raise :class:`ItemError` naming it."""
    failure = ItemFailure(index=k, item=_label(items[k], label), error=f"{type(exc).__name__}: {exc}", traceback=tb)
    if not return_exceptions:
        raise ItemError(failure) from exc
    return failure


def _prefetched(items: Sequence, prefetch, depth: int) -> Iterator[tuple[bool, Any]]:
    """``(True, prefetch(item))`` or ``(False, (exception, traceback))`` per item, in order.

    Without ``prefetch``: ``(True, item)``. With it, a reader thread computes up to ``depth`` items ahead
    of the consumer (:func:`read_ahead`) and stops when the consumer does.
    """
    if prefetch is None:
        for item in items:
            yield True, item
        return

    def values():
        for item in items:
            try:
                yield True, prefetch(item)
            except Exception as exc:
                yield False, (exc, _traceback.format_exc())

    yield from read_ahead(values(), depth)


def read_ahead(iterable: Iterable, depth: int = 2) -> Iterator:
    """The items of ``iterable`` in order, read up to ``depth`` ahead by a daemon reader thread (a recording's
    images decoded while the frames before them are matched; OpenCV's decoders release the GIL). An
    exception of the reader is raised where its item would have come; the reader stops when the consumer
    does."""
    import queue

    ready: queue.Queue = queue.Queue(maxsize=max(1, int(depth)))
    stop = threading.Event()
    end = object()

    def put(value) -> bool:
        while not stop.is_set():
            try:
                ready.put(value, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def read() -> None:
        try:
            for item in iterable:
                if not put((True, item)):
                    return
        except BaseException as exc:            # handed to the consumer
            put((False, exc))
            return
        put((True, end))

    threading.Thread(target=read, name="mrstereo-reader", daemon=True).start()
    try:
        while True:
            ok, value = ready.get()
            if not ok:
                raise value
            if value is end:
                return
            yield value
    finally:
        stop.set()


def _map_local(func, items: Sequence, bar, return_exceptions: bool, label, prefetch=None) -> list:
    results = []
    for k, (ok, value) in enumerate(_prefetched(items, prefetch, depth=2)):
        reached("frame")
        if ok:
            try:
                results.append(func(value))
                bar.update(1)
                continue
            except Exception as exc:
                error, tb = exc, _traceback.format_exc()
        else:
            error, tb = value
        results.append(_failure(k, items, label, error, tb, return_exceptions))
        bar.update(1)
    return results


def _map_threads(func, items: Sequence, workers: int, bar, return_exceptions: bool, label, prefetch=None) -> list:
    """:func:`map_ordered` on a pool of ``workers`` single-threaded worker threads of this process.

    No Dask: a thread pool starts at once, a local Dask cluster only after its imports and
    start-up. At most ``2 * workers`` items are in flight.
    """
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    task = _Task(func)
    results: list = [None] * len(items)
    pending: dict = {}

    def collect(block_until: int) -> None:
        while len(pending) > block_until:
            done, _ = wait(pending, return_when=FIRST_COMPLETED)
            for future in done:
                k = pending.pop(future)
                ok, value = future.result()[0]
                results[k] = value if ok else _failure(k, items, label, *value, return_exceptions)
                bar.update(1)
                reached("frame")

    with _single_threaded_kernels(), ThreadPoolExecutor(workers, thread_name_prefix="mrstereo-worker") as pool:
        try:
            for k, (ok, value) in enumerate(_prefetched(items, prefetch, depth=workers + 1)):
                if ok:
                    pending[pool.submit(task, [value])] = k
                else:
                    results[k] = _failure(k, items, label, *value, return_exceptions)
                    bar.update(1)
                collect(2 * workers - 1)
            collect(0)
        except BaseException:
            for future in pending:
                future.cancel()
            raise
    return results


def _chunk_size(client, n_items: int) -> int:
    """Items per Dask task: about 8 tasks per worker thread, at most 8 items each.

    A Dask task costs milliseconds of scheduling in the client's interpreter, a sizeable share of a
    frame's work: a few frames per task amortize it, enough tasks per thread keep the workers busy.
    """
    try:
        threads = max(1, sum(client.nthreads().values()))
    except Exception:                       # a client that cannot tell: one item per task
        return 1
    return max(1, min(8, n_items // (8 * threads)))


WORKER_TIMEOUT_S = 30.0
"""How long a Dask cluster may be without workers: before the first task (a scheduler nobody joined) and
whenever all of its workers have left during a run. Then the run fails naming the scheduler."""

_POLL_S = 1.0


def _wait_for_workers(client, what: str) -> None:
    """Return once the client's cluster has a worker; RuntimeError naming its scheduler after
    ``WORKER_TIMEOUT_S`` without one (distributed would queue the tasks forever)."""
    try:
        client.wait_for_workers(1, timeout=WORKER_TIMEOUT_S)
    except TimeoutError:
        address = getattr(client.scheduler, "address", None) or "?"
        raise RuntimeError(f"scheduler {address}: {what} in {WORKER_TIMEOUT_S:g} s") from None


def _as_completed(client, futures: Sequence) -> Iterator:
    """The futures as they finish; every ``_POLL_S`` without one, a cluster left without workers gets
    ``WORKER_TIMEOUT_S`` to regain one (:func:`_wait_for_workers`)."""
    from distributed import wait

    pending = set(futures)
    while pending:
        try:
            done, pending = wait(pending, timeout=_POLL_S, return_when="FIRST_COMPLETED")
        except TimeoutError:
            if not client.scheduler_info().get("workers"):
                _wait_for_workers(client, "all workers left and none joined")
            continue
        yield from done


def _map_dask(client, func, items: Sequence, bar, return_exceptions: bool, label, desc: str) -> list:
    _wait_for_workers(client, "no worker joined")
    task = _Task(func)
    token = uuid.uuid4().hex[:12]
    size = _chunk_size(client, len(items))
    starts = range(0, len(items), size)
    futures = client.map(task, [items[a:a + size] for a in starts],
                         key=[f"{desc}-{a}-{token}" for a in starts])
    first = {f.key: a for a, f in zip(starts, futures)}
    results: list = [None] * len(items)
    try:
        for future in _as_completed(client, futures):
            a = first[future.key]
            n = min(size, len(items) - a)
            if future.status == "error":            # the chunk itself failed (e.g. a result that cannot be sent)
                exc, tb = future.exception(), future.traceback()
                text = "".join(_traceback.format_tb(tb)) if tb is not None else ""
                for k in range(a, a + n):
                    results[k] = _failure(k, items, label, exc, text, return_exceptions)
            else:
                for k, (ok, value) in enumerate(future.result(), start=a):
                    results[k] = value if ok else _failure(k, items, label, *value, return_exceptions)
            future.release()
            bar.update(n)
            reached("frame")
    finally:
        client.cancel([f for f in futures if not f.done()])
    return results


# ------------------------------------------------------------------ a live loop's threads

class LatestFrame:
    """A one-frame slot between a producer and consumers; the producer never waits unless ``lossless``.

    ``put`` replaces a frame nobody took yet (counted in ``dropped``), or waits with ``lossless``;
    ``take`` hands out the frame with a ticket (0, 1, ...) or None once closed and empty.
    """

    def __init__(self, *, lossless: bool = False) -> None:
        self.lossless = lossless
        self.dropped = 0
        self.tickets = 0
        self._item = None
        self._closed = False
        self._cond = threading.Condition()

    def put(self, item, stop: threading.Event) -> bool:
        """Offer ``item``; False when stopped before it could be placed (lossless only)."""
        with self._cond:
            if self.lossless:
                while self._item is not None and not stop.is_set():
                    self._cond.wait(0.1)
                if stop.is_set():
                    return False
            elif self._item is not None:
                self.dropped += 1
            self._item = item
            self._cond.notify_all()
            return True

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()

    def take(self, timeout_s: float = 0.1):
        """``(ticket, item)``; ``(None, None)`` after ``timeout_s`` with nothing; raises StopIteration when
        closed and empty."""
        with self._cond:
            if self._item is None and not self._closed:
                self._cond.wait(timeout_s)
            if self._item is None:
                if self._closed:
                    raise StopIteration
                return None, None
            item, self._item = self._item, None
            ticket, self.tickets = self.tickets, self.tickets + 1
            self._cond.notify_all()
            return ticket, item

    def discard(self) -> bool:
        """Drop a frame still in the slot (counted); True if there was one."""
        with self._cond:
            if self._item is None:
                return False
            self._item = None
            self.dropped += 1
            self._cond.notify_all()
            return True


class Ordered:
    """Matched frames handed to the fuser by ticket, in the order the matchers took them."""

    def __init__(self) -> None:
        self._items: dict[int, object] = {}
        self._cond = threading.Condition()

    def put(self, ticket: int, item) -> None:
        with self._cond:
            self._items[ticket] = item
            self._cond.notify_all()

    def get(self, ticket: int, timeout_s: float) -> object | None:
        with self._cond:
            if ticket not in self._items:
                self._cond.wait(timeout_s)
            return self._items.pop(ticket, None)


def rss_mb() -> float:
    """Resident memory of this process now [MB] (Linux /proc; 0 elsewhere)."""
    try:
        with open("/proc/self/statm") as fh:
            return int(fh.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 1e6
    except (OSError, ValueError, IndexError):
        return 0.0


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e6      # Linux: kibibytes


class Growing:
    """An array that grows along its first axis by doubling (the trajectory)."""

    def __init__(self, shape: tuple[int, ...]) -> None:
        self._data = np.empty((64,) + shape)
        self.n = 0

    def append(self, value) -> None:
        if self.n == len(self._data):
            self._data = np.concatenate([self._data, np.empty_like(self._data)])
        self._data[self.n] = value
        self.n += 1

    def view(self) -> np.ndarray:
        return self._data[:self.n]


class Writer:
    """Writes snapshots of the outputs on its own thread; a newer snapshot replaces one not yet begun."""

    def __init__(self, write: Callable[[dict], None]) -> None:
        self._write = write
        self._pending = None
        self._cond = threading.Condition()
        self._closed = False
        self.error: BaseException | None = None
        self._thread = threading.Thread(target=self._loop, name="mrstereo-live-writer", daemon=True)
        self._thread.start()

    def submit(self, snapshot: dict) -> None:
        with self._cond:
            self._pending = snapshot
            self._cond.notify_all()

    def _loop(self) -> None:
        while True:
            with self._cond:
                while self._pending is None and not self._closed:
                    self._cond.wait()
                snapshot, self._pending = self._pending, None
                if snapshot is None:
                    return
            try:
                self._write(snapshot)
            except BaseException as exc:        # reported by the fuser
                self.error = exc
            reached("save")

    def close(self) -> None:
        with self._cond:
            self._closed = True
            self._cond.notify_all()
        self._thread.join()


class StreamThreads:
    """A capture thread and ``workers`` worker threads over a stream, and what they share: a one-frame slot
    (:class:`LatestFrame`; ``lossless`` False: the newest frame wins), the worked items in order
    (:class:`Ordered`, by ticket), the bound on items in flight (``in_flight``: the consumer releases
    one per item taken), errors, counts and CPU times.

    ``frames`` is iterated on the capture thread, each frame wrapped by ``make_item``; ``work(item)``
    runs on a worker (its exception stored in ``item.error``); at most ``max_items`` frames are taken.
    """

    def __init__(self, frames, make_item: Callable, work: Callable, *, workers: int, lossless: bool,
                 max_items: int | None, stop: threading.Event, name: str = "mrstereo-live") -> None:
        self.frames, self.make_item, self.work, self.max_items, self.stop = frames, make_item, work, max_items, stop
        self.slot = LatestFrame(lossless=lossless)
        self.ordered = Ordered()
        self.in_flight = threading.Semaphore(workers)
        self.errors: list[BaseException] = []
        self.cpu: dict[str, float] = {}
        self.counts = {"in": 0}
        self.threads = [threading.Thread(target=self._capture, name=f"{name}-capture", daemon=True)]
        self.threads += [threading.Thread(target=self._worker, args=(k,), name=f"{name}-match-{k}",
                                          daemon=True) for k in range(workers)]

    def start(self) -> None:
        for t in self.threads:
            t.start()

    def join(self) -> None:
        self.stop.set()
        for t in self.threads:
            t.join(timeout=5.0)

    def matching(self) -> bool:
        """A worker still runs."""
        return any(t.is_alive() for t in self.threads[1:])

    def _capture(self) -> None:
        import time

        start, slot, stop = time.thread_time(), self.slot, self.stop
        try:
            for frame in self.frames:
                if stop.is_set():
                    break
                self.counts["in"] += 1
                if not slot.put(self.make_item(frame), stop):
                    self.counts["in"] -= 1
                    break
                if self.max_items is not None and self.counts["in"] >= self.max_items:
                    self.counts["end"] = "max frames"
                    break
        except BaseException as exc:
            self.errors.append(exc)
            stop.set()
        finally:
            slot.close()
            self.cpu["capture"] = time.thread_time() - start

    def _worker(self, k: int) -> None:
        import time

        import numba

        start = time.thread_time()
        numba.set_num_threads(1)            # one core per worker: the workers are the parallelism
        try:
            while True:
                while not self.in_flight.acquire(timeout=0.1):
                    if self.stop.is_set():
                        return
                try:
                    ticket, item = self.slot.take()
                except StopIteration:
                    self.in_flight.release()
                    return
                if item is None:
                    self.in_flight.release()
                    continue
                try:
                    self.work(item)
                except BaseException as exc:
                    item.error = exc
                self.ordered.put(ticket, item)
        finally:
            self.cpu[f"matcher {k}"] = time.thread_time() - start
