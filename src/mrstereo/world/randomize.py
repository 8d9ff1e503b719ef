"""Randomized corridor worlds: many different corridors, each fixed by one integer seed.

:func:`random_world` draws the corridor, its textures, lights, obstacles, side rooms, doors, the
stereo head, the cameras' sensors and a robot path from ``numpy.random.default_rng`` in a fixed
order, so a seed always gives the same world. What is drawn from which range, and which seeds
choose the defaults: docs/world.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from .. import _checks
from ..camera import Camera, CameraInfo, CameraMount, StereoCamera
from ..geometry.ground import ground_from_mount
from ..transforms import rotation_from_rpy
from .render import SensorModel
from .scene import (LABEL_DOOR, LABEL_FLOOR, LABEL_OBSTACLE, LABEL_POSTER, TEXTURE_BLOTCH, TEXTURE_CHECKER, TEXTURE_POSTER,
                    TEXTURE_STRIPES_U, TEXTURE_STRIPES_V, TEXTURE_TILES, TEXTURE_WEAK, TEXTURE_WOOD, WALL_THICK_M, Box,
                    Cylinder, Decal, Light, Material, Scene, _corridor_boxes)

__all__ = ["RandomWorld", "random_world", "random_stereo", "RANGES", "DROP_RANGES", "WALL_TEXTURES"]

RANGES = {
    "corridor_width_m": (1.6, 3.0),
    "corridor_length_m": (8.0, 15.5),
    "ceiling_m": (2.2, 3.0),
    "camera_height_m": (0.3, 1.2),
    "tilt_rad": (0.0, 0.4),
    "baseline_m": (0.06, 0.16),
    "horizontal_fov_deg": (50.0, 80.0),
    "noise_sigma": (0.8, 4.0),
    "gain": (0.6, 1.3),
    "right_gain_ratio": (0.85, 1.15),
    "black_level": (0.0, 12.0),
    "obstacles": (4, 9),
}
"""Ranges of the randomized quantities (uniform draws)."""

DROP_RANGES = {
    "ledge_depth_m": (0.3, 1.5),
    "hole_depth_m": (0.3, 1.5),
    "hole_size_m": (0.4, 1.0),
    "holes": (1, 2),
    "kerb_m": (0.03, 0.05),
    "ramp_depth_m": (0.1, 0.25),
    "ramp_slope_deg": (3.0, 7.0),
    "stair_riser_m": (0.15, 0.2),
}
"""Ranges of the drops of ``random_world(..., drops=True)`` (uniform draws; docs/world.md, "Drops")."""

SLAB_DEPTH_M = 2.0      # the floor slab of a world with drops: pit walls reach this deep
RAMP_RISER_M = 0.01     # a ramp is a flight of 1 cm risers (axis-aligned boxes)

_CLEARANCE_M = 0.4      # obstacles keep this far from the robot path (robot radius + margin)
_GRID_HALF_M = 2.95     # everything the map should show stays within |y| < 3 m (the default grid)


@dataclass(frozen=True)
class RandomWorld:
    """One randomized world: the scene, the true stereo rig (``stereo.mount``), the left and right
    sensors, the robot path ``waypoints_xy`` (K, 2) clear of every obstacle by 0.4 m, and ``summary``:
    the drawn parameters in plain numbers (written into the dataset manifest). With ``drops=True`` the
    summary's ``"drops"`` lists the ledge or ramp, holes, kerbs and sunken steps drawn.
    """

    seed: int
    scene: Scene
    stereo: StereoCamera
    sensors: tuple[SensorModel, SensorModel]
    waypoints_xy: np.ndarray
    summary: dict


def _u(rng: np.random.Generator, lo_hi) -> float:
    lo, hi = lo_hi
    return float(rng.uniform(lo, hi))


def random_stereo(rng, width: int = 320, height: int = 240) -> StereoCamera:
    """A realistic stereo head: baseline 6-16 cm, 50-80 degree field of view, mount, raw cameras.

    The raw cameras have barrel distortion (``k1`` in [-0.08, 0], ``k2`` in [0, 0.01]), focal
    lengths within 1 % of the rectified one, principal points up to 3 px off and rotations up to
    0.8 degrees relative to the rectified frame, like :func:`mrstereo.world.default_stereo`.
    """
    rng = np.random.default_rng(rng)
    width = _checks.positive_int("width", width, minimum=16)
    height = _checks.positive_int("height", height, minimum=16)
    fov = math.radians(_u(rng, RANGES["horizontal_fov_deg"]))
    f = (width / 2.0) / math.tan(fov / 2.0)
    baseline = _u(rng, RANGES["baseline_m"])
    height_m, tilt_rad = _u(rng, RANGES["camera_height_m"]), _u(rng, RANGES["tilt_rad"])
    s = width / 320.0
    cx = (width - 1) / 2.0 + rng.uniform(-3, 3) * s
    cy = (height - 1) / 2.0 + rng.uniform(-3, 3) * s
    rect = Camera(width=width, height=height, fx=f, fy=f, cx=cx, cy=cy)
    raws, Rs = [], []
    for _ in range(2):
        raws.append(Camera(width=width, height=height, fx=f * rng.uniform(0.99, 1.01),
                           fy=f * rng.uniform(0.99, 1.01), cx=cx + rng.uniform(-3, 3) * s,
                           cy=cy + rng.uniform(-3, 3) * s, k1=rng.uniform(-0.08, 0.0), k2=rng.uniform(0.0, 0.01)))
        Rs.append(rotation_from_rpy(*rng.uniform(-0.014, 0.014, 3)))
    P_left = np.hstack([rect.K, np.zeros((3, 1))])
    P_right = P_left.copy()
    P_right[0, 3] = -f * baseline
    return StereoCamera(left=CameraInfo(raws[0], R=Rs[0], P=P_left, name="left"),
                        right=CameraInfo(raws[1], R=Rs[1], P=P_right, name="right"),
                        mount=CameraMount.from_rig(height_m, tilt_rad, R_rect_from_cam=Rs[0]))


# Material banks: kind -> (texture, albedo, contrast, scale_m[, period_m]), each number drawn
# uniformly from a (lo, hi) pair, in this order, or constant; (lo, hi, k) is a draw scaled by k.
_WALL = {"paint": (TEXTURE_WEAK, (0.45, 0.85), (0.01, 0.05), (0.1, 0.5)),     # a few grey levels
         "tiles": (TEXTURE_TILES, (0.45, 0.85), (0.03, 0.1), (0.1, 0.3), (0.15, 0.5)),
         "stripes": (TEXTURE_STRIPES_U, (0.45, 0.85), (0.04, 0.2), (0.1, 0.4), (0.06, 0.4)),
         "blotch": (TEXTURE_BLOTCH, (0.45, 0.85), (0.08, 0.3), (0.03, 0.2)),
         "wood": (TEXTURE_WOOD, (0.45, 0.85, 0.7), (0.1, 0.25), (0.03, 0.08), (0.08, 0.2))}
_FLOOR = {"paint": (TEXTURE_WEAK, (0.3, 0.7), (0.01, 0.04), (0.1, 0.5)),
          "tiles": (TEXTURE_TILES, (0.3, 0.7), (0.02, 0.08), (0.1, 0.3), (0.3, 0.6)),
          "checker": (TEXTURE_CHECKER, (0.3, 0.7), (0.1, 0.3), (0.2, 0.6), (0.2, 0.5)),
          "wood": (TEXTURE_WOOD, (0.3, 0.7), (0.08, 0.2), (0.03, 0.08), (0.1, 0.25)),
          "carpet": (TEXTURE_BLOTCH, (0.3, 0.7), (0.05, 0.15), (0.01, 0.04)),
          "stripes": (TEXTURE_STRIPES_V, (0.3, 0.7), (0.03, 0.1), (0.1, 0.4), (0.2, 0.6))}
_CEILING = {"paint": (TEXTURE_WEAK, (0.7, 0.9), (0.01, 0.04), 0.4),
            "tiles": (TEXTURE_TILES, (0.7, 0.9), (0.02, 0.06), 0.3, (0.5, 0.7))}
_POSTER = {"poster": (TEXTURE_POSTER, (0.4, 0.6), (0.3, 0.5), (0.02, 0.05)),
           "chessboard": (TEXTURE_CHECKER, 0.5, (0.4, 0.55), 5.0, (0.03, 0.1)),     # perfectly repetitive
           "stripes": (TEXTURE_STRIPES_U, 0.5, (0.3, 0.5), 1.0, (0.03, 0.12))}
_OBSTACLE = {"blotch": (TEXTURE_BLOTCH, (0.25, 0.75), (0.2, 0.45), (0.02, 0.06)),
             "checker": (TEXTURE_CHECKER, (0.25, 0.75), (0.2, 0.4), (0.02, 0.05), (0.04, 0.12)),
             "wood": (TEXTURE_WOOD, (0.25, 0.75), (0.15, 0.3), (0.03, 0.06), (0.05, 0.12)),
             "poster": (TEXTURE_POSTER, (0.25, 0.75), (0.25, 0.45), (0.02, 0.05)),
             "plain": (TEXTURE_WEAK, (0.25, 0.75), (0.06, 0.12), (0.03, 0.08))}
WALL_TEXTURES = tuple(_WALL)
"""Kinds of wall material in the bank (``random_world(..., wall_texture=...)`` picks one)."""


def _material(rng, table: dict, kind) -> tuple[str, Material]:
    """A material of ``kind`` (a str, or a list to draw it from) from ``table`` (see above)."""
    kind = kind if isinstance(kind, str) else str(rng.choice(kind))
    texture, *numbers = table[kind]
    return kind, Material(texture, *(v if not isinstance(v, tuple) else rng.uniform(v[0], v[1]) if len(v) == 2
                                     else rng.uniform(v[0], v[1]) * v[2] for v in numbers))


# --------------------------------------------------------------------------- layout helpers
def _path_points(waypoints: np.ndarray, step_m: float = 0.05) -> np.ndarray:
    out = [waypoints[:1]]
    for a, b in zip(waypoints[:-1], waypoints[1:]):
        n = max(1, int(math.ceil(np.hypot(*(b - a)) / step_m)))
        out.append(a + (b - a) * (np.arange(1, n + 1)[:, None] / n))
    return np.concatenate(out)


def _rect_clear(rect, path_pts: np.ndarray, placed: list, gap: float) -> bool:
    """``rect`` (x0, x1, y0, y1) keeps ``_CLEARANCE_M`` from the path and ``gap`` from ``placed``."""
    x0, x1, y0, y1 = rect
    dx = np.maximum(np.maximum(x0 - path_pts[:, 0], path_pts[:, 0] - x1), 0.0)
    dy = np.maximum(np.maximum(y0 - path_pts[:, 1], path_pts[:, 1] - y1), 0.0)
    if np.min(np.hypot(dx, dy)) < _CLEARANCE_M:
        return False
    return all(x1 + gap <= a0 or a1 + gap <= x0 or y1 + gap <= b0 or b1 + gap <= y0 for a0, a1, b0, b1 in placed)


def _intervals_free(a: float, b: float, taken: list[tuple[float, float]], gap: float) -> bool:
    return all(b + gap <= lo or hi + gap <= a for lo, hi in taken)


_SOLIDS = {"box": ((0.2, 0.7), (0.2, 0.7), (0.3, 1.2)), "low": ((0.2, 0.6), (0.2, 0.6), (0.12, 0.22)),
           "cylinder": ((0.08, 0.3), (0.3, 1.2)), "pole": ((0.02, 0.05), (0.9, 1.6))}


def _obstacle(rng, kind: str, x: float, y: float, mat: int) -> tuple[list[Box], list[Cylinder], tuple]:
    """Primitives of one obstacle centred at (x, y) and its footprint rectangle (label set later)."""
    boxes: list[Box] = []
    cyls: list[Cylinder] = []
    if kind in _SOLIDS:         # a box (sizes x, y, height) or a cylinder (radius, height)
        size = [rng.uniform(lo, hi) for lo, hi in _SOLIDS[kind]]
        if len(size) == 3:
            sx, sy, h = size
            boxes.append(Box((x - sx / 2, y - sy / 2, 0.0), (x + sx / 2, y + sy / 2, h), mat, 0))
            rect = (x - sx / 2, x + sx / 2, y - sy / 2, y + sy / 2)
        else:
            r, h = size
            cyls.append(Cylinder((x, y), r, h, mat, 0))
            rect = (x - r, x + r, y - r, y + r)
    else:                       # table or chair: a top on four thin legs (a chair has a backrest)
        table = kind == "table"
        sx = rng.uniform(0.6, 1.2) if table else rng.uniform(0.38, 0.48)
        sy = rng.uniform(0.5, 0.8) if table else rng.uniform(0.38, 0.48)
        h = rng.uniform(0.68, 0.76) if table else rng.uniform(0.42, 0.48)
        leg = rng.uniform(0.02, 0.03) if table else rng.uniform(0.012, 0.02)
        boxes.append(Box((x - sx / 2, y - sy / 2, h - 0.035), (x + sx / 2, y + sy / 2, h), mat, 0))
        for ex in (-1, 1):
            for ey in (-1, 1):
                cyls.append(Cylinder((x + ex * (sx / 2 - 2 * leg), y + ey * (sy / 2 - 2 * leg)), leg, h - 0.035,
                                     mat, 0))
        if not table:
            side = rng.choice([-1, 1])
            bx = x + side * (sx / 2 - 0.015)
            boxes.append(Box((bx - 0.015, y - sy / 2, h), (bx + 0.015, y + sy / 2, h + 0.4), mat, 0))
        rect = (x - sx / 2, x + sx / 2, y - sy / 2, y + sy / 2)
    return boxes, cyls, rect


def _labelled(boxes: list[Box], cyls: list[Cylinder], label: int) -> tuple[list[Box], list[Cylinder]]:
    return ([Box(b.min_m, b.max_m, b.material, label) for b in boxes],
            [Cylinder(c.centre_m, c.radius_m, c.height_m, c.material, label) for c in cyls])


# --------------------------------------------------------------------------- the world
class _MaterialBank:
    """The materials of one world in the order they are drawn; :meth:`add` gives a material's index."""

    def __init__(self) -> None:
        self.names: list[str] = []
        self.materials: list[Material] = []

    def add(self, pair: tuple[str, Material]) -> int:
        self.names.append(str(pair[0]))
        self.materials.append(pair[1])
        return len(self.materials) - 1


