"""Frame observations on disk: what one frame adds to a map (:class:`~mrstereo.mapping.fusion.FrameObservation`)
saved to and read from a ``.npz`` file with a fingerprint of what it was computed from (a resumable batch
run's per-frame store, docs/scale-out.md). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..io import atomic_write
from .fusion import FrameObservation

__all__ = ["save_observation", "load_observation", "observation_fingerprint"]


def save_observation(path: str | os.PathLike, obs: FrameObservation, fingerprint: str = "") -> None:
    """Write ``obs`` (and ``fingerprint``) to ``path`` atomically."""
    with atomic_write(Path(path)) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, fingerprint=np.array(fingerprint), index=obs.index, pose=np.array(obs.pose), pan_rad=obs.pan_rad,
                 obstacle_points_world=obs.obstacle_points_world, floor_points_world=obs.floor_points_world,
                 n_valid_disparity=obs.n_valid_disparity, ground_message=np.array(obs.ground_message),
                 baseline_focal_m_px=np.nan if obs.baseline_focal_m_px is None else obs.baseline_focal_m_px,
                 sensor_height_m=np.nan if obs.sensor_height_m is None else obs.sensor_height_m,
                 boundary_points=obs.boundary_points)


def observation_fingerprint(path: str | os.PathLike) -> str | None:
    """The fingerprint saved with an observation (None: none saved)."""
    with np.load(path) as z:
        return str(z["fingerprint"]) if "fingerprint" in z.files else None


def load_observation(path: str | os.PathLike) -> FrameObservation:
    """The observation :func:`save_observation` wrote."""
    with np.load(path) as z:
        return FrameObservation(index=int(z["index"]), pose=tuple(float(v) for v in z["pose"]),
                                pan_rad=float(z["pan_rad"]), obstacle_points_world=z["obstacle_points_world"],
                                floor_points_world=z["floor_points_world"],
                                n_valid_disparity=int(z["n_valid_disparity"]),
                                ground_message=str(z["ground_message"]),
                                baseline_focal_m_px=_optional_float(z["baseline_focal_m_px"]),
                                sensor_height_m=_optional_float(z["sensor_height_m"]),
                                boundary_points=int(z["boundary_points"]))


def _optional_float(value) -> float | None:
    """A scalar saved by :func:`save_observation` (NaN: None)."""
    value = float(value)
    return None if np.isnan(value) else value
