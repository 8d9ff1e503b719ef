"""The floor of a run: a given camera mount checked against the floor seen in the first frames, or the
floor estimated from them when there is no mount.

:class:`FloorVote` collects the RANSAC floor fits (:func:`~mrstereo.geometry.obstacles.ground_for_frame`)
of a run's first frames, one at a time as they come, and decides once: the seen floor is the median of
the first ``n_frames`` confident fits within ``max_frames`` frames (else the fit with the largest inlier
share, reported as not confident). A given mount is kept when the camera is at least
:data:`MIN_CAMERA_HEIGHT_M` above its floor and a floor seen in two frames agrees within
:data:`MOUNT_HEIGHT_TOLERANCE_M` and :data:`MOUNT_TILT_TOLERANCE_RAD`; otherwise the seen floor is used
and the warning says why. User guide: docs/mapping.md ("The floor"). Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from dataclasses import replace
from typing import NamedTuple

import numpy as np

from ..camera import CameraMount, StereoCamera
from .ground import GroundPlane, T_robot_from_cam_ground, ground_from_mount

__all__ = ["FloorVote", "RunFloor", "median_floor", "mount_of_floor", "MOUNT_HEIGHT_TOLERANCE_M",
           "MOUNT_TILT_TOLERANCE_RAD", "MIN_CAMERA_HEIGHT_M", "FLOOR_FRAMES", "MAX_FLOOR_FRAMES"]

MOUNT_HEIGHT_TOLERANCE_M = 0.10
"""A given mount whose camera height differs more than this from the floor seen in the images is not used."""
MOUNT_TILT_TOLERANCE_RAD = math.radians(5.0)
"""A given mount whose tilt differs more than this from the floor seen in the images is not used."""
MOUNT_ROLL_TOLERANCE_RAD = math.radians(10.0)
"""A given mount whose roll about the optical axis differs more than this from the floor seen in the images (an
upside-down or sideways camera) is not used."""
MIN_CAMERA_HEIGHT_M = 0.05
"""A given mount with the camera lower than this above the floor is taken for a base frame that is not on the floor."""
FLOOR_FRAMES = 3
"""The seen floor is the median of this many confident fits..."""
MAX_FLOOR_FRAMES = 10
"""... among the first frames, at most this many."""


class RunFloor(NamedTuple):
    """The camera mount of a run and the floor it implies (:meth:`FloorVote.result`)."""

    mount: CameraMount
    floor: GroundPlane
    warning: str | None = None
    """Why the given mount was not used, or looks wrong: one line for the user (None: nothing to say)."""


def median_floor(fits: list[tuple[int, GroundPlane]], *, confident: bool) -> GroundPlane:
    """The median height, tilt and roll of floor fits ``(frame index, GroundPlane)``."""
    med = {name: float(np.median([getattr(g, name) for _, g in fits]))
           for name in ("height_m", "tilt_rad", "roll_rad", "inlier_share", "residual_m")}
    frames = ", ".join(str(k) for k, _ in fits)
    return GroundPlane(**med, success=True, method=fits[0][1].method,
                       n_inliers=int(np.median([g.n_inliers for _, g in fits])),
                       message=f"estimated: median of {len(fits)} floor fit(s), frame(s) {frames}"
                               + ("" if confident else " (none confident)"))


def mount_of_floor(floor: GroundPlane, stereo: StereoCamera) -> CameraMount:
    """The camera mount a floor fit implies (the fit is of the rectified left frame, the mount of the raw
    camera: ``p_rect = R p_raw``)."""
    return CameraMount.from_rectified(T_robot_from_cam_ground(floor), stereo.left.R)


def _disagreement(given: GroundPlane, seen: GroundPlane | None) -> str | None:
    """Why a given mount's floor disagrees with the seen one (None: it agrees, or nothing to compare)."""
    if given.height_m < MIN_CAMERA_HEIGHT_M:
        return f"a camera {given.height_m:.3f} m above the floor is below {MIN_CAMERA_HEIGHT_M:.2f} m"
    if seen is None:
        return None
    dh, dt = abs(given.height_m - seen.height_m), abs(given.tilt_rad - seen.tilt_rad)
    if dh > MOUNT_HEIGHT_TOLERANCE_M:
        return f"the height is off by {dh:.3f} m (more than {MOUNT_HEIGHT_TOLERANCE_M:.2f} m)"
    if dt > MOUNT_TILT_TOLERANCE_RAD:
        return f"the tilt is off by {math.degrees(dt):.1f} deg (more than {math.degrees(MOUNT_TILT_TOLERANCE_RAD):.0f} deg)"
    dr = abs(math.remainder(given.roll_rad - seen.roll_rad, math.tau))
    if dr > MOUNT_ROLL_TOLERANCE_RAD:
        return (f"the roll is off by {math.degrees(dr):.0f} deg (more than {math.degrees(MOUNT_ROLL_TOLERANCE_RAD):.0f} "
                "deg: the camera upside down or on its side?)")
    return None


