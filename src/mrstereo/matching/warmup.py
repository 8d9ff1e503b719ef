"""Load or compile every kernel of the matcher before the first frame (:func:`warm_up`).

numba compiles a kernel on its first call and keeps the machine code in its cache (``__pycache__``
beside the sources): the first run after an install or an upgrade compiles for minutes, later
runs load in seconds. :func:`warm_up` makes both happen on a tiny synthetic pair, so a robot's
first frame is matched at full speed. The whole chain: :func:`mrstereo.warm_up`; docs/speed.md
("First run"). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import numpy as np

from . import _band_kernels, _guard_kernels, _postfilter_kernels, _refine_kernels, _union_kernels
from .cost import match_prepared, prepare_gray, refine_candidates
from .disparity import DisparityResult, compute_disparity

__all__ = ["warm_up", "warm_pair", "cache_is_cold", "KERNEL_MODULES"]

KERNEL_MODULES = (_band_kernels, _refine_kernels, _union_kernels, _postfilter_kernels, _guard_kernels)
"""The matcher's kernel modules."""

WARM_MAX_DISPARITY_PX = 64.0
"""The tiny pair's search: three levels (decimations 1, 2, 4, the coarsest refined) and the near guard's own
level (decimation 8)."""


def warm_pair(seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """A 96 x 256 uint8 pair that reaches every kernel of :func:`compute_disparity` at ``max_disparity_px =
    64``: a textured background at disparity 6 (finest level), a box at 45 px (the coarsest, refined level)
    and a box at 90 px, past the near limit (the near guard's clusters, confirmation and margins)."""
    rng = np.random.default_rng(seed)
    h, w = 96, 256
    right = rng.integers(0, 256, (h, w), dtype=np.uint8)
    disparity = np.full((h, w), 6, np.intp)
    disparity[20:70, 60:100] = 45
    disparity[24:80, 150:220] = 90
    xs = np.arange(w)[None, :] - disparity
    left = np.where(xs >= 0, np.take_along_axis(right, np.clip(xs, 0, w - 1), axis=1),
                    rng.integers(0, 256, (h, w), dtype=np.uint8)).astype(np.uint8)
    return left, right


def warm_up(presets=("robust", "mapping")) -> list[DisparityResult]:
    """Load (or, the first time, compile) every kernel :func:`compute_disparity` runs with ``presets``.

    Runs each preset on :func:`warm_pair` and the refinement's three paths (scattered pixels, row
    strips, boxes) once; a second call takes milliseconds. Returns the presets' results (a too-near
    region found, for the tests).
    """
    left, right = warm_pair()
    results = [compute_disparity(left, right, max_disparity_px=WARM_MAX_DISPARITY_PX, preset=preset)
               for preset in presets]
    pair = [prepare_gray(image.astype(np.float32), kind="xsobel", cap=7, window=9, cost="zncc")
            for image in (left, right)]
    coarse = np.full(left.shape, 6.0, np.float32)
    sparse = np.zeros(left.shape, bool)
    sparse[10, 10] = True
    dense = np.ones(left.shape, bool)
    for want, boxes in ((sparse, None), (dense, None), (dense, [(0, left.shape[0], 0, left.shape[1])])):
        refine_candidates(*pair, coarse, want, half_px=3, max_cost=0.6, boxes=boxes)
    match_prepared(*pair, d_lo=0, d_hi=8, rows=(0, left.shape[0]), cols=(0, left.shape[1]), right_check=True)
    return results


def cache_is_cold(modules=KERNEL_MODULES) -> bool:
    """True when some kernel module has nothing in numba's cache for its current source (a fresh install,
    an upgrade, a cleared cache): :func:`warm_up` will then compile, for minutes."""
    for module in modules:
        cached = False
        for value in vars(module).values():
            cache = getattr(value, "_cache", None)
            index = getattr(getattr(cache, "_cache_file", None), "_load_index", None)
            if index is not None and index():
                cached = True
                break
        if not cached:
            return True
    return False
