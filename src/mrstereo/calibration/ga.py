"""Camera calibration by a real-coded genetic algorithm, paper section 2.2 (eq. 4-8).

The chromosome of eq. (4) is ``C = [f, u0, v0, k1, k2, alpha, beta, gamma, X, Y, Z]`` in the
paper's parameterization (:class:`mrstereo.camera.PaperCamera`). Table 2: N = 100, pc = 0.8,
pm = 0.1, elitism; uniform initialisation within the bounds (eq. 5); fitness eq. (6), the sum of
squared reprojection errors in px^2; tournament selection; crossover ``(1 - w) C_i + w C_i+1``
with ``w = pc`` (eq. 7-8 as printed); the "reciprocal" mutation read as Michalewicz's non-uniform
mutation toward one bound. With several planar views the search keeps the intrinsic genes
``[f, u0, v0, k1, k2]`` and each view's pose comes in closed form from a homography (Zhang). Each
choice and its measurements: docs/calibration.md, "The paper's GA (eq. 4-8)".
Conventions: docs/conventions.md.

References
----------
Q. Ji, Y. Zhang, "Camera calibration with genetic algorithms", IEEE T-SMC-A
31(2):120-130, 2001. Z. Michalewicz, "Genetic Algorithms + Data Structures =
Evolution Programs", Springer 1996 (non-uniform mutation). Z. Zhang, "A flexible
new technique for camera calibration", IEEE T-PAMI 22(11), 2000.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, fields
from typing import Callable, Sequence

import numpy as np

from .. import _checks
from ..camera import Camera, PaperCamera, normalized_from_pixels, project_points, undistort_normalized
from ..transforms import T_from_R_t, rotation_from_rpy
from .targets import CalibrationView

__all__ = ["GENES", "GABounds", "GAConfig", "GAResult", "paper_bounds", "default_bounds",
           "default_pixel_density", "MULTIVIEW_GA", "homography_poses", "ga_calibrate_single",
           "ga_calibrate_intrinsics"]

GENES = ("f_mm", "u0_px", "v0_px", "k1_mm", "k2_mm", "alpha_rad", "beta_rad", "gamma_rad",
         "X_m", "Y_m", "Z_m")


@dataclass(frozen=True)
class GABounds:
    """Lower and upper bound of every gene of eq. (4) (Table 1), as ``(lo, hi)``."""

    f_mm: tuple[float, float]
    u0_px: tuple[float, float]
    v0_px: tuple[float, float]
    k1_mm: tuple[float, float]
    k2_mm: tuple[float, float]
    alpha_rad: tuple[float, float] = (-math.pi / 4, math.pi / 4)
    beta_rad: tuple[float, float] = (-math.pi / 4, math.pi / 4)
    gamma_rad: tuple[float, float] = (-math.pi / 4, math.pi / 4)
    X_m: tuple[float, float] = (-0.9, 0.9)
    Y_m: tuple[float, float] = (-0.5, 0.5)
    Z_m: tuple[float, float] = (1.0, 2.0)

    def __post_init__(self) -> None:
        for f in fields(self):
            pair = _checks.ordered_pair(f"bound {f.name}", getattr(self, f.name), strict=False)
            object.__setattr__(self, f.name, pair)
        if self.f_mm[0] <= 0:
            raise ValueError(f"bound f_mm must be positive, got {self.f_mm}")

    def array(self) -> np.ndarray:
        """Bounds as an array of shape (2, 11): row 0 lower, row 1 upper, order of :data:`GENES`."""
        return np.array([getattr(self, g) for g in GENES]).T


def paper_bounds() -> GABounds:
    """Table 1 of the paper in our units and camera frame (z forward: its Z in [-2000, -1000] mm
    is Z in [1, 2] m; the garbled X, Y bounds are read as [-0.9, 0.9] and [-0.5, 0.5] m)."""
    return GABounds(f_mm=(6.0, 9.0), u0_px=(220.0, 360.0), v0_px=(220.0, 360.0),
                    k1_mm=(-1e-3, 1e-3), k2_mm=(-1e-3, 1e-3))


def default_pixel_density(width: int) -> float:
    """Pixel density [px/mm] assumed when none is given: a 1/3" sensor (4.8 mm) spans the width."""
    return width / 4.8