class _Corridor(NamedTuple):
    """The drawn corridor: side walls at ``y = +-half_m``, end walls at ``x0_m`` and ``x1_m``."""

    width_m: float
    half_m: float
    ceiling_m: float
    x0_m: float
    x1_m: float


def _draw_corridor(rng) -> _Corridor:
    width_m = _u(rng, RANGES["corridor_width_m"])
    ceiling_m = _u(rng, RANGES["ceiling_m"])
    x0 = -rng.uniform(0.6, 1.5)
    return _Corridor(width_m, width_m / 2.0, ceiling_m, x0, x0 + _u(rng, RANGES["corridor_length_m"]))


def _draw_path(rng, corridor: _Corridor) -> np.ndarray:
    """Waypoints (K, 2) every ~2.5 m with lateral offsets inside the corridor."""
    n_way = int(rng.integers(3, 6))
    xs = np.linspace(0.0, min(10.5, corridor.x1_m - 1.2), n_way)
    lateral = max(corridor.half_m - 0.55, 0.0)
    ys = rng.uniform(-lateral, lateral, n_way) * rng.uniform(0.0, 1.0)
    ys[0] = rng.uniform(-0.3, 0.3) * lateral
    return np.round(np.stack([xs, ys], 1), 3)


def _draw_wall_gaps(rng, corridor: _Corridor) -> tuple[list, list, dict[int, list]]:
    """Side openings ``(side, xa, xb, top, depth)`` into small rooms, recessed doors ``(side, xa, xb)``,
    and the x intervals they take on each wall (``+1`` left, ``-1`` right)."""
    openings: list[tuple[int, float, float, float, float]] = []
    doors: list[tuple[int, float, float]] = []
    taken: dict[int, list] = {+1: [], -1: []}
    x1, h = corridor.x1_m, corridor.ceiling_m
    max_depth = _GRID_HALF_M - corridor.half_m - WALL_THICK_M
    for _ in range(int(rng.integers(0, 3))):
        side = int(rng.choice([-1, 1]))
        w = rng.uniform(0.8, 1.8)
        xa = rng.uniform(0.5, x1 - w - 0.5)
        depth = rng.uniform(0.6, 1.4)
        if depth <= max_depth - 0.05 and _intervals_free(xa - 0.3, xa + w + 0.3, taken[side], 0.3):
            top = float(rng.choice([2.1, h]))
            openings.append((side, float(xa), float(xa + w), top, float(min(depth, max_depth - 0.05))))
            taken[side].append((xa - 0.3, xa + w + 0.3))
    for _ in range(int(rng.integers(0, 5))):
        side = int(rng.choice([-1, 1]))
        xa = rng.uniform(0.0, x1 - 1.2)
        if _intervals_free(xa, xa + 0.9, taken[side], 0.2):
            doors.append((side, float(xa), float(xa + 0.9)))
            taken[side].append((xa, xa + 0.9))
    return openings, doors, taken


