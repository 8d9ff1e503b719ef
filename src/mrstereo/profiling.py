"""Per-stage wall-clock times of the per-frame chain (``--profile`` of the CLI, benchmarks).

The pipeline marks its stages with :func:`stage`; nothing is measured unless a :class:`Profile`
is active (``with profiling() as prof: ...; print(prof.table())``). Times from all threads of
the process add up (worker processes are not seen). Stages: ``read``, ``rectify``, ``match``
(eq. 9-12), ``reject`` (eq. 13), ``3-D`` (eq. 14-16), ``grid``, ``scan``: docs/speed.md.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import threading
import time
from contextlib import contextmanager, nullcontext

__all__ = ["Profile", "profiling", "stage", "active"]

_NULL = nullcontext()
_active: Profile | None = None


class Profile:
    """Accumulated seconds and call counts per stage name (thread-safe)."""

    def __init__(self, *, clock=time.perf_counter) -> None:
        self.seconds: dict[str, float] = {}
        self.calls: dict[str, int] = {}
        self.clock = clock
        """Seconds of what: wall-clock (``time.perf_counter``, the default) or e.g. ``time.thread_time``
        (CPU time of the calling thread: robust to a busy machine, for single-threaded runs)."""
        self._lock = threading.Lock()

    def add(self, name: str, seconds: float) -> None:
        with self._lock:
            self.seconds[name] = self.seconds.get(name, 0.0) + seconds
            self.calls[name] = self.calls.get(name, 0) + 1

    @contextmanager
    def stage(self, name: str):
        t0 = self.clock()
        try:
            yield
        finally:
            self.add(name, self.clock() - t0)

    def per_frame_ms(self, n_frames: int) -> dict[str, float]:
        """Milliseconds per frame of every stage, in the order the stages were first seen."""
        n = max(int(n_frames), 1)
        return {name: 1000.0 * s / n for name, s in self.seconds.items()}

    def table(self, n_frames: int | None = None) -> str:
        """A small text table: stage, ms per frame, calls, total s (frames: the ``match`` calls by default)."""
        if n_frames is None:
            n_frames = self.calls.get("match", max(self.calls.values(), default=1))
        rows = [f"profile ({n_frames} frame{'s' if n_frames != 1 else ''}; wall-clock, summed over threads)",
                f"{'stage':<8} {'ms/frame':>9} {'calls':>6} {'total s':>8}"]
        for name, ms in self.per_frame_ms(n_frames).items():
            rows.append(f"{name:<8} {ms:9.2f} {self.calls[name]:6d} {self.seconds[name]:8.3f}")
        total = sum(self.seconds.values())
        rows.append(f"{'sum':<8} {1000.0 * total / max(n_frames, 1):9.2f} {'':6} {total:8.3f}")
        return "\n".join(rows)


def active() -> Profile | None:
    """The profile being filled, or None."""
    return _active


def stage(name: str):
    """Context manager timing one stage into the active profile; a no-op when none is active."""
    profile = _active
    return _NULL if profile is None else profile.stage(name)


@contextmanager
def profiling(profile: Profile | None = None):
    """Activate ``profile`` (a new one by default) for the duration of the block; yields it."""
    global _active
    previous, _active = _active, profile if profile is not None else Profile()
    try:
        yield _active
    finally:
        _active = previous
