"""Run matchers on benchmark scenes and tabulate the metrics side by side.

:func:`evaluate_scenes` reads each scene, runs every method of :data:`METHODS` with the scene's
search range (``"mrstereo"``: the ``"robust"`` preset; ``"mrstereo-paper"``: NSSD + WTA as eq. 9-10;
the OpenCV baselines), scores and times it. Each method first runs once on a 64-row strip, so
one-off costs (numba compilation, OpenCV threads) are not charged to a scene. User guide:
docs/evaluation.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import json
import math
import platform
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import asdict, dataclass, replace

import cv2
import numpy as np

from .baselines import BASELINES
from .datasets import Scene, load_scenes
from .metrics import DisparityMetrics, disparity_metrics

__all__ = ["METHODS", "EvaluationRow", "EvaluationReport", "evaluate_scenes", "run_method"]

METHODS = ("mrstereo", "mrstereo-paper", "StereoBM", "StereoSGBM")


def _mrstereo(preset: str) -> Callable[..., np.ndarray]:
    def run(left, right, *, max_disparity_px):
        from ..matching import compute_disparity
        return compute_disparity(left, right, max_disparity_px=max_disparity_px, preset=preset).disparity_px
    return run


_RUNNERS: dict[str, Callable[..., np.ndarray]] = {
    "mrstereo": _mrstereo("robust"),
    "mrstereo-paper": _mrstereo("paper"),
    **BASELINES,
}


def run_method(method: str, scene: Scene, *, max_disparity_px: int | None = None) -> np.ndarray:
    """Disparity map (float32 px, NaN invalid) of one method on one scene.

    ``max_disparity_px`` overrides the scene's search range.
    """
    if method not in _RUNNERS:
        raise ValueError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}")
    max_d = scene.max_disparity_px if max_disparity_px is None else max_disparity_px
    out = np.asarray(_RUNNERS[method](scene.left, scene.right, max_disparity_px=max_d), dtype=np.float32)
    if out.shape != scene.shape:
        raise RuntimeError(f"method {method} returned shape {out.shape} for a {scene.shape} scene")
    return out


@dataclass(frozen=True)
class EvaluationRow:
    """One method on one scene."""

    scene: str
    layout: str
    directory: str
    method: str
    width_px: int
    height_px: int
    max_disparity_px: int
    seconds: float
    metrics: DisparityMetrics


def _fmt(value: float, digits: int = 1) -> str:
    return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) else f"{value:.{digits}f}"


def _nan_to_none(obj):
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_nan_to_none(v) for v in obj]
    return obj


@dataclass(frozen=True)
class EvaluationReport:
    """All rows of an evaluation (scene-major: all methods of the first scene, then the next), with
    the ``methods`` and ``scenes`` in the order evaluated, and markdown and JSON views.
    """

    rows: tuple[EvaluationRow, ...]
    methods: tuple[str, ...]
    scenes: tuple[str, ...]

    def row(self, scene: str, method: str) -> EvaluationRow:
        """The row of one scene label (``Scene.name``) and method."""
        for r in self.rows:
            if r.scene == scene and r.method == method:
                return r
        raise KeyError(f"no row for scene {scene!r} and method {method!r}")

    def mean(self, method: str) -> dict[str, float]:
        """Unweighted mean over scenes of the headline numbers of one method."""
        rows = [r for r in self.rows if r.method == method]
        if not rows:
            raise KeyError(f"no rows for method {method!r}")

        def avg(get):
            return float(np.mean([get(r) for r in rows]))
        return {
            "bad_2_dense_pct": avg(lambda r: r.metrics.dense.bad_2_pct),
            "bad_2_estimated_pct": avg(lambda r: r.metrics.estimated.bad_2_pct),
            "bad_1_dense_pct": avg(lambda r: r.metrics.dense.bad_1_pct),
            "bad_1_estimated_pct": avg(lambda r: r.metrics.estimated.bad_1_pct),
            "avg_abs_error_estimated_px": avg(lambda r: r.metrics.estimated.avg_abs_error_px),
            "density_pct": avg(lambda r: r.metrics.density_pct),
            "seconds": avg(lambda r: r.seconds),
        }

    def to_markdown(self) -> str:
        """Two tables: scenes x methods (headline numbers) and every metric per row."""
        lines = ["## Disparity accuracy", "",
                 "Cells: bad-2 % dense (invalid = bad) / bad-2 % among estimated pixels / "
                 "density % / seconds. Non-occluded pixels where the dataset has a mask, else all "
                 "ground-truth pixels.", ""]
        lines.append("| scene | layout | size | max d |" + "".join(f" {m} |" for m in self.methods))
        lines.append("|---|---|---|---|" + "---|" * len(self.methods))
        first = {}
        for r in self.rows:
            first.setdefault(r.scene, r)
        for scene in self.scenes:
            head = first[scene]
            cells = []
            for method in self.methods:
                m = self.row(scene, method)
                cells.append(f"{_fmt(m.metrics.dense.bad_2_pct)} / {_fmt(m.metrics.estimated.bad_2_pct)} / "
                             f"{_fmt(m.metrics.density_pct, 0)} / {_fmt(m.seconds, 3)}")
            lines.append(f"| {scene} | {head.layout} | {head.width_px}x{head.height_px} | "
                         f"{head.max_disparity_px} | " + " | ".join(cells) + " |")
        means = [self.mean(m) for m in self.methods]
        lines.append("| **mean** | | | | " + " | ".join(
            f"{_fmt(s['bad_2_dense_pct'])} / {_fmt(s['bad_2_estimated_pct'])} / {_fmt(s['density_pct'], 0)} / "
            f"{_fmt(s['seconds'], 3)}" for s in means) + " |")
        lines += ["", "## All metrics", "",
                  "bad-t: % of pixels with |d - d_gt| > t px; dense counts pixels without an estimate as bad "
                  "(and as d = 0 for avg/RMS); est. = among estimated pixels only.", "",
                  "| scene | method | region | density % | bad-0.5 | bad-1 | bad-2 | bad-4 | avg px | RMS px "
                  "| bad-0.5 est. | bad-1 est. | bad-2 est. | bad-4 est. | avg est. px | RMS est. px | seconds |",
                  "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in self.rows:
            d, e = r.metrics.dense, r.metrics.estimated
            nums = [d.bad_0_5_pct, d.bad_1_pct, d.bad_2_pct, d.bad_4_pct]
            nums_e = [e.bad_0_5_pct, e.bad_1_pct, e.bad_2_pct, e.bad_4_pct]
            lines.append(
                f"| {r.scene} | {r.method} | {r.metrics.region} | {_fmt(r.metrics.density_pct)} | "
                + " | ".join(_fmt(v) for v in nums) + f" | {_fmt(d.avg_abs_error_px, 2)} | {_fmt(d.rms_error_px, 2)} | "
                + " | ".join(_fmt(v) for v in nums_e) + f" | {_fmt(e.avg_abs_error_px, 2)} | "
                f"{_fmt(e.rms_error_px, 2)} | {_fmt(r.seconds, 3)} |")
        return "\n".join(lines) + "\n"

    def to_dict(self) -> dict:
        """JSON-ready dict (NaN -> None)."""
        from importlib.metadata import PackageNotFoundError, version
        try:
            mrstereo_version = version("mrstereo")
        except PackageNotFoundError:
            mrstereo_version = "unknown"
        data = {
            "methods": list(self.methods),
            "scenes": list(self.scenes),
            "rows": [asdict(r) for r in self.rows],
            "mean": {m: self.mean(m) for m in self.methods},
            "environment": {"mrstereo": mrstereo_version, "opencv": cv2.__version__,
                            "numpy": np.__version__, "python": platform.python_version(),
                            "machine": platform.machine()},
        }
        return _nan_to_none(data)

    def to_json(self, *, indent: int = 2) -> str:
        """The report as a JSON string (NaN written as null)."""
        return json.dumps(self.to_dict(), indent=indent, allow_nan=False)


def _check_methods(methods) -> tuple[str, ...]:
    if isinstance(methods, str):
        methods = (methods,)
    methods = tuple(methods)
    if not methods:
        raise ValueError("methods must name at least one method")
    unknown = [m for m in methods if m not in _RUNNERS]
    if unknown:
        raise ValueError(f"unknown method(s) {', '.join(map(repr, unknown))}; expected some of {', '.join(METHODS)}")
    if len(set(methods)) != len(methods):
        raise ValueError(f"methods contains duplicates: {methods}")
    return methods


def _warm_up(method: str, scene: Scene, max_d: int) -> None:
    rows = min(scene.shape[0], 64)
    strip = replace(scene, left=scene.left[:rows], right=scene.right[:rows],
                    gt_disparity_px=scene.gt_disparity_px[:rows], nonocc_mask=None)
    try:
        run_method(method, strip, max_disparity_px=max_d)
    except Exception:  # noqa: BLE001 -- a warm-up failure shows again, with its message, on the real call
        pass


def _evaluate_job(job: tuple) -> EvaluationRow:
    """One (scene, method) run: the unit of work sent to a Dask worker or run in-process."""
    label, scene, method, max_d = job
    start = time.perf_counter()
    disparity = run_method(method, scene, max_disparity_px=max_d)
    seconds = time.perf_counter() - start
    return EvaluationRow(
        scene=label, layout=scene.layout, directory=str(scene.directory), method=method,
        width_px=scene.shape[1], height_px=scene.shape[0], max_disparity_px=int(max_d), seconds=seconds,
        metrics=disparity_metrics(disparity, scene.gt_disparity_px, nonocc_mask=scene.nonocc_mask))


def evaluate_scenes(dirs: Iterable, *, methods: Sequence[str] = METHODS, max_disparity_px: int | None = None,
                    progress: bool = True, workers: int | None = None, scheduler=None,
                    processes: bool = False) -> EvaluationReport:
    """Evaluate matchers on benchmark scene directories.

    Parameters
    ----------
    dirs : iterable of str or Path
        Scene directories :func:`~mrstereo.evaluation.datasets.load_scenes` reads (an mrstereo
        dataset contributes every frame with ground-truth disparity).
    methods : sequence of str
        Some of :data:`METHODS`.
    max_disparity_px : int, optional
        Search range for every scene (default: each scene's own range).
    progress : bool
        Show a tqdm progress bar on stderr.
    workers, scheduler, processes :
        Spread the (scene, method) runs as :func:`mrstereo._executor.map_ordered` does;
        per-run times on workers include each worker's first numba compilation.

    Returns
    -------
    EvaluationReport
    """
    from .._executor import map_ordered

    methods = _check_methods(methods)
    dirs = list(dirs)
    if not dirs:
        raise ValueError("dirs must name at least one scene directory")
    if max_disparity_px is not None:
        from .. import _checks
        max_disparity_px = _checks.positive_int("max_disparity_px", max_disparity_px)
    scenes = [scene for d in dirs for scene in load_scenes(d)]  # fail on a bad directory before any work
    labels = []
    for scene in scenes:
        label = scene.name
        while label in labels:
            label = f"{scene.layout}/{label}" if not label.startswith(scene.layout) else f"{label}'"
        labels.append(label)
    if workers is None and scheduler is None:
        for method in methods:      # compile the kernels before timing (in-process only)
            _warm_up(method, scenes[0], max_disparity_px or scenes[0].max_disparity_px)
    jobs = [(label, scene, method, max_disparity_px or scene.max_disparity_px)
            for label, scene in zip(labels, scenes) for method in methods]
    rows = map_ordered(_evaluate_job, jobs, workers=workers, scheduler=scheduler, processes=processes,
                       progress=progress,
                       desc="evaluate", label=lambda job: f"{job[0]} {job[2]}", unit="run")
    return EvaluationReport(rows=tuple(rows), methods=methods, scenes=tuple(labels))