def _draw_decals(rng, corridor: _Corridor, bank: _MaterialBank, taken: dict[int, list]) -> list[Decal]:
    """Posters and flat door panels painted on the walls, clear of the openings and doors."""
    x1, half, h = corridor.x1_m, corridor.half_m, corridor.ceiling_m
    decals = []
    for _ in range(int(rng.integers(2, 7))):
        side = int(rng.choice([-1, 1]))
        w = rng.uniform(0.4, 1.2)
        xa = rng.uniform(0.0, x1 - w)
        if not _intervals_free(xa, xa + w, taken[side], 0.1):
            continue
        z0 = rng.uniform(0.3, 1.2)
        zh = rng.uniform(0.4, 1.0)
        mat = bank.add(_material(rng, _POSTER, ["poster", "poster", "chessboard", "stripes"]))
        decals.append(Decal(-side, side * half, xa, xa + w, z0, min(z0 + zh, h - 0.1), mat, LABEL_POSTER))
        taken[side].append((xa, xa + w))
    for _ in range(int(rng.integers(0, 3))):
        side = int(rng.choice([-1, 1]))
        xa = rng.uniform(0.0, x1 - 0.9)
        if not _intervals_free(xa, xa + 0.9, taken[side], 0.1):
            continue
        mat = bank.add(("panel", Material(TEXTURE_WOOD, rng.uniform(0.2, 0.5), rng.uniform(0.15, 0.3), 0.04,
                                          rng.uniform(0.06, 0.12))))
        decals.append(Decal(-side, side * half, xa, xa + 0.9, 0.0, 2.1, mat, LABEL_DOOR))
        taken[side].append((xa, xa + 0.9))
    return decals


