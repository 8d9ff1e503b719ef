"""Frame observations on disk: a resumable run's per-frame store (``mrstereo batch``, docs/scale-out.md).

Each frame leaves four files (:func:`frame_outputs`): its disparity (PFM), point cloud (PLY), virtual
scan (JSON) and what it adds to the map (:class:`~mrstereo.mapping.fusion.FrameObservation`, ``.npz``)
with a fingerprint of what it was computed from (:func:`digest` of the inputs, :func:`file_stamp` of
files); :func:`resume_frame` reads back a frame whose files are whole and whose fingerprint matches.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np

from ..geometry.ply import read_ply, write_ply
from ..geometry.scan import write_scan_json
from ..io import atomic_write, read_pfm, write_disparity
from .fusion import FrameObservation

__all__ = ["save_observation", "load_observation", "observation_fingerprint", "frame_outputs", "save_frame",
           "resume_frame", "digest", "file_stamp"]


def digest(value) -> str:
    """A short stable hash of JSON-able ``value`` (anything else by its repr)."""
    text = json.dumps(value, sort_keys=True, default=repr, separators=(",", ":"))
    return hashlib.sha256(text.encode("utf-8")).hexdigest()[:32]


def file_stamp(path: Path | None) -> list | None:
    """``[path, size, mtime_ns]`` of a file (None for no file): what a changed file changes."""
    if path is None:
        return None
    try:
        st = os.stat(path)
    except OSError:
        return [str(path), None, None]
    return [str(path), st.st_size, st.st_mtime_ns]


def frame_outputs(frames_dir: str | os.PathLike, index: int) -> dict[str, Path]:
    """The four files of frame ``index``: disparity, cloud, scan, observation."""
    base = Path(frames_dir) / f"{index:06d}"
    return {"disparity": base.with_suffix(".pfm"), "cloud": base.with_suffix(".ply"),
            "scan": Path(f"{base}.scan.json"), "observation": Path(f"{base}.obs.npz")}


def save_frame(files: dict[str, Path], obs: FrameObservation, *, fingerprint: str, disparity_px: np.ndarray,
               points_robot_image: np.ndarray, left_rect: np.ndarray, scan, comment: str = "") -> None:
    """Write a frame's four files (:func:`frame_outputs`), each atomically, the observation last."""
    import cv2

    gray = cv2.cvtColor(left_rect, cv2.COLOR_BGR2GRAY) if left_rect.ndim == 3 else left_rect
    write_disparity(files["disparity"], disparity_px)
    write_ply(files["cloud"], points_robot_image.reshape(-1, 3), intensity=gray.ravel(), comment=comment)
    write_scan_json(files["scan"], scan)
    save_observation(files["observation"], obs, fingerprint)


def resume_frame(files: dict[str, Path], fingerprint: str) -> FrameObservation | None:
    """The observation of a finished frame, or None when one of its four files is missing or unreadable or
    it was computed from other inputs or options (then the frame is computed again)."""
    if not all(p.is_file() for p in files.values()):
        return None
    try:
        if observation_fingerprint(files["observation"]) != fingerprint:
            return None
        read_pfm(files["disparity"])
        json.loads(files["scan"].read_text(encoding="utf-8"))
        read_ply(files["cloud"])
        return load_observation(files["observation"])
    except Exception:                  # any damage: recompute (the files are rewritten atomically)
        return None


def save_observation(path: str | os.PathLike, obs: FrameObservation, fingerprint: str = "") -> None:
    """Write ``obs`` (and ``fingerprint``) to ``path`` atomically."""
    with atomic_write(Path(path)) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, fingerprint=np.array(fingerprint), index=obs.index, pose=np.array(obs.pose), pan_rad=obs.pan_rad,
                 obstacle_points_world=obs.obstacle_points_world, floor_points_world=obs.floor_points_world,
                 n_valid_disparity=obs.n_valid_disparity, ground_message=np.array(obs.ground_message),
                 baseline_focal_m_px=np.nan if obs.baseline_focal_m_px is None else obs.baseline_focal_m_px,
                 sensor_height_m=np.nan if obs.sensor_height_m is None else obs.sensor_height_m,
                 boundary_points=obs.boundary_points,
                 **({} if obs.drop_points_world is None else {"drop_points_world": obs.drop_points_world}))


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
                                boundary_points=int(z["boundary_points"]),
                                drop_points_world=z["drop_points_world"] if "drop_points_world" in z.files else None)


def _optional_float(value) -> float | None:
    """A scalar saved by :func:`save_observation` (NaN: None)."""
    value = float(value)
    return None if np.isnan(value) else value
