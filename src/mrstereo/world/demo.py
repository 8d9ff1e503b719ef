"""The world part of ``mrstereo demo``: render a few frames and write images and GT figures."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .. import _checks
from ..io import write_image
from .dataset import _PANS
from .figures import save_disparity_figure, save_map_figure, save_stereo_figure
from .groundtruth import ground_truth_map
from .render import default_stereo, render_stereo_frame
from .scene import default_scene

__all__ = ["write_world_demo"]


def write_world_demo(out_dir: str | os.PathLike, *, seed: int = 0, n_stops: int = 2, stop_spacing_m: float = 3.0,
                     width: int = 320, height: int = 240, progress: bool = True) -> list[Path]:
    """Render the default corridor at ``n_stops`` stops (front, +45, -45 degree views) and write PNGs.

    The stops lie on the corridor centre line, ``stop_spacing_m`` apart from the origin.

    Per frame: ``frame_K_left_raw.png`` ... (the four images), ``frame_K_images.png``
    (raw and rectified pairs) and ``frame_K_gt_disparity.png``; once:
    ``gt_map.png`` with the robot path. Existing files of the same names are replaced.

    Returns
    -------
    list of Path
        The files written.
    """
    from tqdm import tqdm

    n_stops = _checks.positive_int("n_stops", n_stops)
    stop_spacing_m = _checks.finite_number("stop_spacing_m", stop_spacing_m, positive=True)
    out_dir = Path(out_dir)
    if out_dir.exists() and not out_dir.is_dir():
        raise ValueError(f"output {out_dir} exists and is not a directory")
    scene, stereo = default_scene(seed), default_stereo(width, height)
    poses = np.array([[stop_spacing_m * k, 0.0, 0.0] for k in range(n_stops)])
    written: list[Path] = []
    jobs = [(pose, pan) for pose in poses for pan in _PANS]
    max_d = stereo.focal_px * stereo.baseline_m / 0.5
    for k, (pose, pan) in enumerate(tqdm(jobs, desc="rendering demo", unit="frame", disable=not progress)):
        frame = render_stereo_frame(scene, stereo, pose=tuple(pose), pan_rad=pan, seed=seed * 1000 + k)
        view = {0.0: "front"}.get(pan, "left 45 deg" if pan > 0 else "right 45 deg")
        base = out_dir / f"frame_{k:02d}"
        for name, image in (("left_raw", frame.raw_left), ("right_raw", frame.raw_right),
                            ("left_rect", frame.left_rect), ("right_rect", frame.right_rect)):
            path = Path(f"{base}_{name}.png")
            write_image(path, image)
            written.append(path)
        title = f"frame {k}: pose x={pose[0]:.2f} m y={pose[1]:.2f} m, {view}"
        written.append(save_stereo_figure(f"{base}_images.png", {
            "raw left": frame.raw_left, "raw right": frame.raw_right,
            "rectified left": frame.left_rect, "rectified right": frame.right_rect}, title=title))
        written.append(save_disparity_figure(f"{base}_gt_disparity.png", frame.disparity_px,
                                             title=f"ground-truth disparity, {title}",
                                             max_disparity_px=max_d))
    written.append(save_map_figure(out_dir / "gt_map.png", ground_truth_map(scene), poses=np.asarray(poses),
                                   title="ground-truth map of the corridor (12 m x 6 m, 5 cm cells)"))
    return written
