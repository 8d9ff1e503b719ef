"""Frame observations on disk: a resumable run's per-frame store (``mrstereo batch``, docs/scale-out.md).

Each frame leaves four files (:func:`frame_outputs`): its disparity (PFM), point cloud (PLY), virtual
scan (JSON) and what it adds to the map (:class:`~mrstereo.mapping.fusion.FrameObservation`, ``.npz``)
with a fingerprint of what it was computed from (:func:`digest` of the inputs, :func:`file_stamp` of
files; :func:`dataset_fingerprint`, :func:`frame_fingerprint`, :func:`map_fingerprint`);
:func:`resume_frame` reads back a frame whose files are whole and whose fingerprint matches. Each dataset
has its own output folder (:func:`output_names`), claimed by its ``dataset.json``.
Conventions: docs/conventions.md.
"""
from __future__ import annotations

import hashlib
import json
import os
import re
from collections import Counter
from pathlib import Path

import numpy as np

from .. import __version__
from ..camera import mount_entry
from ..geometry.ply import write_ply
from ..geometry.scan import write_scan_json
from ..io import atomic_write, write_disparity
from .fusion import FrameObservation
from .rosmap import ros_map_files

__all__ = ["save_observation", "load_observation", "observation_fingerprint", "frame_outputs", "save_frame",
           "resume_frame", "digest", "file_stamp", "dataset_fingerprint", "frame_fingerprint", "map_fingerprint",
           "output_owner", "output_names", "DATASET_RECORD", "content_digest", "remove_stale_frames", "claim_folder",
           "bag_fingerprint"]

DATASET_RECORD = "dataset.json"
"""The file that claims a dataset's output folder (its ``root``)."""


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


def content_digest(paths) -> str:
    """A hash of the files' bytes, in order (a changed, truncated or edited file changes it)."""
    h = hashlib.sha256()
    for path in paths:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
        h.update(b"\0")
    return h.hexdigest()[:32]


def frame_outputs(frames_dir: str | os.PathLike, index: int) -> dict[str, Path]:
    """The four files of frame ``index``: disparity, cloud, scan, observation."""
    base = Path(frames_dir) / f"{index:06d}"
    return {"disparity": base.with_suffix(".pfm"), "cloud": base.with_suffix(".ply"),
            "scan": Path(f"{base}.scan.json"), "observation": Path(f"{base}.obs.npz")}


def save_frame(files: dict[str, Path], obs: FrameObservation, *, fingerprint: str, disparity_px: np.ndarray,
               points_robot_image: np.ndarray, left_rect: np.ndarray, scan, comment: str = "") -> None:
    """Write a frame's four files (:func:`frame_outputs`), each atomically, the observation last with the
    fingerprint of its inputs and the bytes of the other three (:func:`resume_frame` checks both)."""
    import cv2

    gray = cv2.cvtColor(left_rect, cv2.COLOR_BGR2GRAY) if left_rect.ndim == 3 else left_rect
    write_disparity(files["disparity"], disparity_px)
    write_ply(files["cloud"], points_robot_image.reshape(-1, 3), intensity=gray.ravel(), comment=comment)
    write_scan_json(files["scan"], scan)
    save_observation(files["observation"], obs, _with_files(fingerprint, files))


def _with_files(fingerprint: str, files: dict[str, Path]) -> str:
    return digest([fingerprint, content_digest(files[k] for k in ("disparity", "cloud", "scan"))])


def resume_frame(files: dict[str, Path], fingerprint: str) -> FrameObservation | None:
    """The observation of a finished frame, or None when one of its four files is missing, unreadable or
    changed since it was written, or it was computed from other inputs or options (then the frame is
    computed again)."""
    if not all(p.is_file() for p in files.values()):
        return None
    try:
        if observation_fingerprint(files["observation"]) != _with_files(fingerprint, files):
            return None
        return load_observation(files["observation"])
    except Exception:                  # any damage: recompute (the files are rewritten atomically)
        return None


def remove_stale_frames(frames_dir: str | os.PathLike, n_frames: int) -> list[Path]:
    """Remove the files :func:`save_frame` wrote for frames ``n_frames`` and on (frames no longer in the
    recording); nothing else in ``frames_dir`` is touched. Returns the files removed."""
    removed = []
    for path in Path(frames_dir).glob("*"):
        match = _FRAME_FILE.fullmatch(path.name)
        if match and int(match.group(1)) >= n_frames and path.is_file():
            path.unlink()
            removed.append(path)
    return removed


_FRAME_FILE = re.compile(r"(\d{6,})(\.pfm|\.ply|\.scan\.json|\.obs\.npz)")


_DROP_DATA = ("drop_points_world", "drop_candidates_world", "drop_weak_points_world")
"""The drop test's arrays of a :class:`FrameObservation` (saved when not None)."""


