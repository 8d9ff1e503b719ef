"""Area correlation on one image pair and one disparity band (paper section 3.3).

The per-level solver of the multi-range matcher: image pre-filters, the NSSD cost of eq. (9)
(or ZNCC), winner-take-all, eq. (10), and the full-resolution refinement. The paper puts
the right pixel at ``x + d``; mrstereo uses ``x_right = x_left - d`` with ``d >= 0``, so eq. (9) is
evaluated on ``I_R(x + i - d, y + j)`` (docs/conventions.md).
"""
from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import NamedTuple

import cv2
import numpy as np

from . import _band_kernels, _refine_kernels
from .config import COSTS, PREFILTERS

__all__ = ["BandMatch", "PreparedImage", "prefilter", "prepare", "match_band", "match_prepared",
           "match_checked", "CheckedMatch", "prepare_gray", "refine_candidates", "PREFILTERS", "COSTS"]


@dataclass(frozen=True)
class BandMatch:
    """Raw winner-take-all result of one band search (integer + sub-pixel parts).

    Attributes
    ----------
    disparity_int : ndarray int32 (H, W)
        Winner of eq. (10) in pixels of the searched images; -1 where not searched.
    subpixel_px : ndarray float32 (H, W)
        Offset in [-0.5, 0.5] of the parabola through the costs at ``d - 1, d, d + 1``.
    best_cost, second_cost : ndarray float32 (H, W)
        Cost of the winner and the lowest cost at least 2 px away from it (inf if none).
    right_disparity_int : ndarray int32 (H, W) or None
        Winner for each right-image pixel (for the left-right check), -1 if none.
    d_lo, d_hi : int
        The band searched.
    """

    disparity_int: np.ndarray
    subpixel_px: np.ndarray
    best_cost: np.ndarray
    second_cost: np.ndarray
    right_disparity_int: np.ndarray | None
    d_lo: int
    d_hi: int


def prefilter(image: np.ndarray, kind: str, *, cap: int = 31) -> np.ndarray:
    """Pre-filter a gray image before the cost.

    Parameters
    ----------
    image : ndarray float32 (H, W)
        Gray image.
    kind : {"none", "xsobel"}
        ``"xsobel"``: horizontal 3x3 Sobel derivative / 4, rounded and clipped to ``[-cap, cap]``
        (OpenCV StereoBM's default pre-filter; it removes the gain/offset differences of the two
        cameras); ``"none"``: the raw intensities (eq. 9).
    cap : int
        Clipping bound (grey levels).

    Returns
    -------
    ndarray (H, W)
        int32 for integer-valued results (the kernel's running sums are then exact), else
        float64.
    """
    if kind == "none":
        out = image
    elif kind == "xsobel":
        out = np.clip(np.rint(cv2.Sobel(image, cv2.CV_32F, 1, 0, ksize=3,
                                        borderType=cv2.BORDER_REPLICATE) / 4.0), -cap, cap)
    else:
        raise ValueError(f"prefilter must be one of {PREFILTERS}, got {kind!r}")
    if np.array_equal(out, np.rint(out)) and np.abs(out).max(initial=0) < 2 ** 12:
        return out.astype(np.int32)
    return out.astype(np.float64)


def _accumulator_dtype(left: np.ndarray, right: np.ndarray, window: int):
    """float32 when every running sum is an integer below 2**24 (exact), else float64."""
    if left.dtype.kind in "iu" and right.dtype.kind in "iu":
        peak = max(int(np.abs(left).max(initial=0)), int(np.abs(right).max(initial=0)))
        if window * window * peak * peak * 2 < 2 ** 24:
            return np.float32
    return np.float64


_SCRATCH = threading.local()