def _place_obstacle(rng, kind: str, mat: int, corridor: _Corridor, path_pts: np.ndarray,
                    placed: list) -> tuple | None:
    """Up to 40 draws of where an obstacle stands: ``(boxes, cylinders, footprint)`` of the first one
    inside the corridor and clear of the path and of ``placed``, else None."""
    x0, x1, half = corridor.x0_m, corridor.x1_m, corridor.half_m
    for _attempt in range(40):
        x = rng.uniform(0.4, min(x1, 12.0) - 0.4)
        y = rng.uniform(-half, half)
        if rng.uniform() < 0.3:           # against a wall
            y = np.sign(y) * half
        b, c, rect = _obstacle(rng, kind, x, y, mat)
        # shift into the corridor if it pokes through a wall
        shift = min(0.0, half - rect[3]) + max(0.0, -half - rect[2])
        if shift:
            b = [Box((p.min_m[0], p.min_m[1] + shift, p.min_m[2]), (p.max_m[0], p.max_m[1] + shift, p.max_m[2]),
                     p.material, 0) for p in b]
            c = [Cylinder((p.centre_m[0], p.centre_m[1] + shift), p.radius_m, p.height_m, p.material, 0)
                 for p in c]
            rect = (rect[0], rect[1], rect[2] + shift, rect[3] + shift)
        if rect[1] < x1 - 0.05 and rect[0] > x0 + 0.05 and _rect_clear(rect, path_pts, placed, 0.15):
            return b, c, rect
    return None


