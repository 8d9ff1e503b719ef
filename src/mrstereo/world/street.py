"""A long street world for odometry at car speed: building fronts, parked cars, poles, a wide rig.

:func:`street_world` draws a road along +x between rows of buildings, side streets, parked
cars, poles and trees, and a KITTI-like rig (0.5 m baseline, level, 1.65 m up); the path is
:func:`mrstereo.world.paths.speed_path`. User guide: docs/world.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math

import numpy as np

from .. import _checks
from ..camera import Camera, CameraMount, StereoCamera
from .randomize import RandomWorld, _material
from .render import SensorModel
from .scene import (LABEL_FLOOR, LABEL_OBSTACLE, LABEL_POSTER, LABEL_WALL, TEXTURE_BLOTCH, TEXTURE_CHECKER,
                    TEXTURE_POSTER, TEXTURE_TILES, TEXTURE_WEAK, TEXTURE_WOOD, Box, Cylinder, Decal, Light,
                    Material, Scene)

__all__ = ["street_world", "STREET_BASELINE_M", "STREET_CAMERA_HEIGHT_M"]

STREET_BASELINE_M = 0.5
"""Baseline of the street rig (a car's stereo head; KITTI's is 0.54 m)."""
STREET_CAMERA_HEIGHT_M = 1.65
"""Height of the street rig's left camera above the road (KITTI's)."""


_FACADES = {"tiles": (TEXTURE_TILES, (0.4, 0.7), (0.08, 0.15), (0.2, 0.5), (0.4, 1.2)),     # as randomize's banks
            "blotch": (TEXTURE_BLOTCH, (0.35, 0.6), (0.15, 0.3), (0.3, 1.0)),
            "wood": (TEXTURE_WOOD, (0.3, 0.55), (0.15, 0.3), (0.1, 0.3), (0.3, 0.8)),
            "plain": (TEXTURE_WEAK, (0.5, 0.8), (0.04, 0.1), (0.5, 2.0))}


def _facade_material(rng: np.random.Generator) -> Material:
    return _material(rng, _FACADES, tuple(_FACADES)[int(rng.integers(0, 4))])[1]


def street_world(seed: int, *, width: int = 320, height: int = 240, length_m: float = 160.0,
                 width_m: float = 12.0) -> RandomWorld:
    """Draw a street world from ``seed``.

    Parameters
    ----------
    seed : int
        Non-negative; the same seed gives the same world.
    width, height : int
        Image size of the rig (77 degree field of view).
    length_m, width_m : float
        Length of the street along +x and distance between the building fronts.

    Returns
    -------
    RandomWorld
        ``waypoints_xy`` runs from ``(0, 0)`` to ``(length_m, 0)``.
    """
    seed = _checks.positive_int("seed", seed, minimum=0)
    width = _checks.positive_int("width", width, minimum=16)
    height = _checks.positive_int("height", height, minimum=16)
    length = _checks.finite_number("length_m", length_m, positive=True)
    street = _checks.finite_number("width_m", width_m, positive=True)
    if street < 8.0:
        raise ValueError(f"width_m must be at least 8 m (two lanes and parked cars), got {street}")
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0x57EE7]))
    half = street / 2.0
    x0, x1 = -10.0, length + 20.0
    mats = [Material(TEXTURE_BLOTCH, 0.32, 0.12, 0.25),                 # 0 road
            Material(TEXTURE_CHECKER, 0.45, 0.35, 0.05, 0.8),            # 1 window band
            Material(TEXTURE_POSTER, 0.5, 0.45, 0.06)]                   # 2 poster / shop sign
    boxes = [Box((x0, -half - 40.0, -0.2), (x1, half + 40.0, 0.0), 0, LABEL_FLOOR)]
    decals, cylinders = [], []
    for side in (+1, -1):
        x = x0
        while x < x1:
            span = rng.uniform(8.0, 25.0)
            setback = rng.uniform(0.0, 2.0)
            tall = rng.uniform(5.0, 15.0)
            mats.append(_facade_material(rng))
            y_front = side * (half + setback)
            ya, yb = sorted((y_front, y_front + side * 10.0))
            boxes.append(Box((x, ya, 0.0), (min(x + span, x1), yb, tall), len(mats) - 1, LABEL_WALL))
            for floor_z in np.arange(2.5, tall - 1.0, 3.0):              # a band of windows per storey
                decals.append(Decal(-side, y_front, x + 0.5, min(x + span, x1) - 0.5, floor_z, floor_z + 1.2,
                                    1, LABEL_WALL))
            if rng.uniform() < 0.5:
                a = x + rng.uniform(0.5, max(0.6, span - 3.0))
                decals.append(Decal(-side, y_front, a, min(a + rng.uniform(1.0, 3.0), x + span), 0.3, 2.2, 2,
                                    LABEL_POSTER))
            x += span + (rng.uniform(4.0, 10.0) if rng.uniform() < 0.3 else 0.0)     # a side street
        # the far side of the side streets: a back row of buildings
        yb_back = side * (half + 35.0)
        ya, yb = sorted((yb_back, yb_back + side * 5.0))
        mats.append(_facade_material(rng))
        boxes.append(Box((x0, ya, 0.0), (x1, yb, 20.0), len(mats) - 1, LABEL_WALL))
    label = LABEL_OBSTACLE
    for side in (+1, -1):
        x = x0 + rng.uniform(0.0, 6.0)
        while x < x1 - 5.0:                                                # parked cars along the kerb
            if rng.uniform() < 0.7:
                mats.append(Material(TEXTURE_BLOTCH, rng.uniform(0.2, 0.7), rng.uniform(0.2, 0.35), 0.15))
                yc = side * (half - 1.3)
                boxes.append(Box((x, yc - 0.9, 0.0), (x + 4.2, yc + 0.9, rng.uniform(1.3, 1.7)), len(mats) - 1,
                                 label))
                label = min(label + 1, 255)
            x += 4.2 + rng.uniform(0.8, 8.0)
        for xp in np.arange(x0 + rng.uniform(0.0, 15.0), x1, rng.uniform(12.0, 20.0)):   # poles and trees
            mats.append(Material(TEXTURE_WOOD, rng.uniform(0.25, 0.5), 0.25, 0.1, 0.15))
            cylinders.append(Cylinder((float(xp), side * (half - 0.2)), rng.uniform(0.12, 0.3), rng.uniform(3.5, 7.0),
                                      len(mats) - 1, label))
            label = min(label + 1, 255)
    lights = tuple(Light((float(x), 0.0, 25.0), 500.0) for x in np.arange(x0, x1, 40.0))
    scene = Scene(boxes=tuple(boxes), cylinders=tuple(cylinders), decals=tuple(decals), lights=lights,
                  materials=tuple(mats), skirting_m=0.0, skirting_material=0, ambient=0.6,
                  x_range_m=(x0, x1), half_width_m=half, height_m=40.0, seed=seed)
    f = (width / 2.0) / math.tan(math.radians(77.0) / 2.0)
    camera = Camera(width=width, height=height, fx=f, fy=f, cx=(width - 1) / 2.0, cy=(height - 1) / 2.0)
    stereo = StereoCamera.ideal(camera, STREET_BASELINE_M,
                                mount=CameraMount.from_xyz_rpy((0.0, 0.0, STREET_CAMERA_HEIGHT_M), (0.0, 0.0, 0.0)))
    noise = rng.uniform(1.0, 2.5)
    sensors = (SensorModel(noise_sigma=noise), SensorModel(gain=rng.uniform(0.9, 1.1), noise_sigma=noise))
    summary = {"seed": seed, "kind": "street", "length_m": round(length, 3), "width_m": round(street, 3),
               "buildings": sum(b.label == LABEL_WALL for b in boxes) - 2, "obstacles": label - LABEL_OBSTACLE,
               "baseline_m": STREET_BASELINE_M, "camera_height_m": STREET_CAMERA_HEIGHT_M,
               "focal_px": round(f, 1), "noise_sigma": round(noise, 2)}
    return RandomWorld(seed=seed, scene=scene, stereo=stereo, sensors=sensors,
                       waypoints_xy=np.array([[0.0, 0.0], [length, 0.0]]), summary=summary)
