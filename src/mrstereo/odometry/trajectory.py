"""Trajectories: TUM files, alignment and error metrics (as the ``evo`` tools compute them), figures.

TUM format: one line ``t tx ty tz qx qy qz qw`` per pose (the base in the world), ``#`` comments.
Metrics (:func:`trajectory_metrics`; definitions in docs/odometry.md, Metrics): ATE after a
rigid Umeyama alignment (``evo_ape -a``) and unaligned, RPE per metre over consecutive segments of
the true path (``evo_rpe --delta 1 --delta_unit m --pairs_from_reference``; with ``all_pairs``,
``--all_pairs``; divided by the 1 m), RPE per frame (``evo_rpe --delta 1 --delta_unit f``; also in % of
the mean true step: meaningful on a drive of a few frames), end-point error. Conventions: docs/conventions.md.

References
----------
S. Umeyama. Least-squares estimation of transformation parameters between two point patterns.
IEEE TPAMI 13(4), 1991. J. Sturm et al. A benchmark for the evaluation of RGB-D SLAM systems.
IROS 2012 (ATE, RPE, the TUM format). M. Grupp. evo: Python package for the evaluation of
odometry and SLAM. https://github.com/MichaelGrupp/evo, 2017.
"""
from __future__ import annotations

import math
import os
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from ..io import atomic_write
from ..transforms import T_from_position_quaternion, T_from_R_t, quaternion_from_rotation, rotation_angle_rad

__all__ = ["write_tum", "read_tum", "umeyama_alignment", "TrajectoryMetrics", "trajectory_metrics",
           "path_length_m", "plot_trajectories", "moved_to_body",
           "rpe_pairs"]


def _poses(name: str, T) -> np.ndarray:
    T = np.asarray(T, dtype=np.float64)
    if T.ndim != 3 or T.shape[1:] != (4, 4) or len(T) == 0:
        raise ValueError(f"{name} must have shape (N, 4, 4) with N >= 1, got {T.shape}")
    if not np.isfinite(T).all():
        raise ValueError(f"{name} contains NaN or inf")
    return T


def write_tum(path: str | os.PathLike, stamps_s, T_world_from_base, *, comment: str | None = None) -> Path:
    """Write poses as a TUM trajectory file (atomically); returns the path."""
    T = _poses("T_world_from_base", T_world_from_base)
    stamps = np.asarray(stamps_s, dtype=np.float64).ravel()
    if stamps.shape != (len(T),) or not np.isfinite(stamps).all():
        raise ValueError(f"stamps_s must be {len(T)} finite numbers, got shape {stamps.shape}")
    lines = [f"# {line}" for line in (comment or "").splitlines()]
    lines.append("# t tx ty tz qx qy qz qw")
    for t, pose in zip(stamps, T):
        q = quaternion_from_rotation(pose[:3, :3])
        lines.append(" ".join([f"{t:.9f}"] + [f"{v:.9f}" for v in (*pose[:3, 3], *q)]))
    path = Path(path)
    with atomic_write(path) as tmp:
        tmp.write_text("\n".join(lines) + "\n")
    return path