def _draw_obstacles(rng, corridor: _Corridor, bank: _MaterialBank,
                    path_pts: np.ndarray) -> tuple[list[Box], list[Cylinder], list[str]]:
    """Obstacles placed by rejection sampling, clear of the path and of each other; labelled
    ``LABEL_OBSTACLE + k`` in the order of their footprint's x. Returns boxes, cylinders and kinds."""
    placed: list[tuple] = []
    parts: list[tuple] = []
    kinds = ["box", "box", "cylinder", "low", "pole", "table", "chair"]
    n_obstacles = int(rng.integers(RANGES["obstacles"][0], RANGES["obstacles"][1] + 1))
    for _ in range(n_obstacles):
        kind = str(rng.choice(kinds))
        mat = bank.add(_material(rng, _OBSTACLE, ["blotch", "blotch", "checker", "wood", "poster", "plain"]))
        found = _place_obstacle(rng, kind, mat, corridor, path_pts, placed)
        if found is not None:
            b, c, rect = found
            placed.append(rect)
            parts.append((rect[0], kind, b, c))
    boxes, cylinders, obstacle_kinds = [], [], []
    for k, (_, kind, b, c) in enumerate(sorted(parts, key=lambda p: p[0])):
        b, c = _labelled(b, c, LABEL_OBSTACLE + k)
        boxes += b
        cylinders += c
        obstacle_kinds.append(kind)
    return boxes, cylinders, obstacle_kinds


def _draw_lights(rng, corridor: _Corridor) -> tuple[tuple[Light, ...], float]:
    """Lamps along the ceiling (one row or two) and the ambient light."""
    half, h = corridor.half_m, corridor.ceiling_m
    spacing = rng.uniform(1.5, 3.5)
    power = rng.uniform(1.2, 3.5)
    rows = [0.0] if rng.uniform() < 0.7 else [-half / 2, half / 2]
    lights = tuple(Light((float(x), float(y), h - 0.1), power * (1.0 if len(rows) == 1 else 0.6))
                   for x in np.arange(corridor.x0_m + rng.uniform(0.3, spacing), corridor.x1_m, spacing)
                   for y in rows)
    return lights, rng.uniform(0.15, 0.5)


def _draw_sensors(rng) -> tuple[SensorModel, SensorModel]:
    """Left and right exposure, gain, black level and noise (the right gain near the left one)."""
    gain = _u(rng, RANGES["gain"])
    noise = _u(rng, RANGES["noise_sigma"])
    return (SensorModel(gain=gain, black_level=_u(rng, RANGES["black_level"]), noise_sigma=noise),
            SensorModel(gain=gain * _u(rng, RANGES["right_gain_ratio"]), black_level=_u(rng, RANGES["black_level"]),
                        noise_sigma=noise * rng.uniform(0.8, 1.25)))


# --------------------------------------------------------------------------- drops (docs/world.md, "Drops")
def _slab_boxes(outer, pits, mat: int) -> list[Box]:
    """The floor slab ``outer`` (x0, x1, y0, y1), ``SLAB_DEPTH_M`` deep, without the rectangles ``pits``."""
    xs = sorted({outer[0], outer[1], *(v for p in pits for v in p[:2])})
    ys = sorted({outer[2], outer[3], *(v for p in pits for v in p[2:])})
    boxes = []
    for ya, yb in zip(ys[:-1], ys[1:]):
        run = None
        for xa, xb in zip(xs[:-1], xs[1:]):
            cx, cy = 0.5 * (xa + xb), 0.5 * (ya + yb)
            hole = any(p[0] < cx < p[1] and p[2] < cy < p[3] for p in pits)
            if not hole:
                run = (xa if run is None else run[0], xb)
            if run is not None and (hole or xb == xs[-1]):
                boxes.append(Box((run[0], ya, -SLAB_DEPTH_M), (run[1], yb, 0.0), mat, LABEL_FLOOR))
                run = None
    return boxes