def default_bounds(views: Sequence[CalibrationView] | CalibrationView, *, width: int, height: int,
                   pixel_density_px_per_mm: float | None = None) -> GABounds:
    """Bounds derived from the image size and the target (rules: docs/calibration.md).

    ``fx`` in [0.4 W, 2.5 W], the principal point in the central 30 %, ``|k1|, |k2| <= 0.5`` on
    normalized coordinates, ``gamma`` in [-pi, pi] (the target's Z axis points away from the
    camera), the translation from a rough depth ``fx * extent_m / extent_px`` of every view.
    """
    views = [views] if isinstance(views, CalibrationView) else list(views)
    width = _checks.positive_int("width", width)
    height = _checks.positive_int("height", height)
    density = (default_pixel_density(width) if pixel_density_px_per_mm is None
               else _checks.finite_number("pixel_density_px_per_mm", pixel_density_px_per_mm, positive=True))
    f_px = (0.4 * width, 2.5 * width)
    f_mid_mm = math.sqrt(f_px[0] * f_px[1]) / density
    d_lo, d_hi, reach = math.inf, 0.0, 0.0
    for view in views:
        p, uv = view.points_target, view.uv
        ext_m = float(np.linalg.norm(np.ptp(p, axis=0)))
        ext_px = max(float(np.linalg.norm(np.ptp(uv, axis=0))), 1.0)
        r = float(np.linalg.norm(p.mean(axis=0)))
        d_lo = min(d_lo, 0.5 * f_px[0] * ext_m / ext_px - r)
        d_hi = max(d_hi, 1.5 * f_px[1] * ext_m / ext_px + r)
        reach = max(reach, 0.5 * ext_m + r)
    d_lo = max(d_lo, 1e-3)
    return GABounds(
        f_mm=(f_px[0] / density, f_px[1] / density),
        u0_px=(0.35 * width, 0.65 * width), v0_px=(0.35 * height, 0.65 * height),
        k1_mm=(-0.5 / f_mid_mm**2, 0.5 / f_mid_mm**2), k2_mm=(-0.5 / f_mid_mm**4, 0.5 / f_mid_mm**4),
        gamma_rad=(-math.pi, math.pi), X_m=(-reach, reach), Y_m=(-reach, reach), Z_m=(d_lo, d_hi))


@dataclass(frozen=True)
class GAConfig:
    """Genetic algorithm settings (Table 2 defaults: N = 100, pc = 0.8, pm = 0.1, elitism).

    ``mixing_weight``: None = ``pc`` (eq. 7-8 as printed), a number in [0, 1], or ``"uniform"``
    (a random weight per pair). ``max_points_per_view`` (multi-view GA only): the search's fitness
    uses at most this many evenly spread points of each view (None: all; ``history`` is over
    those); the result's fitness, RMS and poses use all points (LM, seeded by the GA, uses every
    point anyway). Several views use ``MULTIVIEW_GA``.
    """

    population: int = 100
    crossover_probability: float = 0.8
    mutation_probability: float = 0.1
    mixing_weight: float | str | None = None
    elite: int = 2
    tournament: int = 3
    generations: int = 2000
    stall_generations: int = 200
    tolerance: float = 1e-10
    mutation_shape: float = 3.0
    max_points_per_view: int | None = None

    def __post_init__(self) -> None:
        _checks.positive_int("population", self.population, minimum=4)
        _checks.positive_int("generations", self.generations)
        _checks.positive_int("stall_generations", self.stall_generations)
        _checks.positive_int("elite", self.elite, minimum=0)
        _checks.positive_int("tournament", self.tournament)
        if self.elite >= self.population:
            raise ValueError(f"elite must be < population, got {self.elite} >= {self.population}")
        for name in ("crossover_probability", "mutation_probability"):
            v = _checks.finite_number(name, getattr(self, name))
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"{name} must be within [0, 1], got {v}")
        _checks.finite_number("tolerance", self.tolerance, nonnegative=True)
        _checks.finite_number("mutation_shape", self.mutation_shape, positive=True)
        if self.max_points_per_view is not None:
            _checks.positive_int("max_points_per_view", self.max_points_per_view, minimum=4)
        w = self.mixing_weight
        if isinstance(w, str) and w != "uniform":
            raise ValueError(f"mixing_weight must be a number in [0, 1], None or 'uniform', got {w!r}")
        if w is not None and w != "uniform":
            v = _checks.finite_number("mixing_weight", w)
            if not 0.0 <= v <= 1.0:
                raise ValueError(f"mixing_weight must be within [0, 1], None or 'uniform', got {w}")