def read_tum(path: str | os.PathLike) -> tuple[np.ndarray, np.ndarray]:
    """Read a TUM trajectory: ``(stamps_s (N,), T_world_from_base (N, 4, 4))``."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"trajectory file not found: {path}")
    stamps, poses = [], []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        line = line.strip()
        if not line or line.startswith("#"):
            continue
        try:
            values = [float(v) for v in line.replace(",", " ").split()]
        except ValueError:
            raise ValueError(f"trajectory {path} line {n}: expected 8 numbers 't tx ty tz qx qy qz qw'") from None
        if len(values) != 8 or not all(math.isfinite(v) for v in values):
            raise ValueError(f"trajectory {path} line {n}: expected 8 finite numbers 't tx ty tz qx qy qz qw', "
                             f"got {len(values)}")
        try:
            poses.append(T_from_position_quaternion(values[1:4], values[4:]))
        except ValueError as exc:
            raise ValueError(f"trajectory {path} line {n}: {exc}") from None
        stamps.append(values[0])
    if not poses:
        raise ValueError(f"trajectory {path} has no poses")
    return np.array(stamps), np.stack(poses)


def umeyama_alignment(source_xyz, target_xyz, *, planar: bool = False) -> np.ndarray:
    """The rigid motion ``T`` (4x4) minimizing ``sum |T source_i - target_i|^2`` (Umeyama 1991).

    ``planar``: a rotation about z and a translation in x, y only (SE(2)).
    """
    src = np.asarray(source_xyz, dtype=np.float64)
    dst = np.asarray(target_xyz, dtype=np.float64)
    if src.shape != dst.shape or src.ndim != 2 or src.shape[1] != 3:
        raise ValueError(f"source_xyz and target_xyz must both be (N, 3), got {src.shape} and {dst.shape}")
    dims = 2 if planar else 3
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    cov = (dst - mu_d)[:, :dims].T @ (src - mu_s)[:, :dims] / len(src)
    U, _, Vt = np.linalg.svd(cov)
    S = np.eye(dims)
    if np.linalg.det(U) * np.linalg.det(Vt) < 0:
        S[-1, -1] = -1.0
    R = np.eye(3)
    R[:dims, :dims] = U @ S @ Vt
    T = T_from_R_t(R, mu_d - R @ mu_s)
    if planar:
        T[2, 3] = 0.0
    return T


def path_length_m(T) -> float:
    """Length of the polyline through the positions."""
    p = _poses("T", T)[:, :3, 3]
    return float(np.linalg.norm(np.diff(p, axis=0), axis=1).sum())


@dataclass(frozen=True)
class TrajectoryMetrics:
    """Errors of an estimated trajectory against the truth (metres, degrees; docs/odometry.md).

    ``ate_rmse_m`` after the ``alignment`` (no scale) and ``ate_rmse_unaligned_m`` from the common
    first pose; ``rpe_translation_per_m`` and ``rpe_rotation_deg_per_m`` over pairs ``delta_m`` apart
    (``all_pairs``: every frame starts one, else consecutive segments; NaN if the path is shorter);
    ``rpe_translation_per_frame_m`` and ``rpe_rotation_deg_per_frame`` over consecutive frames (RMSE, as
    ``evo_rpe --delta 1 --delta_unit f``; NaN for a single pose) and ``mean_step_m``, the true path's mean
    step; ``end_point_error_m``; ``path_length_m`` of the true path; ``n_poses``.
    """

    ate_rmse_m: float
    ate_rmse_unaligned_m: float
    rpe_translation_per_m: float
    rpe_rotation_deg_per_m: float
    end_point_error_m: float
    path_length_m: float
    n_poses: int
    alignment: str
    delta_m: float
    all_pairs: bool = False
    rpe_translation_per_frame_m: float = math.nan
    rpe_rotation_deg_per_frame: float = math.nan

    @property
    def mean_step_m(self) -> float:
        """The true path's mean step between frames [m] (NaN for a single pose)."""
        return self.path_length_m / (self.n_poses - 1) if self.n_poses > 1 else math.nan

    @property
    def rpe_frame_percent(self) -> float:
        """The RPE per frame in % of the mean true step (NaN when the truth does not move)."""
        step = self.mean_step_m
        return 100.0 * self.rpe_translation_per_frame_m / step if step > 0 else math.nan

    @property
    def ate_percent(self) -> float:
        return 100.0 * self.ate_rmse_m / self.path_length_m if self.path_length_m > 0 else math.nan

    @property
    def end_point_percent(self) -> float:
        return 100.0 * self.end_point_error_m / self.path_length_m if self.path_length_m > 0 else math.nan

    def to_dict(self) -> dict:
        out = asdict(self)
        out["ate_percent"], out["end_point_percent"] = self.ate_percent, self.end_point_percent
        out["mean_step_m"], out["rpe_frame_percent"] = self.mean_step_m, self.rpe_frame_percent
        return {k: (None if isinstance(v, float) and math.isnan(v) else v) for k, v in out.items()}

    def describe(self) -> str:
        """One line of the errors; what a too short path cannot give is "n/a" with the reason."""
        if self.path_length_m > 0:
            ate = f"{100 * self.ate_rmse_m:.1f} cm ({self.ate_percent:.2f} % of {self.path_length_m:.2f} m"
            end = f"{100 * self.end_point_error_m:.1f} cm ({self.end_point_percent:.2f} %)"
        else:
            ate = f"{100 * self.ate_rmse_m:.1f} cm (no motion"
            end = f"{100 * self.end_point_error_m:.1f} cm"
        rpe = (f"RPE {100 * self.rpe_translation_per_m:.2f} % / {self.rpe_rotation_deg_per_m:.2f} deg per m"
               if math.isfinite(self.rpe_translation_per_m) else
               f"RPE n/a (the path is shorter than {self.delta_m:g} m)")
        if math.isfinite(self.rpe_translation_per_frame_m):
            share = f" ({self.rpe_frame_percent:.1f} % of the {100 * self.mean_step_m:.1f} cm mean step)" \
                if self.mean_step_m > 0 else ""
            rpe += (f"; per frame {100 * self.rpe_translation_per_frame_m:.2f} cm{share} / "
                    f"{self.rpe_rotation_deg_per_frame:.3f} deg")
        return (f"ATE RMSE {ate}, {self.alignment} aligned; {100 * self.ate_rmse_unaligned_m:.1f} cm unaligned), "
                f"{rpe}, end point {end}")


