"""The sinks a command asks for (viewers, a ROS 2 bag: :mod:`mrstereo.mapping.sinks`, where finished runs
are replayed into them: :func:`~mrstereo.mapping.sinks.replay_map_run`,
:func:`~mrstereo.mapping.sinks.replay_odometry`).
Conventions: docs/conventions.md; user guide: docs/live.md.
"""
from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from pathlib import Path

from ..camera import StereoCamera
from ..mapping.sinks import BagSink, ViewerSink

__all__ = ["ViewerSink", "BagSink", "open_sinks"]

def open_sinks(stereo: StereoCamera, view_stem: str | os.PathLike, *, viewers: Sequence[str] = (),
               record_bag: str | os.PathLike | None = None, foxglove_port: int | None = 8765,
               rerun_mode: str | None = None, echo: Callable[[str], None] | None = None, viewer_port: int = 9876,
               viewer_web_port: int | None = None) -> list:
    """The sinks a run's options ask for: ``viewers`` (``"rerun"``: ``view_stem``.rrd, and a viewer spawned
    with a display or its data served on 127.0.0.1:``viewer_port`` (and the web viewer on ``viewer_web_port``
    when given), or neither with ``rerun_mode="none"``; ``"foxglove"``:
    ``view_stem``.mcap and a websocket server on ``foxglove_port``, None: none), and a ROS 2 bag at
    ``record_bag``. ``echo`` is told where to look."""
    from ..viz.live import FoxgloveLogger, RerunLogger, require_viewers

    require_viewers(viewers)
    stem = Path(view_stem)
    made = not stem.parent.exists()
    stem.parent.mkdir(parents=True, exist_ok=True)
    sinks = []
    try:
        for viewer in viewers:
            if viewer == "rerun":
                mode = rerun_mode or ("spawn" if os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")
                                      else "serve" if viewer_web_port is None else "web")
                logger = RerunLogger(rrd_path=stem.with_suffix(".rrd"), mode=mode, grpc_port=viewer_port,
                                     web_port=viewer_web_port or 9090)
                if echo is not None and logger.url:
                    echo(f"rerun: open {logger.url} in a browser" if mode == "web" else
                         f"rerun: connect a viewer with `rerun {logger.url}`")
            else:
                logger = FoxgloveLogger(mcap_path=stem.with_suffix(".mcap"), port=foxglove_port)
                if echo is not None and logger.url:
                    echo(f"foxglove: connect the Foxglove app to {logger.url}")
            sinks.append(ViewerSink(logger, stereo))
        if record_bag is not None:
            from ..recordings.bag_writer import BagWriter

            sinks.append(BagSink(BagWriter(record_bag)))
    except BaseException:
        for sink in sinks:
            sink.discard()
        if made and not any(stem.parent.iterdir()):     # the output folder made here, left empty: gone
            stem.parent.rmdir()
        raise
    return sinks