@dataclass(frozen=True)
class GAResult:
    """Outcome of a GA run.

    ``genes`` is the best chromosome (order of :data:`GENES`, or its first five
    for the multi-view GA); ``fitness`` its eq. (6) value [px^2]; ``history`` the
    best fitness after every generation; ``camera`` the converted :class:`Camera`;
    ``poses`` one 4x4 ``T_cam_from_target`` per view.
    """

    genes: np.ndarray
    fitness: float
    rms_px: float
    generations: int
    history: np.ndarray
    stop_reason: str
    camera: Camera
    poses: tuple[np.ndarray, ...]
    paper_camera: PaperCamera = field(repr=False, default=None)


MULTIVIEW_GA = GAConfig(generations=200, stall_generations=50, max_points_per_view=60)


def _evolve(fitness: Callable[[np.ndarray], np.ndarray], lo: np.ndarray, hi: np.ndarray, config: GAConfig,
            rng: np.random.Generator, progress=None) -> tuple[np.ndarray, float, int, np.ndarray, str]:
    """Generic real-coded GA loop (module notes); minimizes ``fitness`` over the box [lo, hi]."""
    n_pop, n_genes = config.population, lo.size
    span = hi - lo
    pop = lo + rng.random((n_pop, n_genes)) * span                     # eq. (5)
    fit = fitness(pop)
    history = []
    best = float(np.min(fit))
    last_improvement, stop = 0, "generation limit reached"
    n_child = n_pop - config.elite
    n_pairs = (n_child + 1) // 2
    gen = 0
    for gen in range(1, config.generations + 1):
        order = np.argsort(fit, kind="stable")
        elites = pop[order[:config.elite]]
        # tournaments fill the mating pool
        entrants = rng.integers(0, n_pop, size=(config.tournament, 2 * n_pairs))
        winners = entrants[np.argmin(fit[entrants], axis=0), np.arange(2 * n_pairs)]
        p1, p2 = pop[winners[0::2]], pop[winners[1::2]]
        # arithmetic crossover, eq. (7)-(8)
        if config.mixing_weight == "uniform":
            w = rng.random((n_pairs, 1))
        else:
            w = config.crossover_probability if config.mixing_weight is None else float(config.mixing_weight)
        cross = rng.random((n_pairs, 1)) < config.crossover_probability
        c1 = np.where(cross, (1.0 - w) * p1 + w * p2, p1)
        c2 = np.where(cross, (1.0 - w) * p2 + w * p1, p2)
        children = np.concatenate([c1, c2])[:n_child]
        # bound-directed non-uniform ("reciprocal") mutation
        mutate = rng.random(children.shape) < config.mutation_probability
        up = rng.random(children.shape) < 0.5
        frac = 1.0 - rng.random(children.shape) ** ((1.0 - (gen - 1) / config.generations) ** config.mutation_shape)
        moved = np.where(up, children + (hi - children) * frac, children - (children - lo) * frac)
        children = np.clip(np.where(mutate, moved, children), lo, hi)
        pop = np.concatenate([elites, children])
        fit = np.concatenate([fit[order[:config.elite]], fitness(children)])
        now = float(np.min(fit))
        if now < best - config.tolerance * max(abs(best), 1e-300):
            last_improvement = gen
        best = min(best, now)
        history.append(best)
        if progress is not None:
            progress(gen, best)
        if gen - last_improvement >= config.stall_generations:
            stop = f"no improvement for {config.stall_generations} generations"
            break
    i = int(np.argmin(fit))
    return pop[i].copy(), float(fit[i]), gen, np.asarray(history), stop


