"""The synthetic office corridor: geometry, materials and lights (paper Sec. 5, Figs. 7 and 11-14).

Axis-aligned boxes, vertical cylinders and decals painted on walls; textures are deterministic
functions of world surface coordinates keyed by ``Scene.seed``, so every camera sees the same
surface. Floor, walls and ceiling are weakly textured (what eq. (13) rejects). The corridor:
docs/world.md. Conventions: docs/conventions.md.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from .. import _checks

__all__ = [
    "Material", "Box", "Cylinder", "Decal", "Light", "Scene", "default_scene",
    "LABEL_NONE", "LABEL_FLOOR", "LABEL_WALL", "LABEL_CEILING", "LABEL_DOOR", "LABEL_POSTER",
    "LABEL_SKIRTING", "LABEL_OBSTACLE", "LABEL_NAMES", "is_obstacle_label",
    "TEXTURE_WEAK", "TEXTURE_TILES", "TEXTURE_BLOTCH", "TEXTURE_CHECKER", "TEXTURE_POSTER",
    "TEXTURE_WOOD", "TEXTURE_STRIPES_U", "TEXTURE_STRIPES_V",
]

# Surface classes of the label image. Obstacle k (0-based) has label LABEL_OBSTACLE + k.
LABEL_NONE, LABEL_FLOOR, LABEL_WALL, LABEL_CEILING = 0, 1, 2, 3
LABEL_DOOR, LABEL_POSTER, LABEL_SKIRTING = 4, 5, 6
LABEL_OBSTACLE = 10
LABEL_NAMES = {LABEL_NONE: "none", LABEL_FLOOR: "floor", LABEL_WALL: "wall", LABEL_CEILING: "ceiling",
               LABEL_DOOR: "door", LABEL_POSTER: "poster", LABEL_SKIRTING: "skirting",
               LABEL_OBSTACLE: "obstacle (10 + index)"}

# Texture kinds (Material.kind), evaluated in world/_kernels.py.
TEXTURE_WEAK, TEXTURE_TILES, TEXTURE_BLOTCH, TEXTURE_CHECKER, TEXTURE_POSTER, TEXTURE_WOOD = range(6)
TEXTURE_STRIPES_U, TEXTURE_STRIPES_V = 6, 7   # stripes across the surface's u (along x or y) / v axis


def is_obstacle_label(labels) -> np.ndarray:
    """True where a label image shows an obstacle."""
    return np.asarray(labels) >= LABEL_OBSTACLE


@dataclass(frozen=True)
class Material:
    """A procedural texture (``TEXTURE_*`` ``kind``): albedo ``albedo +- contrast`` at feature size ``scale_m``.

    ``period_m`` is the tile, checker square, plank or stripe period. Surface coordinates ``(u, v)``:
    ``(y, z)`` on faces normal to x, ``(x, z)`` normal to y, ``(x, y)`` on floors, (arc, z) on cylinders.
    """

    kind: int
    albedo: float
    contrast: float
    scale_m: float
    period_m: float = 0.0


@dataclass(frozen=True)
class Box:
    """Axis-aligned box ``min_m <= p <= max_m`` (world, metres)."""

    min_m: tuple[float, float, float]
    max_m: tuple[float, float, float]
    material: int
    label: int


@dataclass(frozen=True)
class Cylinder:
    """Vertical cylinder standing on the floor: centre ``(x, y)``, radius, height (with a top cap)."""

    centre_m: tuple[float, float]
    radius_m: float
    height_m: float
    material: int
    label: int


@dataclass(frozen=True)
class Decal:
    """A rectangle painted on the wall face ``y = y_m`` whose outward normal is ``normal_sign`` * y.

    The left wall (y > 0) faces -y (``normal_sign = -1``), the right wall faces +y.

    Covers ``x0_m <= x <= x1_m``, ``z0_m <= z <= z1_m``.
    """

    normal_sign: int
    y_m: float
    x0_m: float
    x1_m: float
    z0_m: float
    z1_m: float
    material: int
    label: int


@dataclass(frozen=True)
class Light:
    """Point light (ceiling lamp) at ``position_m`` with relative ``power``."""

    position_m: tuple[float, float, float]
    power: float


@dataclass(frozen=True)
class Scene:
    """A static scene of boxes, cylinders, decals and lights (``material`` fields index ``materials``).

    The skirting board is the band ``z < skirting_m`` of every wall face; ``ambient`` adds to the
    lamps; the free corridor space is ``x_range_m``, ``|y| < half_width_m``, ``0 < z < height_m``
    plus ``free_regions_m`` (side rooms); ``seed`` keys all textures.
    """

    boxes: tuple[Box, ...]
    cylinders: tuple[Cylinder, ...]
    decals: tuple[Decal, ...]
    lights: tuple[Light, ...]
    materials: tuple[Material, ...]
    skirting_m: float = 0.1
    skirting_material: int = 0
    ambient: float = 0.3
    x_range_m: tuple[float, float] = (-1.0, 14.5)
    half_width_m: float = 1.2
    height_m: float = 2.5
    seed: int = 0
    free_regions_m: tuple[tuple[float, float, float, float], ...] = ()

    def __post_init__(self) -> None:
        for name, kind in (("boxes", Box), ("cylinders", Cylinder), ("decals", Decal), ("lights", Light),
                           ("materials", Material)):
            items = getattr(self, name)
            if isinstance(items, (str, bytes)) or not all(isinstance(item, kind) for item in items):
                raise TypeError(f"{name} must be a sequence of {kind.__name__}, got {items!r:.60}")
        n_mat = len(self.materials)
        for prim in (*self.boxes, *self.cylinders, *self.decals):
            if not 0 <= prim.material < n_mat:
                raise ValueError(f"material index {prim.material} out of range (scene has {n_mat} materials)")
        _checks.finite_number("skirting_m", self.skirting_m, nonnegative=True)
        _checks.finite_number("ambient", self.ambient, nonnegative=True)
        for m in self.materials:
            if m.kind not in range(8):
                raise ValueError(f"material kind must be one of the TEXTURE_* constants (0-7), got {m.kind}")

    def packed(self) -> dict[str, np.ndarray]:
        """The scene as the flat arrays the render kernels take (cached)."""
        return _pack(self)


@lru_cache(maxsize=16)
def _pack(scene: Scene) -> dict[str, np.ndarray]:
    boxes = np.array([[*b.min_m, *b.max_m] for b in scene.boxes], np.float64).reshape(-1, 6)
    cyl = np.array([[*c.centre_m, c.radius_m, c.height_m] for c in scene.cylinders], np.float64).reshape(-1, 4)
    decals = np.array([[d.normal_sign, d.y_m, d.x0_m, d.x1_m, d.z0_m, d.z1_m] for d in scene.decals],
                      np.float64).reshape(-1, 6)
    mats = np.array([[m.kind, m.albedo, m.contrast, m.scale_m, m.period_m] for m in scene.materials],
                    np.float64).reshape(-1, 5)
    lights = np.array([[*li.position_m, li.power] for li in scene.lights], np.float64).reshape(-1, 4)

    def ints(items, attr):
        return np.array([getattr(p, attr) for p in items], np.int64).reshape(-1)

    out = {"boxes": boxes, "box_material": ints(scene.boxes, "material"), "box_label": ints(scene.boxes, "label"),
           "cylinders": cyl, "cylinder_material": ints(scene.cylinders, "material"),
           "cylinder_label": ints(scene.cylinders, "label"), "decals": decals,
           "decal_material": ints(scene.decals, "material"), "decal_label": ints(scene.decals, "label"),
           "materials": mats, "lights": lights}
    for arr in out.values():
        arr.setflags(write=False)
    return out


WALL_THICK_M = 0.2
DOOR_TOP_M = 2.1


def _wall_boxes(side: int, x0: float, x1: float, y_in: float, thickness: float, height: float,
                gaps: list[tuple[float, float, float]], wall_mat: int) -> list[Box]:
    """Wall on one side with door openings ``(xa, xb, top_z)``: segments plus lintels."""
    y_a, y_b = sorted((side * y_in, side * (y_in + thickness)))
    out, x = [], x0
    for xa, xb, top in sorted(gaps):
        out.append(Box((x, y_a, 0.0), (xa, y_b, height), wall_mat, LABEL_WALL))
        if top < height:
            out.append(Box((xa, y_a, top), (xb, y_b, height), wall_mat, LABEL_WALL))
        x = xb
    out.append(Box((x, y_a, 0.0), (x1, y_b, height), wall_mat, LABEL_WALL))
    return out


def _corridor_boxes(x0: float, x1: float, half: float, h: float, *, doors, openings=(), outer_half_m: float,
                    ids: dict[str, int]) -> tuple[list[Box], list]:
    """Floor and ceiling (to ``|y| = outer_half_m + 1``), end walls, side walls at ``y = +-half`` with
    their gaps, door recesses ``(side, xa, xb)`` and the small rooms behind openings ``(side, xa, xb,
    top, depth)``; returns the boxes and the rooms' floor rectangles ``(xa, xb, ya, yb)``.
    ``ids``: the materials of wall, floor, ceiling and door."""
    t, wall = WALL_THICK_M, ids["wall"]
    boxes: list[Box] = [
        Box((x0 - 1.0, -outer_half_m - 1.0, -0.2), (x1 + 1.0, outer_half_m + 1.0, 0.0), ids["floor"], LABEL_FLOOR),
        Box((x0 - 1.0, -outer_half_m - 1.0, h), (x1 + 1.0, outer_half_m + 1.0, h + 0.2), ids["ceiling"],
            LABEL_CEILING),
        Box((x0 - t, -half, 0.0), (x0, half, h), wall, LABEL_WALL),
        Box((x1, -half, 0.0), (x1 + t, half, h), wall, LABEL_WALL),
    ]
    free_regions = []
    for side in (+1, -1):
        gaps = ([(xa, xb, DOOR_TOP_M) for s, xa, xb in doors if s == side]
                + [(xa, xb, top) for s, xa, xb, top, _ in openings if s == side])
        boxes += _wall_boxes(side, x0, x1, half, t, h, gaps, wall)
        for s, xa, xb in doors:
            if s == side:
                ya, yb = sorted((side * (half + 0.1), side * (half + t)))        # the door 0.1 m back
                boxes.append(Box((xa, ya, 0.0), (xb, yb, DOOR_TOP_M), ids["door"], LABEL_DOOR))
        for s, xa, xb, top, depth in openings:
            if s != side:
                continue
            # a small room behind the opening: back wall and two side walls
            y_in, y_back = side * half, side * (half + depth)
            ya, yb = sorted((y_back, y_back + side * t))
            boxes.append(Box((xa - t, ya, 0.0), (xb + t, yb, h), wall, LABEL_WALL))
            ya, yb = sorted((y_in, y_back))
            boxes.append(Box((xa - t, ya, 0.0), (xa, yb, h), wall, LABEL_WALL))
            boxes.append(Box((xb, ya, 0.0), (xb + t, yb, h), wall, LABEL_WALL))
            free_regions.append((xa, xb, ya, yb))
    return boxes, free_regions


def default_scene(seed: int = 0) -> Scene:
    """The default office corridor (about 15.5 m x 2.4 m x 2.5 m) with six obstacles (docs/world.md).

    ``seed`` (non-negative) keys the textures only: ground-truth maps of different seeds coincide.
    """
    seed = _checks.positive_int("seed", seed, minimum=0)
    materials = (
        Material(TEXTURE_WEAK, 0.72, 0.035, 0.25),            # 0 wall paint (weak)
        Material(TEXTURE_TILES, 0.50, 0.04, 0.20, 0.6),       # 1 floor tiles (weak)
        Material(TEXTURE_WEAK, 0.80, 0.03, 0.40),             # 2 ceiling (weak)
        Material(TEXTURE_WOOD, 0.45, 0.25, 0.05, 0.11),       # 3 wooden door
        Material(TEXTURE_WEAK, 0.25, 0.05, 0.05),             # 4 skirting board (dark)
        Material(TEXTURE_POSTER, 0.55, 0.45, 0.035),          # 5 poster
        Material(TEXTURE_BLOTCH, 0.50, 0.45, 0.05),           # 6 obstacle, blotchy
        Material(TEXTURE_CHECKER, 0.50, 0.40, 0.03, 0.08),    # 7 obstacle, checker
        Material(TEXTURE_WOOD, 0.30, 0.30, 0.04, 0.07),       # 8 coloured (dark) door panel
        Material(TEXTURE_BLOTCH, 0.60, 0.40, 0.03),           # 9 obstacle, fine blotches
    )
    WALL, FLOOR, CEIL, DOOR, SKIRT, POSTER, OBST_A, OBST_B, PANEL, OBST_C = range(10)
    x0, x1, half, h = -1.0, 14.5, 1.2, 2.5
    doors = [(side, xa, xa + 0.9) for side, xa in ((+1, 3.0), (+1, 8.4), (-1, 5.2), (-1, 11.0))]   # recessed
    boxes, _ = _corridor_boxes(x0, x1, half, h, doors=doors, outer_half_m=half,
                               ids={"wall": WALL, "floor": FLOOR, "ceiling": CEIL, "door": DOOR})
    # obstacles labelled in the order of their near face's distance from the start
    obst_boxes = [Box((0.6, -0.55, 0.0), (0.9, -0.25, 0.4), OBST_A, LABEL_OBSTACLE),
                  Box((2.6, 0.75, 0.0), (3.0, 1.2, 0.8), OBST_B, LABEL_OBSTACLE + 2),
                  Box((6.0, -0.25, 0.0), (6.4, 0.25, 0.6), OBST_C, LABEL_OBSTACLE + 4),
                  Box((9.0, -1.2, 0.0), (9.5, -0.7, 1.2), OBST_A, LABEL_OBSTACLE + 5)]
    obst_cyls = [Cylinder((1.8, 0.55), 0.15, 0.7, OBST_B, LABEL_OBSTACLE + 1),
                 Cylinder((3.9, -0.6), 0.2, 0.5, OBST_C, LABEL_OBSTACLE + 3)]
    boxes += obst_boxes
    decals = (
        # The left wall (y = +half) faces -y, the right wall (y = -half) faces +y.
        Decal(-1, half, 5.0, 5.8, 1.1, 1.9, POSTER, LABEL_POSTER),
        Decal(-1, half, 10.3, 11.0, 1.2, 1.8, POSTER, LABEL_POSTER),
        Decal(+1, -half, 2.5, 3.2, 1.0, 1.7, POSTER, LABEL_POSTER),
        Decal(+1, -half, 7.9, 8.9, 1.1, 1.9, POSTER, LABEL_POSTER),
        Decal(+1, -half, 12.6, 13.2, 1.2, 1.8, POSTER, LABEL_POSTER),
        Decal(-1, half, 12.0, 12.9, 0.0, DOOR_TOP_M, PANEL, LABEL_DOOR),
        Decal(+1, -half, 1.0, 1.9, 0.0, DOOR_TOP_M, PANEL, LABEL_DOOR),
    )
    lights = tuple(Light((float(x), 0.0, h - 0.1), 2.4) for x in np.arange(0.5, 14.0, 2.5))
    return Scene(boxes=tuple(boxes), cylinders=tuple(obst_cyls), decals=decals, lights=lights,
                 materials=materials, skirting_m=0.1, skirting_material=SKIRT, ambient=0.3,
                 x_range_m=(x0, x1), half_width_m=half, height_m=h, seed=seed)