def _clip_path(waypoints: np.ndarray, x_max: float) -> np.ndarray:
    """The path up to ``x = x_max`` (its waypoints' x increase)."""
    keep = waypoints[waypoints[:, 0] <= x_max]
    if len(keep) < len(waypoints):
        a, b = waypoints[len(keep) - 1], waypoints[len(keep)]
        keep = np.vstack([keep, a + (b - a) * (x_max - a[0]) / (b[0] - a[0])])
    return np.round(keep, 3)


def _draw_end(rng, corridor: _Corridor, waypoints: np.ndarray, floor: int) -> tuple:
    """A ledge (the floor ends 0.3-1.5 m above a lower floor) or a drivable ramp down to a lower floor across
    the corridor beyond the path's end: ``(pit, fill boxes, x_edge, summary)``."""
    half, x1 = corridor.half_m, corridor.x1_m
    if rng.uniform() < 0.6:
        depth = _u(rng, DROP_RANGES["ledge_depth_m"])
        x_e = min(float(waypoints[-1, 0]) + rng.uniform(0.8, 1.8), x1 - 1.0)
        pit = (x_e, x1, -half, half)
        fill = [Box((x_e, -half, -depth - 0.2), (x1, half, -depth), floor, LABEL_FLOOR)]
        return pit, fill, x_e, {"kind": "ledge", "x_m": round(x_e, 3), "depth_m": round(depth, 3)}
    slope = math.radians(_u(rng, DROP_RANGES["ramp_slope_deg"]))
    n = max(1, int(round(min(_u(rng, DROP_RANGES["ramp_depth_m"]), 3.0 * math.tan(slope)) / RAMP_RISER_M)))
    run = RAMP_RISER_M / math.tan(slope)
    x_e = min(float(waypoints[-1, 0]) + rng.uniform(0.8, 1.8), x1 - n * run - 0.5)
    pit = (x_e, x1, -half, half)
    fill = [Box((x_e + k * run, -half, -SLAB_DEPTH_M), (x_e + (k + 1) * run, half, -(k + 1) * RAMP_RISER_M),
                floor, LABEL_FLOOR) for k in range(n)]
    fill.append(Box((x_e + n * run, -half, -SLAB_DEPTH_M), (x1, half, -n * RAMP_RISER_M), floor, LABEL_FLOOR))
    return pit, fill, x_e, {"kind": "ramp", "x_m": round(x_e, 3), "depth_m": round(n * RAMP_RISER_M, 3),
                            "slope_deg": round(math.degrees(slope), 2)}


def _draw_patches(rng, corridor: _Corridor, x_end: float, path_pts: np.ndarray, placed: list,
                  floor: int) -> tuple[list, list[Box], list[dict]]:
    """Holes and stairwells down (0.3-1.5 m), a raised kerb (3-5 cm) and a sunken step (3-5 cm) beside the
    path, clear of it, of the obstacles and of each other: ``(pits, boxes, summaries)``."""
    half = corridor.half_m
    kinds = ["hole"] * int(rng.integers(DROP_RANGES["holes"][0], DROP_RANGES["holes"][1] + 1)) + ["kerb", "sunken"]
    pits, boxes, out = [], [], []
    for kind in kinds:
        for _attempt in range(80):
            sx, sy = (rng.uniform(*DROP_RANGES["hole_size_m"]) for _ in range(2))
            x = rng.uniform(0.3, max(0.31, x_end - sx - 0.3))
            y = rng.uniform(-half, half - sy) if rng.uniform() < 0.5 else rng.choice([-half, half - sy])
            rect = (x, x + sx, float(y), float(y) + sy)
            if rect[1] < x_end - 0.3 and _rect_clear(rect, path_pts, placed, 0.15):
                break
        else:
            continue
        placed.append(rect)
        x0, x1, y0, y1 = rect
        if kind == "kerb":
            h = _u(rng, DROP_RANGES["kerb_m"])
            boxes.append(Box((x0, y0, 0.0), (x1, y1, h), floor, LABEL_FLOOR))
            out.append({"kind": "kerb", "rect_m": [round(v, 3) for v in rect], "height_m": round(h, 3)})
            continue
        depth = _u(rng, DROP_RANGES["kerb_m"] if kind == "sunken" else DROP_RANGES["hole_depth_m"])
        pits.append(rect)
        boxes.append(Box((x0, y0, -depth - 0.2), (x1, y1, -depth), floor, LABEL_FLOOR))
        stairs = kind == "hole" and depth > 0.5 and rng.uniform() < 0.5
        if stairs:       # a stairwell: a flight down along x from the far side
            riser = _u(rng, DROP_RANGES["stair_riser_m"])
            for k in range(1, int(depth / riser)):
                xa = x1 - 0.27 * k
                if xa <= x0:
                    break
                boxes.append(Box((xa, y0, -depth), (xa + 0.27, y1, -k * riser), floor, LABEL_FLOOR))
        out.append({"kind": "stairwell" if stairs else kind, "rect_m": [round(v, 3) for v in rect],
                    "depth_m": round(depth, 3)})
    return pits, boxes, out