def _paper_to_opencv(genes: np.ndarray, density: float, aspect: float):
    """Exact conversion of (..., 5+) paper genes to fx, fy, cx, cy, k1, k2 (normalized)."""
    f = genes[..., 0]
    return (f * density, f * density * aspect, genes[..., 1], genes[..., 2],
            genes[..., 3] * f**2, genes[..., 4] * f**4)


def _sum_sq(uv_hat: np.ndarray, uv: np.ndarray) -> np.ndarray:
    err = np.sum((uv_hat - uv) ** 2, axis=(-2, -1))
    return np.where(np.isfinite(err), err, np.inf)


def _check_common(views, width, height, density, aspect, bounds):
    """Checked ``(width, height, density, aspect, bounds)``; default bounds from ``views``."""
    width = _checks.positive_int("width", width)
    height = _checks.positive_int("height", height)
    density = (default_pixel_density(width) if density is None
               else _checks.finite_number("pixel_density_px_per_mm", density, positive=True))
    aspect = _checks.finite_number("aspect", aspect, positive=True)
    if bounds is None:
        bounds = default_bounds(views, width=width, height=height, pixel_density_px_per_mm=density)
    if not isinstance(bounds, GABounds):
        raise TypeError(f"bounds must be GABounds, got {type(bounds).__name__}")
    return width, height, density, aspect, bounds


def _result(evolved: tuple, poses, n_points: int, width: int, height: int, density: float,
            aspect: float) -> GAResult:
    """The :class:`GAResult` of ``_evolve``'s ``(genes, fitness, generations, history, stop)``."""
    genes, fit, gens, history, stop = evolved
    paper = PaperCamera(width=width, height=height, f_mm=genes[0], alpha_x=density, alpha_y=density * aspect,
                        u0=genes[1], v0=genes[2], k1_mm=genes[3], k2_mm=genes[4])
    return GAResult(genes=genes, fitness=fit, rms_px=math.sqrt(fit / n_points), generations=gens,
                    history=history, stop_reason=stop, camera=paper.to_camera(), poses=tuple(poses),
                    paper_camera=paper)


def ga_calibrate_single(view: CalibrationView, *, width: int, height: int, bounds: GABounds | None = None,
                        config: GAConfig | None = None, pixel_density_px_per_mm: float | None = None,
                        aspect: float = 1.0, rng=None, progress=None) -> GAResult:
    """The paper's GA (eq. 4-8) on one view: 11 genes, intrinsics and pose.

    Parameters
    ----------
    view : CalibrationView
        Control points (any 3D layout; planar is fine).
    width, height : int
        Image size in pixels.
    bounds : GABounds, optional
        Gene bounds; default :func:`default_bounds` of the view (:func:`paper_bounds` is Table 1).
    config : GAConfig, optional
        Table 2 defaults.
    pixel_density_px_per_mm : float, optional
        ``alpha_x`` of eq. (2); default :func:`default_pixel_density`.
    aspect : float
        ``alpha_y / alpha_x`` (1 = square pixels).
    rng : numpy Generator, int or None
        Seed; the same seed gives the same result.
    progress : callable(generation, best_fitness), optional
        Called after every generation.
    """
    _checks.instance("view", view, CalibrationView)
    width, height, density, aspect, bounds = _check_common(view, width, height, pixel_density_px_per_mm,
                                                           aspect, bounds)
    config = GAConfig() if config is None else config
    lo, hi = bounds.array()
    pts, uv = view.points_target, view.uv

    def fitness(pop: np.ndarray) -> np.ndarray:                        # eq. (6)
        fx, fy, cx, cy, k1, k2 = _paper_to_opencv(pop, density, aspect)
        R = rotation_from_rpy(pop[:, 5], pop[:, 6], pop[:, 7])
        points_cam = pts @ np.swapaxes(R, -1, -2) + pop[:, None, 8:11]     # batched BLAS, (P, N, 3)
        uv_hat = project_points(points_cam, fx=fx, fy=fy, cx=cx, cy=cy, k1=k1, k2=k2)
        return _sum_sq(uv_hat, uv)

    evolved = _evolve(fitness, lo, hi, config, _checks.rng(rng), progress)
    genes = evolved[0]
    return _result(evolved, [T_from_R_t(rotation_from_rpy(*genes[5:8]), genes[8:11])], len(pts), width, height,
                   density, aspect)