def save_observation(path: str | os.PathLike, obs: FrameObservation, fingerprint: str = "") -> None:
    """Write ``obs`` (and ``fingerprint``) to ``path`` atomically."""
    with atomic_write(Path(path)) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, fingerprint=np.array(fingerprint), index=obs.index, pose=np.array(obs.pose), pan_rad=obs.pan_rad,
                 obstacle_points_world=obs.obstacle_points_world, floor_points_world=obs.floor_points_world,
                 n_valid_disparity=obs.n_valid_disparity, ground_message=np.array(obs.ground_message),
                 baseline_focal_m_px=np.nan if obs.baseline_focal_m_px is None else obs.baseline_focal_m_px,
                 sensor_height_m=np.nan if obs.sensor_height_m is None else obs.sensor_height_m,
                 boundary_points=obs.boundary_points,
                 **{name: getattr(obs, name) for name in _DROP_DATA if getattr(obs, name) is not None})


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
                                **{name: z[name] if name in z.files else None for name in _DROP_DATA})


def _optional_float(value) -> float | None:
    """A scalar saved by :func:`save_observation` (NaN: None)."""
    value = float(value)
    return None if np.isnan(value) else value


def _frame_files(record) -> list:
    return [file_stamp(p) for p in (record.left, record.right, record.left_rect, record.right_rect)]


def dataset_fingerprint(m, config, floor_frames: int, check_mount: bool = True) -> str:
    """What every frame of ``m`` depends on besides its own files: calibration, mount (or the frames the
    floor is estimated from) and whether it is checked, the options of the per-frame chain and of the
    visual odometry (the poses of a recording without any), mrstereo's version."""
    mount = mount_entry(m.mount) if m.mount is not None else \
        {"estimated from": [_frame_files(r) for r in m.frames[:floor_frames]]}
    chain = {k: repr(getattr(config, k)) for k in ("preset", "max_disparity_px", "matching", "rejection",
                                                   "obstacles", "free_space", "odometry")}
    return digest({"calibration": m.calibration.to_dict(), "mount": mount, "check_mount": check_mount,
                   "chain": chain, "version": __version__})


def frame_fingerprint(base: str, record) -> str:
    return digest([base, _frame_files(record), list(record.pose), record.pan_rad])


def map_fingerprint(m, frames: list[str], config) -> str:
    """What a map depends on: its frames' fingerprints, every option of ``config`` (a
    :class:`~mrstereo.pipeline.mapper.PipelineConfig`: window, resolution, fusion, range...), the ground truth
    it is compared with."""
    truth = [list(f.true_pose) if f.true_pose is not None else None for f in m.frames]
    gt = [file_stamp(p) for p in ros_map_files(m.ground_truth_map)] if m.ground_truth_map is not None else None
    return digest({"frames": frames, "config": repr(config), "ground_truth": gt, "true_poses": truth})



def output_owner(folder: Path) -> str | None:
    """The dataset root recorded in an output folder's ``dataset.json`` ("" for a folder without one)."""
    if not folder.exists():
        return None
    try:
        return str(json.loads((folder / DATASET_RECORD).read_text(encoding="utf-8"))["root"])
    except (OSError, ValueError, KeyError, TypeError):
        return ""


def bag_fingerprint(source, config, check_mount: bool) -> str:
    """What the map of a bag (a :class:`~mrstereo.recordings.bag.BagSource`) depends on: its files, topics
    and mount, every option of ``config``, the mount check, mrstereo's version."""
    root = Path(source.root)
    files = sorted(p for p in root.iterdir() if p.is_file()) if root.is_dir() else [root]
    return digest({"bag": [file_stamp(p) for p in files],
                   "topics": [source.left_topic, source.right_topic, source.pose_source, source.mount_source],
                   "mount": mount_entry(source.mount) if source.mount is not None else None,
                   "config": repr(config), "check_mount": check_mount, "version": __version__})


def claim_folder(folder: Path, root, manifest) -> None:
    """Mark ``folder`` as the output of the recording at ``root`` (its ``dataset.json``) unless it is."""
    if output_owner(folder) != str(root):
        with atomic_write(folder / DATASET_RECORD) as tmp:
            tmp.write_text(json.dumps({"root": str(root), "manifest": str(manifest)}) + "\n")


def output_names(manifests, out: Path) -> list[str]:
    """One output folder name per dataset, never shared: the dataset folder's name, or with a hash of its
    path (``ds-1a2b3c4d``) when another dataset of the run has that name or the folder already holds
    something else (another dataset's results, or anything not written by a batch)."""
    bases = [(m.root.parent.name if m.root.name == "mav0" else m.root.name) or "dataset"    # EuRoC: the sequence
             for m in manifests]
    count = Counter(bases)
    names = []
    for m, base in zip(manifests, bases):
        if count[base] > 1 or output_owner(out / base) not in (None, str(m.root)):
            base = f"{base}-{hashlib.sha256(str(m.root).encode()).hexdigest()[:8]}"
            if output_owner(out / base) not in (None, str(m.root)):
                raise ValueError(f"out_dir {out}: the folder {base} holds other results; choose another output "
                                 "folder")
        names.append(base)
    clash = [n for n, k in Counter(names).items() if k > 1]
    if clash:
        raise ValueError(f"two datasets would share the output folder {out / clash[0]}; rename one of them")
    return names
