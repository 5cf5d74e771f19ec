"""Trajectory error metrics: alignment, ATE, RPE and the scale of consecutive windows.

Every function here takes trajectories that are already associated (row i of the estimate and of
the ground truth belong to the same instant; see :mod:`amrvio.eval.associate`). The definitions
are those of evo (Grupp 2017), so the figures equal ``evo_ape``/``evo_rpe``:

- ATE (evo "APE, translation part"): ``e_i = || p_i^est,aligned - p_i^gt ||``.
- RPE (Sturm et al. 2012, TUM RGB-D benchmark, eq. 1): for a pose pair (i, j)
  ``E = (Q_i^-1 Q_j)^-1 (P_i^-1 P_j)`` with Q the ground truth and P the aligned estimate;
  translation error ``|| trans(E) ||``, rotation error ``angle(rot(E))``.
  Pairs are chosen on the estimate (evo's default) in frames or metres of travelled path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.geometry.align import umeyama
from amrvio.types.lie import Sim3, so3_log
from amrvio.types.trajectory import Trajectory

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


class AlignMethod(StrEnum):
    """How the estimate is moved onto the ground truth before the errors are computed."""

    NONE = "none"  # compare as is
    ORIGIN = "origin"  # first estimated pose put on the first ground-truth pose (SE3)
    SE3 = "se3"  # Umeyama, rotation and translation
    SIM3 = "sim3"  # Umeyama, rotation, translation and scale


class DeltaUnit(StrEnum):
    """Unit of the RPE pair distance."""

    FRAMES = "frames"
    METRES = "m"


@dataclass(frozen=True, slots=True)
class ErrorStats:
    """Statistics of a set of non-negative errors (NaN everywhere when ``count == 0``)."""

    rmse: float
    mean: float
    median: float
    std: float
    min: float
    max: float
    sse: float
    count: int

    @staticmethod
    def from_errors(errors: NDArray[np.float64]) -> ErrorStats:
        e = np.asarray(errors, dtype=np.float64).reshape(-1)
        if e.size == 0:
            nan = float("nan")
            return ErrorStats(nan, nan, nan, nan, nan, nan, nan, 0)
        sq = e * e
        return ErrorStats(
            rmse=math.sqrt(float(np.mean(sq))),
            mean=float(np.mean(e)),
            median=float(np.median(e)),
            std=float(np.std(e)),
            min=float(np.min(e)),
            max=float(np.max(e)),
            sse=float(np.sum(sq)),
            count=int(e.size),
        )

    def to_dict(self) -> dict[str, float | int | None]:
        """JSON-ready dict; NaN becomes None."""
        out: dict[str, float | int | None] = {}
        for k in ("rmse", "mean", "median", "std", "min", "max", "sse"):
            v = float(getattr(self, k))
            out[k] = v if math.isfinite(v) else None
        out["count"] = self.count
        return out


def _check_pair(est: Trajectory, gt: Trajectory) -> None:
    if len(est) != len(gt):
        raise ShapeError(
            f"associated trajectories must have the same length, got {len(est)} and {len(gt)}"
        )


# ------------------------------------------------------------------------------------ alignment


def align_trajectory(
    est: Trajectory,
    gt: Trajectory,
    method: AlignMethod | str = AlignMethod.SIM3,
    n_first: int | None = None,
) -> Sim3:
    """The transform ``S`` that puts ``est`` onto ``gt``: compare ``est.transformed(S)`` with ``gt``.

    none: identity. origin: ``T_gt_0 @ T_est_0^-1``. se3 / sim3: Umeyama (1991) on the positions of
    the first ``n_first`` poses (all when None), without / with scale.

    Raises:
        ShapeError: unequal lengths, an empty trajectory, or an alignment that is not defined
            (fewer than 3 poses, all poses at one point, poses on a line).
    """
    _check_pair(est, gt)
    m = AlignMethod(method)
    if len(est) == 0:
        raise ShapeError("cannot align empty trajectories")
    if m is AlignMethod.NONE:
        return Sim3.identity()
    if m is AlignMethod.ORIGIN:
        # First estimate pose onto the first ground-truth pose (evo's align_origin).
        T_gtworld_estworld = gt.pose(0) @ est.pose(0).inverse()
        return Sim3.from_se3(T_gtworld_estworld, 1.0)
    n = len(est) if n_first is None else int(n_first)
    if n < 1:
        raise ShapeError(f"n_first must be >= 1, got {n}")
    n = min(n, len(est))
    return umeyama(est.positions_m[:n], gt.positions_m[:n], with_scale=m is AlignMethod.SIM3)


# ------------------------------------------------------------------------------------------ ATE


def ate_errors_m(est: Trajectory, gt: Trajectory) -> F64:
    """(N,) translation errors ``|| p_est - p_gt ||`` of associated, already aligned poses."""
    _check_pair(est, gt)
    return np.asarray(np.linalg.norm(est.positions_m - gt.positions_m, axis=1), dtype=np.float64)


def ate(est: Trajectory, gt: Trajectory) -> ErrorStats:
    """Absolute trajectory error statistics (metres) of associated, already aligned poses."""
    return ErrorStats.from_errors(ate_errors_m(est, gt))


# ------------------------------------------------------------------------------------------ RPE


def _accumulated_m(positions: F64) -> F64:
    steps = np.linalg.norm(np.diff(positions, axis=0), axis=1)
    return np.concatenate([[0.0], np.cumsum(steps)])


def rpe_pairs(
    positions_m: F64,
    delta: float,
    delta_unit: DeltaUnit | str = DeltaUnit.FRAMES,
    all_pairs: bool = False,
    rel_tol: float = 0.1,
) -> I64:
    """(M, 2) index pairs (i, j), i < j, chosen as evo's ``id_pairs_from_delta``.

    frames: consecutive pairs (0, d), (d, 2d), ... or, with ``all_pairs``, every (i, i + d).
    metres: consecutive pairs where the path travelled since the previous pair start first reaches
    ``delta`` (evo ``filter_pairs_by_path``); with ``all_pairs``, for every i the j whose path
    distance is closest to ``delta``, kept when within ``rel_tol * delta`` of it.
    """
    p = np.asarray(positions_m, dtype=np.float64)
    n = p.shape[0]
    unit = DeltaUnit(delta_unit)
    if not delta > 0:
        raise ShapeError(f"RPE delta must be > 0, got {delta}")
    pairs: list[tuple[int, int]] = []
    if unit is DeltaUnit.FRAMES:
        if float(delta) != int(delta):
            raise ShapeError(f"RPE delta in frames must be an integer, got {delta}")
        d = int(delta)
        if all_pairs:
            first = np.arange(max(n - d, 0))
            return np.stack([first, first + d], axis=1).astype(np.int64).reshape(-1, 2)
        starts = np.arange(0, n, d)
        return np.stack([starts[:-1], starts[1:]], axis=1).astype(np.int64).reshape(-1, 2)
    if n < 2:
        return np.zeros((0, 2), np.int64)
    if all_pairs:
        dist = _accumulated_m(p)
        tol = delta * rel_tol
        for i in range(n - 1):
            from_here = dist[i + 1 :] - dist[i]
            k = int(np.argmin(np.abs(from_here - delta)))
            if abs(from_here[k] - delta) > tol:
                continue
            pairs.append((i, k + i + 1))
    else:
        steps = np.linalg.norm(np.diff(p, axis=0), axis=1)
        ids = [0]
        travelled = 0.0
        for k in range(1, n):
            travelled += float(steps[k - 1])  # summed in order, as evo does
            if travelled >= delta:
                ids.append(k)
                travelled = 0.0
        pairs = list(zip(ids[:-1], ids[1:], strict=True))
    return np.asarray(pairs, dtype=np.int64).reshape(-1, 2)


@dataclass(frozen=True, slots=True, eq=False)
class RpeResult:
    """Relative pose errors over the pairs ``pairs`` (M, 2)."""

    pairs: I64
    trans_errors_m: F64
    rot_errors_deg: F64
    trans: ErrorStats
    rot_deg: ErrorStats


def rpe(
    est: Trajectory,
    gt: Trajectory,
    delta: float = 1.0,
    delta_unit: DeltaUnit | str = DeltaUnit.FRAMES,
    all_pairs: bool = False,
    rel_tol: float = 0.1,
    pairs_from_reference: bool = False,
) -> RpeResult:
    """Relative pose error of associated, already aligned trajectories (evo_rpe's definition).

    Pairs come from the estimate's path unless ``pairs_from_reference``. No pair (trajectory too
    short for ``delta``) gives empty errors and NaN statistics.
    """
    _check_pair(est, gt)
    source = gt if pairs_from_reference else est
    pairs = rpe_pairs(source.positions_m, delta, delta_unit, all_pairs, rel_tol)
    if pairs.shape[0] == 0:
        empty = np.zeros(0)
        return RpeResult(
            pairs, empty, empty, ErrorStats.from_errors(empty), ErrorStats.from_errors(empty)
        )
    i, j = pairs[:, 0], pairs[:, 1]
    Rq, tq = gt.rotations(), gt.positions_m
    Rp, tp = est.rotations(), est.positions_m
    # Relative motions Q_i^-1 Q_j and P_i^-1 P_j (Sturm et al. 2012, eq. 1).
    Rq_rel = np.transpose(Rq[i], (0, 2, 1)) @ Rq[j]
    tq_rel = np.einsum("nki,nk->ni", Rq[i], tq[j] - tq[i])
    Rp_rel = np.transpose(Rp[i], (0, 2, 1)) @ Rp[j]
    tp_rel = np.einsum("nki,nk->ni", Rp[i], tp[j] - tp[i])
    # E = (Q_rel)^-1 P_rel
    R_err = np.transpose(Rq_rel, (0, 2, 1)) @ Rp_rel
    t_err = np.einsum("nki,nk->ni", Rq_rel, tp_rel - tq_rel)
    trans = np.linalg.norm(t_err, axis=1)
    rot = np.degrees(np.linalg.norm(so3_log(R_err).reshape(-1, 3), axis=1))
    return RpeResult(
        pairs, trans, rot, ErrorStats.from_errors(trans), ErrorStats.from_errors(rot)
    )


# --------------------------------------------------------------------------------- scale drift


class WindowStatus(StrEnum):
    """Whether the Sim3 scale of a window could be estimated."""

    OK = "ok"
    DEGENERATE = "degenerate"  # fewer than 3 poses, or poses at one point / on a line


@dataclass(frozen=True, slots=True)
class ScaleWindow:
    """Sim3 scale of one window of associated poses [index_start, index_end] (inclusive).

    scale: Umeyama scale mapping the raw estimate onto the ground truth in this window (None when
    ``status`` is not OK). gt_start_m / gt_length_m: ground-truth path distance at the window start
    and along the window.
    """

    index_start: int
    index_end: int
    t_start_s: float
    t_end_s: float
    gt_start_m: float
    gt_length_m: float
    scale: float | None
    status: WindowStatus
    reason: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "index_start": self.index_start,
            "index_end": self.index_end,
            "t_start_s": self.t_start_s,
            "t_end_s": self.t_end_s,
            "gt_start_m": self.gt_start_m,
            "gt_length_m": self.gt_length_m,
            "scale": self.scale,
            "status": self.status.value,
            "reason": self.reason,
        }


def _window_bounds_m(dist: F64, window_m: float) -> list[tuple[int, int]]:
    n = dist.shape[0]
    bounds: list[tuple[int, int]] = []
    start = 0
    while start < n - 1:
        reach = np.flatnonzero(dist[start + 1 :] - dist[start] >= window_m)
        if reach.size == 0:
            rest = dist[-1] - dist[start]
            if bounds and rest < 0.5 * window_m:
                bounds[-1] = (bounds[-1][0], n - 1)  # short tail joins the last window
            else:
                bounds.append((start, n - 1))
            break
        end = start + 1 + int(reach[0])
        bounds.append((start, end))
        start = end
    return bounds


def _window_bounds_frames(n: int, window: int) -> list[tuple[int, int]]:
    bounds: list[tuple[int, int]] = []
    start = 0
    while start < n - 1:
        end = start + window
        if end >= n - 1:
            if bounds and (n - 1 - start) < 0.5 * window:
                bounds[-1] = (bounds[-1][0], n - 1)
            else:
                bounds.append((start, n - 1))
            break
        bounds.append((start, end))
        start = end
    return bounds


def scale_windows(
    est: Trajectory,
    gt: Trajectory,
    window_m: float | None = None,
    window_frames: int | None = None,
) -> tuple[ScaleWindow, ...]:
    """Sim3 scale of consecutive windows along the path (scale drift over time).

    Windows are cut along the ground-truth path every ``window_m`` metres (default: 10 % of the
    path length), or every ``window_frames`` associated poses. Consecutive windows share their
    boundary pose; a tail shorter than half a window joins the last window. Each window's scale is
    the Umeyama Sim3 scale from the (unaligned) estimate to the ground truth, so a constant value
    means no scale drift.
    """
    _check_pair(est, gt)
    n = len(est)
    if n < 2:
        return ()
    dist = _accumulated_m(gt.positions_m)
    if window_frames is not None:
        if window_frames < 1:
            raise ShapeError(f"window_frames must be >= 1, got {window_frames}")
        bounds = _window_bounds_frames(n, int(window_frames))
    else:
        length = float(dist[-1])
        w = 0.1 * length if window_m is None else float(window_m)
        if not w > 0.0:
            if window_m is None:
                return ()  # the ground truth does not move: no windows
            raise ShapeError(f"window_m must be > 0, got {window_m}")
        bounds = _window_bounds_m(dist, w)
    out: list[ScaleWindow] = []
    for a, b in bounds:
        sl = slice(a, b + 1)
        scale: float | None
        try:
            scale = umeyama(est.positions_m[sl], gt.positions_m[sl], with_scale=True).s
            status, reason = WindowStatus.OK, ""
        except ShapeError as err:
            scale, status, reason = None, WindowStatus.DEGENERATE, str(err)
        out.append(
            ScaleWindow(
                index_start=a,
                index_end=b,
                t_start_s=float(gt.stamps_s[a]),
                t_end_s=float(gt.stamps_s[b]),
                gt_start_m=float(dist[a]),
                gt_length_m=float(dist[b] - dist[a]),
                scale=scale,
                status=status,
                reason=reason,
            )
        )
    return tuple(out)