def moved_to_body(T_world_from_base, T_base_from_cam, T_body_from_cam, T_world_from_body0=None) -> np.ndarray:
    """The poses of another body carrying the same camera: ``T_world_from_base @ T_base_from_cam @
    inv(T_body_from_cam)`` per frame (N, 4, 4), so that an estimate and a truth of different bodies
    (EuRoC's body frame, a drone's IMU) are compared as one body.

    ``T_base_from_cam``, ``T_body_from_cam``: (4, 4) or one per frame; ``T_world_from_body0``: the
    world re-anchored so that the first pose is this one (the truth's first pose).
    """
    T = _poses("T_world_from_base", T_world_from_base)
    M = np.broadcast_to(np.asarray(T_base_from_cam, dtype=np.float64), T.shape)
    B = np.broadcast_to(np.asarray(T_body_from_cam, dtype=np.float64), T.shape)
    out = T @ M @ np.linalg.inv(B)
    if T_world_from_body0 is not None:
        out = np.asarray(T_world_from_body0, dtype=np.float64) @ np.linalg.inv(out[0]) @ out
    return out


def rpe_pairs(T_true, delta_m: float, *, all_pairs: bool = False) -> list[tuple[int, int]]:
    """The pairs of frames ``(i, j)`` about ``delta_m`` metres of true path apart, as
    ``evo_rpe --delta D --delta_unit m --pairs_from_reference`` forms them (evo's
    ``filter_pairs_by_path``).

    ``all_pairs`` (``--all_pairs``): each frame ``i`` pairs with the later frame whose path distance
    from it is nearest ``delta_m``, kept if within 10 % of ``delta_m`` (evo's ``--delta_tol 0.1``).
    Else consecutive segments: the first frame starts one; walking the true positions, a frame ends a
    segment (and starts the next) when the path since the last end reaches ``delta_m``.
    """
    p = _poses("T_true", T_true)[:, :3, 3]
    if all_pairs:
        dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(p, axis=0), axis=1))])
        pairs = []
        for i in range(len(p) - 1):
            ahead = dist[i + 1:] - dist[i]
            k = int(np.argmin(np.abs(ahead - delta_m)))
            if abs(ahead[k] - delta_m) <= 0.1 * delta_m:
                pairs.append((i, i + 1 + k))
        return pairs
    ends, path = [0], 0.0
    for i in range(1, len(p)):
        path += float(np.linalg.norm(p[i] - p[i - 1]))
        if path >= delta_m - 1e-9:          # (ten 0.1 m steps are a metre, whatever the rounding)
            ends.append(i)
            path = 0.0
    return list(zip(ends, ends[1:]))


