"""A test hook: a run signals itself when it reaches a known point, so interrupt tests need no sleep.

``MRSTEREO_SIGNAL_AT="frame:3"`` makes the third call of ``reached("frame")`` send SIGINT to the
process group, as a terminal's Ctrl-C does; ``"frame:3:SIGTERM"`` sends SIGTERM; several points are
separated by commas (``"save:2:SIGINT,stopping:1:SIGINT"``); a fourth field names a file that receives
the ``time.monotonic()`` of the signal. Only the leader of its process group signals (a command
started by a test with ``start_new_session=True``), never its worker processes or a test process.

The points: ``import`` (the command line's first statement, before its imports), ``start`` (the
command line, its handlers installed), ``cluster`` (a Dask cluster
started), ``frame`` (each frame done, in the process that runs the command), ``save`` (each live
snapshot written), ``stopping`` (the live loop's first Ctrl-C handled). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
import sys
import time

ENV_VAR = "MRSTEREO_SIGNAL_AT"
_counts: dict[str, int] = {}


def reached(point: str) -> None:
    """Count one more ``point``; send the signal ``MRSTEREO_SIGNAL_AT`` asks for at this count."""
    spec = os.environ.get(ENV_VAR)
    if not spec or os.getpid() != os.getpgrp():
        return
    _counts[point] = count = _counts.get(point, 0) + 1
    for entry in spec.split(","):
        name, at, *rest = entry.split(":", 3)
        if name == point and int(at) == count:
            if len(rest) > 1:
                with open(rest[1], "w") as f:
                    f.write(repr(time.monotonic()))
            import signal           # (here: the module takes milliseconds to import, the hook none)

            os.killpg(os.getpgrp(), getattr(signal, rest[0] if rest else "SIGINT"))


def _early_interrupt(signum, frame) -> None:
    os.write(2, b"mrstereo: interrupted\n")
    os._exit(130)


def guard_start() -> None:
    """In mrstereo's own process (the console script, ``python -m mrstereo``), from the first statement of
    the package: Ctrl-C or SIGTERM while the command line loads, before any work, is the one line
    ``mrstereo: interrupted`` and exit 130 (the command line installs its own handlers next)."""
    orig = getattr(sys, "orig_argv", [])
    console = os.path.basename(sys.argv[0] if sys.argv else "") == "mrstereo"
    module = any(a == "-m" and b == "mrstereo" for a, b in zip(orig, orig[1:]))
    if console or module:
        import _signal          # (the C module: ``signal`` takes milliseconds to import)

        for signum in (_signal.SIGINT, _signal.SIGTERM):
            _signal.signal(signum, _early_interrupt)