def _floor_text(floor: GroundPlane) -> str:
    return f"height {floor.height_m:.3f} m, tilt {math.degrees(floor.tilt_rad):.1f} deg"


class FloorVote:
    """The floor of a run, decided once from the fits of its first frames (see the module docstring).

    Parameters
    ----------
    stereo : StereoCamera
        The calibration (its rectification relates the fits to the mount).
    mount : CameraMount, optional
        The given mount; None: the floor is estimated.
    check_mount : bool
        Check a given mount against the seen floor (False: it is used as given, no frame is needed).
    n_frames, max_frames : int
        The seen floor is the median of the first ``n_frames`` confident fits within ``max_frames`` frames.
    name : str
        The run's source, for the error message.
    """

    def __init__(self, stereo: StereoCamera, mount: CameraMount | None = None, *, check_mount: bool = True,
                 n_frames: int = FLOOR_FRAMES, max_frames: int = MAX_FLOOR_FRAMES, name: str = "the source") -> None:
        if n_frames < 1 or max_frames < n_frames:
            raise ValueError(f"n_frames must be >= 1 and max_frames >= n_frames, got {n_frames} and {max_frames}")
        self.stereo, self.mount, self.name = stereo, mount, name
        self.n_frames, self.max_frames = int(n_frames), int(max_frames)
        self.given = None if mount is None else ground_from_mount(mount, R_rect_from_cam=stereo.left.R)
        self.needs_frames = mount is None or bool(check_mount)
        self.fits: list[tuple[int, GroundPlane]] = []
        self.best: tuple[int, GroundPlane] | None = None
        self.seen = 0

    @property
    def done(self) -> bool:
        """Enough frames seen to decide."""
        return not self.needs_frames or len(self.fits) >= self.n_frames or self.seen >= self.max_frames

    def add(self, index: int, ground: GroundPlane) -> None:
        """One frame's floor fit (fitted without a mount)."""
        self.seen += 1
        if ground.success and (self.best is None or ground.inlier_share > self.best[1].inlier_share):
            self.best = (index, ground)
        if ground.confident and len(self.fits) < self.n_frames:
            self.fits.append((index, ground))

    def skip(self) -> None:
        """A frame that gave no fit (unreadable): it counts towards ``max_frames``."""
        self.seen += 1

    def seen_floor(self) -> GroundPlane | None:
        if self.best is None:
            return None
        return median_floor(self.fits or [self.best], confident=bool(self.fits))

    def result(self) -> RunFloor:
        """The decision, from the frames added so far (all of a run shorter than ``max_frames``).

        Raises
        ------
        ValueError
            No mount and no floor in any frame added.
        """
        given, mount = self.given, self.mount
        if given is not None and not self.needs_frames:
            return RunFloor(mount, given)
        seen = self.seen_floor()
        if given is None:
            if seen is None:
                raise ValueError(f"no floor found in the first {self.seen} frames of {self.name}; give the camera "
                                 "mount (--mount x,y,z,roll,pitch,yaw or --height/--tilt, or mount:/rig: in the "
                                 "manifest or stereo YAML)")
            return RunFloor(mount_of_floor(seen, self.stereo), seen)
        # one confident fit can be a wall's base or a ramp: a plausible mount is replaced on repeated evidence only
        repeated = len(self.fits) >= min(2, self.seen)
        reason = _disagreement(given, seen if seen is not None and seen.confident and repeated else None)
        if reason is None:
            return RunFloor(mount, given)
        advice = ("give the mount of a base frame on the floor (--base-frame of a bag, --mount x,y,z,roll,pitch,yaw, "
                  "--height/--tilt), or no mount to have the floor estimated")
        if seen is None:
            return RunFloor(mount, given, f"the camera mount looks wrong ({reason}: {_floor_text(given)}) and no "
                                          f"floor was seen in the first frames to replace it; {advice}")
        used = replace(seen, message=f"{seen.message}; used instead of the given mount ({_floor_text(given)})")
        return RunFloor(mount_of_floor(seen, self.stereo), used,
                        f"the camera mount disagrees with the floor seen in the images ({reason}): given "
                        f"{_floor_text(given)}, seen {_floor_text(seen)}; the seen floor is used; {advice}; "
                        "--no-mount-check keeps the given mount")