def _footprints(boxes: list[Box], cylinders: list[Cylinder]) -> dict[int, tuple]:
    """Footprint rectangle (x0, x1, y0, y1) of each obstacle label."""
    rects: dict[int, tuple] = {}
    for lo, hi, label in ([(b.min_m[:2], b.max_m[:2], b.label) for b in boxes]
                          + [((c.centre_m[0] - c.radius_m, c.centre_m[1] - c.radius_m),
                              (c.centre_m[0] + c.radius_m, c.centre_m[1] + c.radius_m), c.label) for c in cylinders]):
        r = rects.get(label, (np.inf, -np.inf, np.inf, -np.inf))
        rects[label] = (min(r[0], lo[0]), max(r[1], hi[0]), min(r[2], lo[1]), max(r[3], hi[1]))
    return rects


def _add_drops(seed: int, corridor: _Corridor, waypoints: np.ndarray, floor: int, boxes: list[Box],
               obstacle_boxes: list[Box], cylinders: list[Cylinder]) -> tuple:
    """Drops drawn from a stream of their own (the rest stays the world of ``seed``): the floor slab with its
    pits replaces the corridor's floor box ``boxes[0]``; obstacles beyond the end's edge are removed (the
    others relabelled in order) and the path stops 0.7 m before it. Returns ``(boxes, obstacle_boxes,
    cylinders, waypoints, kept labels, summary)``."""
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xC0441D0, 2]))
    end_pit, fill, x_e, end = _draw_end(rng, corridor, waypoints, floor)
    waypoints = _clip_path(waypoints, x_e - 0.7)
    rects = _footprints(obstacle_boxes, cylinders)
    keep = sorted((label for label, r in rects.items() if r[1] < x_e - 0.1), key=lambda label: rects[label][0])
    new = {label: LABEL_OBSTACLE + k for k, label in enumerate(keep)}
    obstacle_boxes = [Box(b.min_m, b.max_m, b.material, new[b.label]) for b in obstacle_boxes if b.label in new]
    cylinders = [Cylinder(c.centre_m, c.radius_m, c.height_m, c.material, new[c.label]) for c in cylinders
                 if c.label in new]
    placed = [rects[label] for label in keep]
    pits, patch_boxes, patches = _draw_patches(rng, corridor, x_e, _path_points(waypoints), placed, floor)
    slab = boxes[0]
    outer = (slab.min_m[0], slab.max_m[0], slab.min_m[1], slab.max_m[1])
    boxes = _slab_boxes(outer, [end_pit] + pits, floor) + fill + patch_boxes + boxes[1:]
    return boxes, obstacle_boxes, cylinders, waypoints, keep, {"end": end, "patches": patches}


