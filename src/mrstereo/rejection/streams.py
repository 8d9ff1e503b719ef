"""Suspicious stereo input, named before a run builds a confident map from it.

Two mistakes look like valid input to every later stage: the same stream recorded as left and
right (most pixels of a pair equal, or, with sensor noise or a second encoding, the textured pixels
equal within a few gray levels where a real pair's are shifted) and the streams swapped (a semi-global probe over both signs
of disparity finds mostly negative ones; a raw pair matches better rectified the other way round).
The thresholds and their measurement: docs/errors.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import warnings
from dataclasses import dataclass

import cv2
import numpy as np

from ..camera import StereoCamera

__all__ = ["PairCheck", "check_pair", "warn_pair", "StreamCheck", "PROBLEMS", "IDENTICAL_SHARE", "SWAPPED_SHARE"]

IDENTICAL_SHARE = 0.9
"""A pair with at least this share of equal pixels is a duplicated stream."""
SAME_VIEW_SHARE = 0.5
"""A pair whose textured pixels are equal within :data:`SAME_VIEW_LEVELS` gray levels at least this often shows one
view twice (measured on one pair of each of eight real scenes, KITTI, Middlebury, EuRoC, OpenLORIS, OpenCV's
chessboards: 0.05-0.17; one image twice with +/-2 levels of noise: 1.00, with Gaussian noise of sigma 3: 0.87)."""
SAME_VIEW_LEVELS = 4
_TEXTURE_GRADIENT = 40.0          # |horizontal Sobel| of a textured pixel
_MIN_TEXTURED = 500
SWAPPED_SHARE = 0.65
"""A pair is swapped when at least this share of the pixels matched either way match only the other way round."""
_PROBE_WIDTH = 320
_MIN_MATCHED = 200


@dataclass(frozen=True)
class PairCheck:
    """What :func:`check_pair` saw in one stereo pair.

    Attributes
    ----------
    identical_share : float
        Share of pixels equal in both images (as read).
    same_view_share : float
        Share of the textured pixels of the left image (a strong horizontal gradient) whose gray level
        the right image has within :data:`SAME_VIEW_LEVELS` at the same place (NaN: too few textured
        pixels): a real pair's are shifted, one view twice matches with noise.
    matched : int
        Probe pixels matched with a positive disparity, the pair as given.
    matched_exchanged : int
        The same with left and right exchanged: a rectified pair's negative disparities; a raw pair
        rectified the other way round.
    median_disparity_px : float
        Median disparity of the pair as given, full-resolution pixels (NaN: too few matched).
    """

    identical_share: float
    matched: int
    matched_exchanged: int
    median_disparity_px: float
    same_view_share: float = float("nan")

    @property
    def identical(self) -> bool:
        return self.identical_share >= IDENTICAL_SHARE or self.same_view_share >= SAME_VIEW_SHARE

    @property
    def exchanged_share(self) -> float:
        """Share of the matched pixels that match only with left and right exchanged."""
        total = self.matched + self.matched_exchanged
        return self.matched_exchanged / total if total else float("nan")

    @property
    def swapped(self) -> bool:
        return (not self.identical and self.matched + self.matched_exchanged >= _MIN_MATCHED
                and self.exchanged_share >= SWAPPED_SHARE)

    def describe(self) -> str:
        if self.identical_share >= IDENTICAL_SHARE:
            return f"{100 * self.identical_share:.1f} % of the pixels of left and right are equal"
        if self.identical:
            return (f"{100 * self.same_view_share:.0f} % of the textured pixels of left and right are equal within "
                    f"{SAME_VIEW_LEVELS} gray levels (a real pair's are shifted)")
        return (f"{100 * self.exchanged_share:.0f} % of the matched pixels match only with left and right "
                f"exchanged (median disparity as given {self.median_disparity_px:.1f} px)")


def _gray8(image: np.ndarray) -> np.ndarray:
    if image.ndim == 3:
        image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY) if image.shape[2] == 3 else image[:, :, 0]
    if image.dtype != np.uint8:
        image = np.clip(np.asarray(image, np.float32) * (1.0 if image.dtype.kind == "f" else 1 / 257.0), 0, 255)
        image = image.astype(np.uint8)
    return np.ascontiguousarray(image)


def _same_view_share(left: np.ndarray, right: np.ndarray) -> float:
    """:attr:`PairCheck.same_view_share` of a pair (images as read)."""
    gl, gr = _gray8(left), _gray8(right)
    textured = np.abs(cv2.Sobel(gl, cv2.CV_32F, 1, 0, ksize=3)) > _TEXTURE_GRADIENT
    if np.count_nonzero(textured) < _MIN_TEXTURED:
        return float("nan")
    diff = cv2.absdiff(gl, gr)
    return float(np.mean(diff[textured] <= SAME_VIEW_LEVELS))


def _probe(left: np.ndarray, right: np.ndarray) -> tuple[int, int, float]:
    """``(positive, negative, median)``: pixels OpenCV's SGBM matches at positive and negative disparities
    (of both signs, on at most :data:`_PROBE_WIDTH` columns) and their median in full-resolution pixels."""
    gl, gr = _gray8(left), _gray8(right)
    scale = min(1.0, _PROBE_WIDTH / gl.shape[1])
    if scale < 1.0:
        size = (max(16, round(gl.shape[1] * scale)), max(16, round(gl.shape[0] * scale)))
        gl, gr = (cv2.resize(g, size, interpolation=cv2.INTER_AREA) for g in (gl, gr))
    reach = 16 * max(1, min(4, gl.shape[1] // 64))          # disparities -reach .. reach - 1 (probe pixels)
    if gl.shape[1] <= 2 * reach + 5 or gl.shape[0] < 8:
        return 0, 0, float("nan")
    matcher = cv2.StereoSGBM_create(minDisparity=-reach, numDisparities=2 * reach, blockSize=5, P1=8 * 25,
                                    P2=32 * 25, uniquenessRatio=10, speckleWindowSize=50, speckleRange=2,
                                    disp12MaxDiff=1)
    d = matcher.compute(gl, gr).astype(np.float32) / 16.0
    valid = d > -reach              # SGBM marks "no match" with minDisparity - 1
    valid[:, :reach] = False        # columns without a partner at every disparity
    valid[:, -reach:] = False
    values = d[valid & (np.abs(d) >= 0.5)]
    median = float(np.median(values)) / scale if values.size >= _MIN_MATCHED else float("nan")
    return int(np.count_nonzero(values > 0)), int(np.count_nonzero(values < 0)), median


def check_pair(left: np.ndarray, right: np.ndarray, stereo: StereoCamera | None = None, *,
               rectified: bool = True) -> PairCheck:
    """Look for a duplicated or swapped stream in one pair (images as read; ``rectified=False``: a raw pair,
    rectified with ``stereo`` both ways round)."""
    if left.shape != right.shape:
        raise ValueError(f"left and right images differ in size: {left.shape} and {right.shape}")
    identical = float(np.mean(left == right))
    same = _same_view_share(left, right)
    if rectified or stereo is None:
        positive, negative, median = _probe(left, right)
        return PairCheck(identical, positive, negative, median, same)
    positive, _, median = _probe(*stereo.rectify(left, right))
    exchanged, _, _ = _probe(*stereo.rectify(right, left))
    return PairCheck(identical, positive, exchanged, median, same)


PROBLEMS = (("identical", "identical left and right images (a duplicated camera stream?)",
              "the result would show phantom obstacles"),
             ("swapped", "left and right images that look swapped",
              "the result would show false obstacles and free space; check which camera is left"))


def warn_pair(left: np.ndarray, right: np.ndarray, stereo: StereoCamera | None = None, *,
              rectified: bool = True) -> str | None:
    """Warn (``warnings.warn``) when one pair looks duplicated or swapped (:func:`check_pair`); return the text."""
    check = check_pair(left, right, stereo, rectified=rectified)
    for flag, what, hint in PROBLEMS:
        if getattr(check, flag):
            text = f"the pair has {what}: {check.describe()}; {hint}"
            warnings.warn(text, UserWarning, stacklevel=2)
            return text
    return None


class StreamCheck:
    """A run's first ``n_frames`` pairs looked at for a duplicated or swapped stream (:func:`check_pair`);
    :meth:`warn` warns (``warnings.warn``) once when most of them show one. ``name`` is what is read."""

    def __init__(self, stereo: StereoCamera | None, name: str, *, n_frames: int = 3) -> None:
        self.stereo, self.name, self.n_frames = stereo, name, int(n_frames)
        self.checks: list[tuple[int, PairCheck]] = []
        self.warned = False

    @property
    def done(self) -> bool:
        return self.warned or len(self.checks) >= self.n_frames

    def add(self, index: int, left: np.ndarray, right: np.ndarray, *, rectified: bool = True) -> None:
        """One pair (as read); the warning once the first ``n_frames`` are in."""
        if self.done:
            return
        try:
            self.checks.append((index, check_pair(left, right, self.stereo, rectified=rectified)))
        except ValueError:              # (images of two sizes: the chain names them)
            return
        if len(self.checks) >= self.n_frames:
            self.warn()

    def warn(self) -> list[str]:
        """Warn about what most of the pairs seen show (once); the warnings."""
        if self.warned:
            return []
        self.warned = True
        found = []
        for flag, what, hint in PROBLEMS:
            bad = [(k, c) for k, c in self.checks if getattr(c, flag)]
            if bad and len(bad) * 2 > len(self.checks):
                seen = "; ".join(f"frame {k}: {c.describe()}" for k, c in bad)
                found.append(f"{self.name} has {what}: {seen}; {hint}")
        for text in found:
            warnings.warn(text, UserWarning, stacklevel=3)
        return found