def scratch(name: str, shape: tuple[int, ...], dtype) -> np.ndarray:
    """A buffer of the calling thread, kept from call to call per name, shape and dtype (contents
    undefined): the per-frame work allocates no full-size temporary (one set per image size)."""
    buffers = _SCRATCH.__dict__.setdefault("buffers", {})
    key = (name, tuple(shape), np.dtype(dtype).str)
    if key not in buffers:
        if len(buffers) > 64:            # many image sizes: start again
            buffers.clear()
        buffers[key] = np.empty(shape, dtype)
    return buffers[key]


def _strips(n_strips: int | None, n_rows: int) -> int:
    if n_strips is None:
        import numba
        n_strips = numba.get_num_threads()
    return max(1, min(int(n_strips), n_rows))


_KIND = {"nssd": _band_kernels.NSSD, "zncc": _band_kernels.ZNCC}


@dataclass(frozen=True)
class PreparedImage:
    """A pre-filtered image ready for the kernels: padded by the window radius
    (replicated border) in the accumulator's dtype, with its window terms ``a``, ``b``
    (see :mod:`._band_kernels`)."""

    padded: np.ndarray
    a: np.ndarray
    b: np.ndarray
    window: int
    cost: str

    @property
    def kind(self) -> int:
        """The kernels' code of the cost (``_band_kernels.NSSD`` or ``ZNCC``)."""
        return _KIND[self.cost]

    @property
    def shape(self) -> tuple[int, int]:
        return self.a.shape

    @property
    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(padded, a, b)``, as the kernels take a prepared image."""
        return self.padded, self.a, self.b


def prepare(image: np.ndarray, *, window: int, cost: str, dtype=np.float32) -> PreparedImage:
    """Pad a pre-filtered ``image`` and compute its window terms for :func:`match_prepared`.

    Parameters
    ----------
    image : ndarray (H, W)
        Pre-filtered image (:func:`prefilter`).
    window : int
        Odd window size.
    cost : {"nssd", "zncc"}
        The cost the terms are for.
    dtype : numpy dtype
        Accumulator type: float32 when the window sums are exact integers, else float64.
    """
    if cost not in COSTS:
        raise ValueError(f"cost must be one of {COSTS}, got {cost!r}")
    r = window // 2
    image = np.ascontiguousarray(image, dtype=dtype)
    padded = cv2.copyMakeBorder(image, r, r, r, r, cv2.BORDER_REPLICATE)
    return _with_terms(padded, window, cost)


def prepare_gray(gray: np.ndarray, *, kind: str, cap: int, window: int, cost: str) -> PreparedImage:
    """Pre-filter (:func:`prefilter`) a float32 gray image and prepare it, fused for
    ``"xsobel"`` (its values are integers in ``[-cap, cap]``: float32 sums are exact).

    Parameters
    ----------
    gray : ndarray float32 (H, W)
        Gray image.
    kind, cap
        Pre-filter and its clip bound (:func:`prefilter`).
    window, cost
        As :func:`prepare`.
    """
    if kind != "xsobel" or window * window * cap * cap * 2 >= 2 ** 24:
        filtered = prefilter(gray, kind, cap=cap)
        return prepare(filtered, window=window, cost=cost, dtype=_accumulator_dtype(filtered, filtered, window))
    r = window // 2
    h, w = gray.shape
    padded = np.empty((h + 2 * r, w + 2 * r), np.float32)
    _band_kernels.xsobel_padded(np.ascontiguousarray(gray, dtype=np.float32), r, np.float32(cap), padded)
    return _with_terms(padded, window, cost)


def _with_terms(padded: np.ndarray, window: int, cost: str) -> PreparedImage:
    r = window // 2
    shape = (padded.shape[0] - 2 * r, padded.shape[1] - 2 * r)
    a = np.empty(shape, padded.dtype)
    b = np.empty(shape, np.float32)
    _band_kernels.window_terms(padded, r, cost == "zncc", a, b)
    return PreparedImage(padded, a, b, window, cost)


def _span(name: str, span, size: int) -> tuple[int, int]:
    """A half-open range ``(a, b)`` with ``0 <= a <= b <= size`` (the kernels write where it says)."""
    try:
        a, b = (int(v) for v in span)
    except (TypeError, ValueError):
        raise TypeError(f"{name} must be two integers (start, stop), got {span!r}") from None
    if not 0 <= a <= b <= size:
        raise ValueError(f"{name} must satisfy 0 <= start <= stop <= {size}, got ({a}, {b})")
    return a, b


def _checked_band(left: PreparedImage, right: PreparedImage, d_lo, d_hi, rows, cols):
    """The band search's arguments checked before a kernel sees them: ``(d_lo, d_hi, rows, cols)``.

    Both images prepared alike and of one size; ``0 <= d_lo <= d_hi``; ``d_hi`` above the widest
    possible disparity (``width - 1``: a pixel ``x`` searches ``d <= x``) is clipped, which changes no
    result and bounds the kernel's buffers.
    """
    for name, image in (("left", left), ("right", right)):
        if not isinstance(image, PreparedImage):
            raise TypeError(f"{name} must be a PreparedImage (from prepare), got {type(image).__name__}")
    if left.shape != right.shape or left.window != right.window or left.padded.dtype != right.padded.dtype:
        raise ValueError(f"left and right must be prepared alike: shapes {left.shape} and {right.shape}, windows "
                         f"{left.window} and {right.window}, dtypes {left.padded.dtype} and {right.padded.dtype}")
    h, w = left.shape
    d_lo, d_hi = int(d_lo), int(d_hi)
    if not 0 <= d_lo <= d_hi:
        raise ValueError(f"disparities must satisfy 0 <= d_lo <= d_hi, got d_lo={d_lo}, d_hi={d_hi}")
    return d_lo, min(d_hi, max(d_lo, w - 1)), _span("rows", rows, h), _span("cols", cols, w)


def match_prepared(left: PreparedImage, right: PreparedImage, *, d_lo: int, d_hi: int,
                   rows: tuple[int, int], cols: tuple[int, int], right_check: bool,
                   n_strips: int | None = None) -> tuple[np.ndarray, ...]:
    """Winner-take-all (eq. 10) over ``[d_lo, d_hi]`` on prepared images, raw.

    Parameters
    ----------
    left, right : PreparedImage
        The pair (:func:`prepare`).
    d_lo, d_hi : int
        The band searched (pixels of these images).
    rows, cols : (int, int)
        Half-open rows and columns to evaluate.
    right_check : bool
        Also find the right image's winners.
    n_strips : int, optional
        Row strips run in parallel (default: numba's thread count).

    Returns
    -------
    tuple of ndarray (H, W)
        ``(disparity_int, subpixel_px, best_cost, second_cost, right_disparity_int)`` as
        :class:`BandMatch`, with BIG (not inf) where a cost is absent.
    """
    d_lo, d_hi, rows, cols = _checked_band(left, right, d_lo, d_hi, rows, cols)
    h, w = left.shape
    big = _band_kernels.BIG
    out = (_outside((h, w), np.int32, rows, cols, -1), _outside((h, w), np.float32, rows, cols, 0.0),
           _outside((h, w), np.float32, rows, cols, big), _outside((h, w), np.float32, rows, cols, big),
           _outside((h, w), np.int32, rows, (0, w) if right_check else (0, 0), -1))
    if rows[1] > rows[0] and cols[1] > cols[0]:
        _band_kernels.band_winners(left.arrays, right.arrays, left.window // 2, left.kind == _band_kernels.ZNCC,
                                   (d_lo, d_hi), (*rows, *cols), _strips(n_strips, rows[1] - rows[0]),
                                   bool(right_check), out)
    return out


_NONE = np.zeros((1, 1), np.float32)      # an output the kernel is told not to write


def _outside(shape: tuple[int, int], dtype, rows: tuple[int, int], cols: tuple[int, int], value) -> np.ndarray:
    """A new array whose pixels outside ``rows`` x ``cols`` hold ``value`` (the kernel writes the inside;
    an empty span: everywhere)."""
    out = np.empty(shape, dtype)
    if rows[1] <= rows[0] or cols[1] <= cols[0]:
        out.fill(value)
        return out
    out[:rows[0]] = value
    out[rows[1]:] = value
    out[rows[0]:rows[1], :cols[0]] = value
    out[rows[0]:rows[1], cols[1]:] = value
    return out


class CheckedMatch(NamedTuple):
    """Result of :func:`match_checked` (float32 (H, W) maps, pixels of the searched images)."""

    disparity_px: np.ndarray
    """Checked winner (+ parabola offset), NaN where rejected."""
    confidence: np.ndarray
    """``clip(1 - c1 / c2, 0, 1)``, 0 where rejected."""
    alt_px: np.ndarray | None
    """With ``alt_band``: the band's best strict local minimum (integer disparity, NaN none)."""
    alt_cost: np.ndarray | None
    """Its cost (BIG where none)."""
    best_cost: np.ndarray | None
    """With ``alt_band``: the winner's cost ``c1`` (whatever the checks)."""


def match_checked(left: PreparedImage, right: PreparedImage, *, d_lo: int, d_hi: int,
                  rows: tuple[int, int], cols: tuple[int, int], lr_max_diff_px: float | None,
                  uniqueness_ratio: float, max_cost: float | None, subpixel: bool,
                  alt_band: tuple[int, int] | None = None, n_strips: int | None = None) -> CheckedMatch:
    """Band search (eq. 10) with the checks fused into the kernel.

    Returns the winner (+ parabola offset when ``subpixel``) where it passes the left-right
    check (``|d_L - d_R| <= lr_max_diff_px``), the uniqueness ratio and the maximum cost
    (each off when None / 0), else NaN; the confidence ``clip(1 - c1 / c2, 0, 1)`` (0 where
    NaN). Outside ``rows`` NaN.

    Parameters
    ----------
    left, right, d_lo, d_hi, rows, cols, n_strips
        As :func:`match_prepared`.
    lr_max_diff_px, uniqueness_ratio, max_cost : float or None
        The checks (:class:`.config.AcceptanceConfig`).
    subpixel : bool
        Add the parabola offset.
    alt_band : (int, int), optional
        ``(lo, hi)``: also the lowest strict local minimum of the cost at disparities ``lo ..
        hi`` (the band without its search margins), whatever the winner and the checks, with
        its cost, and the winner's cost (the cross-band ambiguity test,
        :func:`mrstereo.matching.disparity.compute_disparity`).
    """
    d_lo, d_hi, rows, cols = _checked_band(left, right, d_lo, d_hi, rows, cols)
    h, w = left.shape
    disparity = np.empty((h, w), np.float32)
    confidence = np.empty((h, w), np.float32)
    disparity[:rows[0]] = np.nan
    disparity[rows[1]:] = np.nan
    confidence[:rows[0]] = 0.0
    confidence[rows[1]:] = 0.0
    alt_px = alt_cost = best_cost = None
    if alt_band is not None:
        alt_px = _outside((h, w), np.float32, rows, cols, np.nan)
        alt_cost = _outside((h, w), np.float32, rows, cols, _band_kernels.BIG)
        best_cost = _outside((h, w), np.float32, rows, cols, _band_kernels.BIG)
    checks = (-1.0 if lr_max_diff_px is None else float(lr_max_diff_px), float(uniqueness_ratio),
              -1.0 if max_cost is None else float(max_cost), bool(subpixel))
    if rows[1] > rows[0] and cols[1] > cols[0]:
        _band_kernels.band_checked(left.arrays, right.arrays, left.window // 2, left.kind == _band_kernels.ZNCC,
                                   (d_lo, d_hi), (*rows, *cols), _strips(n_strips, rows[1] - rows[0]), checks,
                                   (disparity, confidence),
                                   (1, 0) if alt_band is None else (int(alt_band[0]), int(alt_band[1])),
                                   (_NONE, _NONE, _NONE) if alt_band is None else (alt_px, alt_cost, best_cost))
    else:
        disparity[rows[0]:rows[1]] = np.nan
        confidence[rows[0]:rows[1]] = 0.0
    return CheckedMatch(disparity, confidence, alt_px, alt_cost, best_cost)


def match_band(left: np.ndarray, right: np.ndarray, *, d_lo: int, d_hi: int, window: int = 9,
               cost: str = "nssd", rows: tuple[int, int] | None = None,
               cols: tuple[int, int] | None = None, right_check: bool = False,
               n_strips: int | None = None) -> BandMatch:
    """Winner-take-all (eq. 10) of the window cost (eq. 9 or ZNCC) over one band.

    Parameters
    ----------
    left, right : ndarray (H, W)
        Rectified, pre-filtered images of the same size (int32 or float64, see
        :func:`prefilter`).
    d_lo, d_hi : int
        Disparities searched, ``0 <= d_lo <= d_hi``; a pixel ``x`` searches only
        ``d <= x`` (its match must lie inside the right image).
    window : int
        Odd window size ``W = 2 w + 1``.
    cost : {"nssd", "zncc"}
        ``"nssd"`` is eq. (9); ``"zncc"`` is ``1 - `` zero-mean normalized
        cross-correlation, invariant to gain and offset.
    rows, cols : (int, int), optional
        Half-open row and column ranges to evaluate (area of interest, section 3.1);
        the rest of the output is invalid.
    right_check : bool
        Also compute the right image's winners (for the left-right check).
    n_strips : int, optional
        Row strips run in parallel (default: numba's thread count).
    """
    left, right = np.asarray(left), np.asarray(right)
    if left.ndim != 2 or left.shape != right.shape:
        raise ValueError(f"left and right must be 2-D images of one size, got {left.shape} and {right.shape}")
    h, w = left.shape
    rows = (0, h) if rows is None else rows
    cols = (0, w) if cols is None else cols
    if cost not in COSTS:
        raise ValueError(f"cost must be one of {COSTS}, got {cost!r}")
    if isinstance(window, bool) or not isinstance(window, (int, np.integer)) or window < 1 or window % 2 == 0:
        raise ValueError(f"window must be an odd number of pixels >= 1, got {window!r}")
    dtype = _accumulator_dtype(left, right, window)
    pl = prepare(left, window=window, cost=cost, dtype=dtype)
    pr = prepare(right, window=window, cost=cost, dtype=dtype)
    disp, sub, c1, c2, disp_right = match_prepared(pl, pr, d_lo=d_lo, d_hi=d_hi, rows=rows, cols=cols,
                                                   right_check=right_check, n_strips=n_strips)
    c1[c1 >= _band_kernels.BIG] = np.inf
    c2[c2 >= _band_kernels.BIG] = np.inf
    return BandMatch(disparity_int=disp, subpixel_px=sub, best_cost=c1, second_cost=c2,
                     right_disparity_int=disp_right if right_check else None, d_lo=int(d_lo),
                     d_hi=int(d_hi))


# refine_candidates adds up the windows of single pixels (refine_pixels) when fewer than 1 in
# SPARSE_REFINE_SHARE pixels of the rows spanned are wanted (the near guard's scattered
# candidates), else keeps running sums over those rows (refine_strips): the direct sums cost
# 81 products per pixel and offset, the running sums a few per pixel of the rows spanned, so
# the direct sums are cheaper while the wanted pixels are few (about 2.5 % on the shared
# real scenes at 640x480).
SPARSE_REFINE_SHARE = 40


def refine_candidates(left: PreparedImage, right: PreparedImage, coarse_px: np.ndarray, want: np.ndarray, *, half_px: int,
                      max_cost: float | None = None, rows: tuple[int, int] | None = None, n_strips: int | None = None,
                      boxes=None, into: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Re-score a coarse disparity field at full resolution (beyond the paper).

    The full-resolution cost (eq. 9 or ZNCC) is evaluated at offsets ``[-half_px, half_px]``
    around the coarse field; the best gets the parabola offset, a winner on the edge is invalid.

    Parameters
    ----------
    left, right : PreparedImage
        The full-resolution pre-filtered pair (:func:`prepare`).
    coarse_px : ndarray float32 (H, W)
        Coarse disparity in full-resolution pixels; NaNs take the nearest valid value of
        their row (windows at the edge of a valid region need a shift).
    want : ndarray bool (H, W)
        Pixels to refine.
    half_px : int
        Offsets searched on each side.
    max_cost : float, optional
        Winners costing more become invalid.
    boxes : sequence of (row0, row1, col0, col1), optional
        Half-open boxes holding every wanted pixel: the sums cover each box only (scattered
        clusters), the boxes in parallel. Same results.
    into : (ndarray, ndarray), optional
        ``(disparity_px, cost)`` float32 (H, W), C-contiguous, to write the wanted pixels into
        (``disparity_px`` may be ``coarse_px`` itself); the other pixels keep their values.
        Default: new arrays, NaN and inf elsewhere.

    Returns
    -------
    disparity_px, cost : ndarray float32 (H, W)
        Refined disparity (NaN invalid) and the winner's cost (inf invalid).
    """
    _checked_band(left, right, 0, 0, (0, 0), (0, 0))
    h, w = left.shape
    coarse_px, want = np.asarray(coarse_px), np.asarray(want, dtype=bool)
    if coarse_px.shape != (h, w) or want.shape != (h, w):
        raise ValueError(f"coarse_px and want must have the images' shape {(h, w)}, got {coarse_px.shape} and "
                         f"{want.shape}")
    if isinstance(half_px, bool) or not isinstance(half_px, (int, np.integer)) or half_px < 0:
        raise ValueError(f"half_px must be an integer >= 0, got {half_px!r}")
    half_px = min(int(half_px), w)        # (offsets beyond the image width find nothing)
    r = left.window // 2
    rows = _span("rows", (0, h) if rows is None else rows, h)
    center_pad = scratch("center", (h + 2 * r, w + 2 * r), np.int32)
    _refine_kernels.fill_center(np.ascontiguousarray(coarse_px, dtype=np.float32), r, center_pad)
    if into is None:
        out = np.full((h, w), np.nan, np.float32)
        cost = np.full((h, w), np.inf, np.float32)
    else:
        out, cost = into
        for name, array in (("into disparity_px", out), ("into cost", cost)):
            if array.shape != (h, w) or array.dtype != np.float32 or not array.flags.c_contiguous:
                raise ValueError(f"{name} must be C-contiguous float32 {(h, w)}, got {array.dtype} {array.shape}")
    want = np.ascontiguousarray(want)
    max_cost = -1.0 if max_cost is None else float(max_cost)
    if boxes is not None:
        boxes = np.array(boxes, np.int64).reshape(-1, 4)
        boxes[:, 0] = np.maximum(boxes[:, 0], rows[0])
        boxes[:, 1] = np.minimum(boxes[:, 1], rows[1])
        boxes[:, 2] = np.maximum(boxes[:, 2], 0)
        boxes[:, 3] = np.minimum(boxes[:, 3], w)
        threads = _strips(n_strips, h)
        # each box as the tiles holding its wanted pixels (or in row strips: at least one per thread)
        boxes = np.concatenate([_tiles(want, box, r, threads if len(boxes) < threads else 1) for box in boxes
                                if box[1] > box[0] and box[3] > box[2]] or [np.zeros((0, 4), np.int64)])
        # the near guard's fields change every few pixels: products gathered pixel by pixel
        _refine_kernels.refine_boxes(left.arrays, right.arrays, r, left.kind, center_pad, want, boxes, int(half_px),
                                     max_cost, (out, cost))
        return out, cost
    hit = np.flatnonzero(want[rows[0]:rows[1]].any(axis=1))
    if not hit.size:
        return out, cost
    rows = (rows[0] + int(hit[0]), rows[0] + int(hit[-1]) + 1)      # only the rows holding pixels to refine
    if np.count_nonzero(want[rows[0]:rows[1]]) * SPARSE_REFINE_SHARE < (rows[1] - rows[0]) * w:
        ys, xs = np.nonzero(want[rows[0]:rows[1]])
        # xs contiguous (nonzero may return a strided view): one signature of the kernel, compiled once
        _refine_kernels.refine_pixels(left.arrays, right.arrays, r, left.kind, center_pad,
                                      (ys + rows[0], np.ascontiguousarray(xs)),
                                      int(half_px), max_cost, _strips(n_strips, ys.size), (out, cost))
        return out, cost
    # a level's up-sampled field is constant over runs of pixels: products gathered along them, in the
    # tiles that hold wanted pixels
    _refine_kernels.refine_strips(left.arrays, right.arrays, r, left.kind, center_pad, want,
                                  _tiles(want, (*rows, 0, w), r, _strips(n_strips, rows[1] - rows[0])), int(half_px),
                                  max_cost, (out, cost))
    return out, cost


# The dense refinement's tiles: bands of TILE_ROWS rows (running sums restart at each, 2 r rows more
# work), in each the runs of columns holding wanted pixels, runs less than TILE_GAP_COLS apart joined
# (each run costs 2 r columns more). Sums of integer-valued images are exact: any tiling, same results.
TILE_ROWS = 48
TILE_GAP_COLS = 32


def _tiles(want: np.ndarray, box, radius: int, n_threads: int) -> np.ndarray:
    """Boxes ``(row0, row1, col0, col1)`` covering the wanted pixels of ``box``: bands of
    :data:`TILE_ROWS` rows, in each the column runs of wanted pixels (:data:`TILE_GAP_COLS`); or
    ``box`` in one band of rows per thread when the tiles would not save a fifth of the sums."""
    row0, row1, col0, col1 = (int(v) for v in box)
    n_rows = row1 - row0
    if n_rows >= 2 * TILE_ROWS:
        # per band the wanted columns, gaps shorter than TILE_GAP_COLS + 2 r closed, then their runs
        full = n_rows // TILE_ROWS
        edges = np.append(row0 + TILE_ROWS * np.arange(full + 1), row1)[:full + 1 + (n_rows % TILE_ROWS > 0)]
        hit = want[row0:row0 + full * TILE_ROWS, col0:col1].reshape(full, TILE_ROWS, col1 - col0).any(axis=1)
        if n_rows % TILE_ROWS:
            hit = np.vstack([hit, want[row0 + full * TILE_ROWS:row1, col0:col1].any(axis=0)])
        hit = hit.view(np.uint8)
        gap = TILE_GAP_COLS + 2 * radius
        margin = gap + 2                 # zero columns on both sides: the closing never meets the border
        closed = cv2.morphologyEx(np.pad(hit, ((0, 0), (margin, margin))), cv2.MORPH_CLOSE,
                                  np.ones((1, gap + 1), np.uint8))
        step = np.diff(closed.astype(np.int8), axis=1)
        bands, starts = np.nonzero(step == 1)
        ends = np.nonzero(step == -1)[1]
        tiles = np.stack([edges[bands], edges[bands + 1], col0 + starts + 1 - margin, col0 + ends + 1 - margin],
                         axis=1).astype(np.int64)
        tiled = int(((tiles[:, 1] - tiles[:, 0] + 2 * radius) * (tiles[:, 3] - tiles[:, 2] + 2 * radius)).sum())
        if 5 * tiled < 4 * (n_rows + 2 * radius * n_threads) * (col1 - col0 + 2 * radius):
            return tiles
    edges = [row0 + (s * n_rows) // n_threads for s in range(n_threads + 1)]
    return np.array([(edges[s], edges[s + 1], col0, col1) for s in range(n_threads)], np.int64)