def _hartley(points_xy: np.ndarray) -> np.ndarray:
    c = points_xy.mean(axis=0)
    s = math.sqrt(2.0) / max(float(np.mean(np.linalg.norm(points_xy - c, axis=1))), 1e-12)
    return np.array([[s, 0.0, -s * c[0]], [0.0, s, -s * c[1]], [0.0, 0.0, 1.0]])


def homography_poses(points_target: np.ndarray, xy_n: np.ndarray, T_norm: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Batch pose from a plane-to-image homography (Zhang 2000, sec. 3.1 / appendix).

    ``points_target`` (N, 3) with Z = 0, ``xy_n`` (..., N, 2) undistorted
    normalized image points. Returns ``R`` (..., 3, 3) and ``t`` (..., 3) with
    ``t_z > 0``.
    """
    XY = points_target[:, :2]
    T_norm = _hartley(XY) if T_norm is None else T_norm
    Xn = XY @ T_norm[:2, :2].T + T_norm[:2, 2]
    n = len(Xn)
    x, y = xy_n[..., 0], xy_n[..., 1]
    batch = xy_n.shape[:-2]
    A = np.zeros(batch + (2 * n, 9))
    A[..., 0::2, 0] = Xn[:, 0]
    A[..., 0::2, 1] = Xn[:, 1]
    A[..., 0::2, 2] = 1.0
    A[..., 1::2, 3] = Xn[:, 0]
    A[..., 1::2, 4] = Xn[:, 1]
    A[..., 1::2, 5] = 1.0
    A[..., 0::2, 6] = -x * Xn[:, 0]
    A[..., 0::2, 7] = -x * Xn[:, 1]
    A[..., 0::2, 8] = -x
    A[..., 1::2, 6] = -y * Xn[:, 0]
    A[..., 1::2, 7] = -y * Xn[:, 1]
    A[..., 1::2, 8] = -y
    # h33 = 1 (the target centroid is in front of the camera): 8x8 normal equations
    At = np.swapaxes(A[..., :8], -1, -2)
    h8 = np.linalg.solve(At @ A[..., :8], -(At @ A[..., 8:9]))[..., 0]
    H = np.concatenate([h8, np.ones(batch + (1,))], axis=-1).reshape(batch + (3, 3)) @ T_norm
    h1, h2, h3 = H[..., :, 0], H[..., :, 1], H[..., :, 2]
    s = 2.0 / (np.linalg.norm(h1, axis=-1) + np.linalg.norm(h2, axis=-1))
    s = np.where(h3[..., 2] < 0, -s, s)
    r1, r2 = h1 * s[..., None], h2 * s[..., None]
    R0 = np.stack([r1, r2, np.cross(r1, r2)], axis=-1)
    U, _, Vt = np.linalg.svd(R0)
    R = U @ Vt
    return R, h3 * s[..., None]


def ga_calibrate_intrinsics(views: Sequence[CalibrationView], *, width: int, height: int,
                            bounds: GABounds | None = None, config: GAConfig | None = None,
                            pixel_density_px_per_mm: float | None = None, aspect: float = 1.0,
                            rng=None, progress=None) -> GAResult:
    """Multi-view GA over the intrinsic genes ``[f, u0, v0, k1, k2]`` of eq. (4).

    Every view must be planar with Z = 0 (a chessboard). Per candidate and view
    the pose comes from the homography of the undistorted points (module notes);
    the fitness is eq. (6) summed over all views. Parameters as
    :func:`ga_calibrate_single`.
    """
    views = list(views)
    if not views or not all(isinstance(v, CalibrationView) for v in views):
        raise TypeError("views must be a non-empty sequence of CalibrationView")
    if not all(v.is_planar for v in views):
        raise ValueError("the multi-view GA needs planar targets with Z = 0 in every view")
    width, height, density, aspect, bounds = _check_common(views, width, height, pixel_density_px_per_mm,
                                                           aspect, bounds)
    config = MULTIVIEW_GA if config is None else config
    lo, hi = bounds.array()[:, :5]
    # views sharing the same target points (a chessboard) are evaluated as one batch
    groups: list[tuple[np.ndarray, np.ndarray, np.ndarray, list[int]]] = []
    for i, view in enumerate(views):
        for pts, _, _, members in groups:
            if pts.shape == view.points_target.shape and np.array_equal(pts, view.points_target):
                members.append(i)
                break
        else:
            groups.append((view.points_target, _hartley(view.points_target[:, :2]), None, [i]))
    groups = [(pts, Tn, np.stack([views[i].uv for i in members]), members) for pts, Tn, _, members in groups]
    n_max = config.max_points_per_view
    searched = [(pts[k], Tn, uv[:, k], members) for pts, Tn, uv, members in groups
                for k in [np.unique(np.linspace(0, len(pts) - 1, min(len(pts), n_max or len(pts))).round().astype(int))]]

    def poses_of(pop: np.ndarray, groups=searched):
        fx, fy, cx, cy, k1, k2 = (v[:, None] for v in _paper_to_opencv(pop, density, aspect))
        for pts, Tn, uv, members in groups:
            xy = undistort_normalized(normalized_from_pixels(uv[None], fx, fy, cx, cy), k1, k2, iterations=8)
            R, t = homography_poses(pts, xy, Tn)                        # (P, V, 3, 3), (P, V, 3)
            yield pts, uv, members, R, t

    def fitness(pop: np.ndarray, groups=searched) -> np.ndarray:       # eq. (6), summed over views
        fx, fy, cx, cy, k1, k2 = (v[:, None] for v in _paper_to_opencv(pop, density, aspect))
        total = np.zeros(len(pop))
        for pts, uv, _, R, t in poses_of(pop, groups):
            uv_hat = project_points(pts @ np.swapaxes(R, -1, -2) + t[..., None, :], fx=fx, fy=fy, cx=cx, cy=cy,
                                    k1=k1, k2=k2)
            total += np.sum((uv_hat - uv[None]) ** 2, axis=(-3, -2, -1))
        return np.where(np.isfinite(total), total, np.inf)

    genes, fit, gens, history, stop = _evolve(fitness, lo, hi, config, _checks.rng(rng), progress)
    if any(len(sub[0]) < len(full[0]) for sub, full in zip(searched, groups)):
        fit = float(fitness(genes[None, :], groups)[0])                # eq. (6) over all points
    poses: list = [None] * len(views)
    for _, _, members, R, t in poses_of(genes[None, :], groups):
        for j, i in enumerate(members):
            poses[i] = T_from_R_t(R[0, j], t[0, j])
    return _result((genes, fit, gens, history, stop), poses, sum(len(v.uv) for v in views), width, height,
                   density, aspect)