def random_world(seed: int, *, width: int = 320, height: int = 240,
                 wall_texture: str | None = None, drops: bool = False) -> RandomWorld:
    """Draw a corridor world, its stereo rig, sensors and robot path from ``seed``.

    World frame as in :func:`mrstereo.world.default_scene`; everything the default map shows lies
    within ``|y| < 3 m``; obstacle labels ``LABEL_OBSTACLE + k`` are numbered by the x of their footprint.

    Parameters
    ----------
    seed : int
        Non-negative; the same seed gives the same world.
    width, height : int
        Image size of the rig (the field of view is drawn independently).
    wall_texture : {"paint", "tiles", "stripes", "blotch", "wood"}, optional
        The walls' material kind, drawn from a stream of its own after all other draws, so the rest
        stays the world of ``seed``.
    drops : bool
        Add drops (docs/world.md, "Drops"): a ledge or a drivable ramp down across the corridor beyond the
        path's end (the path stops 0.7 m before it, obstacles beyond it are removed), one or two holes or
        stairwells, a raised kerb and a sunken step beside the path; drawn from a stream of their own. The
        floor is wood or carpet (on paint, faint tiles or large checks stereo measures next to nothing, so
        no drop either).
        ``groundtruth.floor_heights`` / ``drop_edges`` give their truth.
    """
    seed = _checks.positive_int("seed", seed, minimum=0)
    if wall_texture is not None and wall_texture not in WALL_TEXTURES:
        raise ValueError(f"wall_texture must be one of {', '.join(WALL_TEXTURES)} or None, got {wall_texture!r}")
    # every draw comes from this one stream in a fixed order: a seed is always the same world
    rng = np.random.default_rng(np.random.SeedSequence([seed, 0xC0441D0]))
    stereo = random_stereo(rng, width, height)
    corridor = _draw_corridor(rng)
    bank = _MaterialBank()
    ids = {"wall": bank.add(_material(rng, _WALL, ["paint", "paint", "tiles", "stripes", "blotch", "wood"])),
           "floor": bank.add(_material(rng, _FLOOR, ["paint", "tiles", "tiles", "checker", "wood", "carpet", "stripes"])),
           "ceiling": bank.add(_material(rng, _CEILING, "paint" if rng.uniform() < 0.5 else "tiles")),
           "skirting": bank.add(("skirting", Material(TEXTURE_WEAK, rng.uniform(0.15, 0.6), 0.04, 0.05))),
           "door": bank.add(("door", Material(TEXTURE_WOOD, rng.uniform(0.3, 0.55), rng.uniform(0.15, 0.3), 0.05,
                                              rng.uniform(0.08, 0.13))))}
    skirting_m = float(rng.choice([0.0, 0.06, 0.1, 0.15]))
    waypoints = _draw_path(rng, corridor)
    openings, doors, taken = _draw_wall_gaps(rng, corridor)
    boxes, free_regions = _corridor_boxes(corridor.x0_m, corridor.x1_m, corridor.half_m, corridor.ceiling_m,
                                          doors=doors, openings=openings, outer_half_m=_GRID_HALF_M, ids=ids)
    decals = _draw_decals(rng, corridor, bank, taken)
    obstacle_boxes, cylinders, obstacle_kinds = _draw_obstacles(rng, corridor, bank, _path_points(waypoints))
    lights, ambient = _draw_lights(rng, corridor)
    sensors = _draw_sensors(rng)
    drop_summary = None
    if drops:
        boxes, obstacle_boxes, cylinders, waypoints, kept, drop_summary = _add_drops(
            seed, corridor, waypoints, ids["floor"], boxes, obstacle_boxes, cylinders)
        obstacle_kinds = [obstacle_kinds[label - LABEL_OBSTACLE] for label in kept]
        # a floor stereo measures everywhere (paint, faint tiles and large checks give it next to no
        # disparity, so no drop either): wood or carpet, from a stream of its own
        bank.names[ids["floor"]], bank.materials[ids["floor"]] = _material(np.random.default_rng(
            np.random.SeedSequence([seed, 0xC0441D0, 3])), _FLOOR, ["wood", "carpet"])
    wall = ids["wall"]
    if wall_texture is not None and wall_texture != bank.names[wall]:
        # after every other draw, from a stream of its own: the rest of the world stays the seed's
        bank.names[wall], bank.materials[wall] = _material(np.random.default_rng(
            np.random.SeedSequence([seed, 0xC0441D0, 1])), _WALL, wall_texture)
    scene = Scene(boxes=tuple(boxes + obstacle_boxes), cylinders=tuple(cylinders), decals=tuple(decals),
                  lights=lights, materials=tuple(bank.materials), skirting_m=skirting_m,
                  skirting_material=ids["skirting"], ambient=ambient, x_range_m=(corridor.x0_m, corridor.x1_m),
                  half_width_m=corridor.half_m, height_m=corridor.ceiling_m, seed=seed,
                  free_regions_m=tuple(free_regions))
    floor = ground_from_mount(stereo.mount, R_rect_from_cam=stereo.left.R)      # the rig's height and tilt
    summary = {
        "seed": seed, "corridor_width_m": round(corridor.width_m, 3),
        "corridor_x_range_m": [round(corridor.x0_m, 3), round(corridor.x1_m, 3)],
        "ceiling_m": round(corridor.ceiling_m, 3), "camera_height_m": round(floor.height_m, 3),
        "tilt_rad": round(floor.tilt_rad, 3), "baseline_m": round(stereo.baseline_m, 4),
        "focal_px": round(stereo.focal_px, 1),
        "textures": {"wall": bank.names[wall], "floor": bank.names[ids["floor"]],
                     "ceiling": bank.names[ids["ceiling"]],
                     "posters": [bank.names[d.material] for d in decals if d.label == LABEL_POSTER]},
        "obstacles": obstacle_kinds, "side_openings": len(openings), "doors": len(doors),
        "lamps": len(lights), "ambient": round(ambient, 3),
        "sensors": [{"gain": round(s.gain, 3), "black_level": round(s.black_level, 2),
                     "noise_sigma": round(s.noise_sigma, 2)} for s in sensors],
    }
    if drop_summary is not None:
        summary["drops"] = drop_summary
    return RandomWorld(seed=seed, scene=scene, stereo=stereo, sensors=sensors, waypoints_xy=waypoints,
                       summary=summary)
