"""Per-stage wall-clock times of the per-frame chain (``--profile`` of the CLI, benchmarks).

The pipeline marks its stages with :func:`stage`; nothing is measured unless a :class:`Profile`
is active (``with profiling() as prof: ...; print(prof.table())``). Times from all threads of
the process add up (worker processes are not seen). Stages: ``read``, ``rectify``, ``match``
(eq. 9-12), ``reject`` (eq. 13), ``3-D`` (eq. 14-16), ``grid``, ``scan``: docs/speed.md.

A name with a dot is a part of the stage before the dot (``match.search``, ``match.refine``,
``match.guard``, ``match.post`` ...): the parent counts the whole time, each part its own time
without the parts nested in it, and the table lists the parts under their parent, outside the
sum.
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
        self._open = threading.local()        # per thread: the seconds of the parts nested in each open part

    def add(self, name: str, seconds: float) -> None:
        with self._lock:
            self.seconds[name] = self.seconds.get(name, 0.0) + seconds
            self.calls[name] = self.calls.get(name, 0) + 1

    @contextmanager
    def stage(self, name: str):
        if "." not in name:
            t0 = self.clock()
            try:
                yield
            finally:
                self.add(name, self.clock() - t0)
            return
        nested = self._open.__dict__.setdefault("parts", [])
        nested.append(0.0)
        t0 = self.clock()
        try:
            yield
        finally:
            elapsed = self.clock() - t0
            self.add(name, elapsed - nested.pop())       # its own time: without the parts inside it
            if nested:
                nested[-1] += elapsed

    def per_frame_ms(self, n_frames: int) -> dict[str, float]:
        """Milliseconds per frame of every stage, in the order the stages were first seen."""
        n = max(int(n_frames), 1)
        return {name: 1000.0 * s / n for name, s in self.seconds.items()}

    def table(self, n_frames: int | None = None) -> str:
        """A small text table: stage, ms per frame, calls, total s (frames: the ``match`` calls by default);
        the parts of a stage (``match.search``) indented under it, with the rest of its time (``.other``)."""
        if n_frames is None:
            n_frames = self.calls.get("match", max(self.calls.values(), default=1))
        n = max(n_frames, 1)
        rows = [f"profile ({n_frames} frame{'s' if n_frames != 1 else ''}; wall-clock, summed over threads)",
                f"{'stage':<14} {'ms/frame':>9} {'calls':>6} {'total s':>8}"]
        ms = self.per_frame_ms(n_frames)
        top = [name for name in ms if name.split(".")[0] == name or name.split(".")[0] not in ms]
        for name in top:
            rows.append(f"{name:<14} {ms[name]:9.2f} {self.calls[name]:6d} {self.seconds[name]:8.3f}")
            parts = [part for part in ms if part.startswith(name + ".")]
            for part in parts:
                rows.append(f"  {part[len(name):]:<12} {ms[part]:9.2f} {self.calls[part]:6d} {self.seconds[part]:8.3f}")
            if parts:
                rest = self.seconds[name] - sum(self.seconds[part] for part in parts)
                rows.append(f"  {'.other':<12} {1000.0 * rest / n:9.2f} {'':6} {rest:8.3f}")
        total = sum(self.seconds[name] for name in top)
        rows.append(f"{'sum':<14} {1000.0 * total / n:9.2f} {'':6} {total:8.3f}")
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