def trajectory_metrics(T_estimated, T_true, *, delta_m: float = 1.0, alignment: str = "se3",
                       all_pairs: bool = False) -> TrajectoryMetrics:
    """ATE, RPE per metre and end-point error of ``T_estimated`` against ``T_true`` (same frames).

    Parameters
    ----------
    T_estimated, T_true : ndarray (N, 4, 4)
        Poses of the same N frames (``T_world_from_base``).
    delta_m : float
        RPE distance between the frames of a pair, along the true path.
    alignment : {"se3", "se2", "none"}
        Alignment of the ATE (``ate_rmse_unaligned_m`` is always given too). The RPE compares
        relative poses, which no rigid alignment changes (``evo_rpe -a`` gives the same numbers).
    all_pairs : bool
        RPE over all pairs (``evo_rpe --all_pairs``) or consecutive segments (:func:`rpe_pairs`). All
        pairs need frames closer than a tenth of ``delta_m``: a car at 1.2 m per frame has no pair
        within 10 % of 1 m (evo: "empty index list"), hence consecutive segments by default.
    """
    P = _poses("T_estimated", T_estimated)
    Q = _poses("T_true", T_true)
    if len(P) != len(Q):
        raise ValueError(f"T_estimated and T_true must have the same number of poses, got {len(P)} and {len(Q)}")
    if alignment not in ("se3", "se2", "none"):
        raise ValueError(f"alignment must be 'se3', 'se2' or 'none', got {alignment!r}")
    if not (isinstance(delta_m, (int, float)) and math.isfinite(delta_m) and delta_m > 0):
        raise ValueError(f"delta_m must be a positive number, got {delta_m!r}")
    p, q = P[:, :3, 3], Q[:, :3, 3]
    unaligned = float(np.sqrt(np.mean(np.sum((p - q) ** 2, axis=1))))
    if alignment == "none" or len(P) < 3:
        aligned = unaligned
    else:
        A = umeyama_alignment(p, q, planar=alignment == "se2")
        aligned = float(np.sqrt(np.mean(np.sum((p @ A[:3, :3].T + A[:3, 3] - q) ** 2, axis=1))))
    dist = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))])
    t_err, r_err = _relative_errors(P, Q, rpe_pairs(Q, delta_m, all_pairs=all_pairs))
    t_frame, r_frame = _relative_errors(P, Q, [(i, i + 1) for i in range(len(P) - 1)])

    def rms(v, per=1.0):
        return float(np.sqrt(np.mean(np.square(v)))) / per if len(v) else math.nan

    return TrajectoryMetrics(ate_rmse_m=aligned, ate_rmse_unaligned_m=unaligned,
                             rpe_translation_per_m=rms(t_err, delta_m), rpe_rotation_deg_per_m=rms(r_err, delta_m),
                             end_point_error_m=float(np.linalg.norm(p[-1] - q[-1])),
                             path_length_m=float(dist[-1]), n_poses=len(P), alignment=alignment,
                             delta_m=float(delta_m), all_pairs=bool(all_pairs),
                             rpe_translation_per_frame_m=rms(t_frame), rpe_rotation_deg_per_frame=rms(r_frame))


def _relative_errors(P: np.ndarray, Q: np.ndarray, pairs) -> tuple[np.ndarray, np.ndarray]:
    """For each pair ``(i, j)`` the error ``E = inv(inv(Q_i) Q_j) inv(P_i) P_j`` of the estimate's relative
    pose: its translation [m] and angle [deg]."""
    t_err, r_err = [], []
    for i, j in pairs:
        E = np.linalg.inv(np.linalg.inv(Q[i]) @ Q[j]) @ (np.linalg.inv(P[i]) @ P[j])
        t_err.append(np.linalg.norm(E[:3, 3]))
        r_err.append(math.degrees(rotation_angle_rad(E[:3, :3])))
    return np.array(t_err), np.array(r_err)


def plot_trajectories(path: str | os.PathLike, trajectories: dict, *, lost=None, title: str = "trajectory") -> Path:
    """Top view of trajectories (legend labels -> (N, 2+) positions in metres), saved as PNG.

    ``lost`` (bool per frame of the first trajectory) marks the frames visual odometry lost.
    """
    from ..viz.plot import new_figure, save_figure

    fig = new_figure(7.0, 5.0)
    ax = fig.add_subplot(1, 1, 1)
    styles = ({"color": "tab:blue", "lw": 1.8}, {"color": "tab:orange", "lw": 1.2, "ls": "--"},
              {"color": "black", "lw": 1.0, "ls": ":"}, {"color": "tab:green", "lw": 1.2})
    first = None
    for k, (label, xy) in enumerate(trajectories.items()):
        xy = np.asarray(xy, dtype=np.float64)
        first = xy if first is None else first
        ax.plot(xy[:, 0], xy[:, 1], label=label, **styles[k % len(styles)])
        ax.plot(xy[:1, 0], xy[:1, 1], "o", color=styles[k % len(styles)]["color"], ms=4)
    if lost is not None and first is not None and np.any(lost):
        m = np.asarray(lost, bool)
        ax.plot(first[m, 0], first[m, 1], "x", color="red", ms=6, label="lost tracking")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_aspect("equal", adjustable="datalim")
    ax.grid(True, alpha=0.3)
    ax.legend(loc="best")
    ax.set_title(title)
    return save_figure(fig, path)
