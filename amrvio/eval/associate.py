"""Association of two trajectories by timestamp (nearest stamp within a maximum difference).

The algorithm is the one of evo (``evo.core.sync.associate_trajectories`` with the
``nearest_time`` method), so that our figures equal ``evo_ape``/``evo_rpe``: the trajectory with
fewer poses (the estimate when both have the same size) is walked in order, and each of its stamps
is paired with the nearest stamp of the other trajectory when ``|dt| <= max_diff_s``. On a tie the
earlier stamp wins. The index of the walked trajectory is strictly increasing; the other can repeat
only when ``max_diff_s`` is at least half the spacing of the walked trajectory.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.types.trajectory import Trajectory

I64 = NDArray[np.int64]


def _stamps(x: ArrayLike, name: str) -> NDArray[np.float64]:
    s = np.asarray(x, dtype=np.float64)
    if s.ndim != 1:
        raise ShapeError(f"{name} must be a 1-D array of stamps, got shape {s.shape}")
    if not np.all(np.isfinite(s)):
        raise ShapeError(f"{name} contains non-finite stamps")
    return s


def match_stamps(
    stamps_a_s: ArrayLike, stamps_b_s: ArrayLike, max_diff_s: float
) -> tuple[I64, I64]:
    """For each stamp of ``a`` the nearest stamp of ``b`` within ``max_diff_s`` seconds.

    ``b`` must be sorted (non-decreasing). Returns ``(idx_a, idx_b)``, int64 arrays of equal length;
    stamps of ``a`` without a partner are left out. Same rules as ``evo.core.sync.matching_time_indices``.
    """
    a = _stamps(stamps_a_s, "stamps_a_s")
    b = _stamps(stamps_b_s, "stamps_b_s")
    if not max_diff_s >= 0.0:
        raise ShapeError(f"max_diff_s must be >= 0, got {max_diff_s}")
    if b.size == 0 or a.size == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    if np.any(np.diff(b) < 0.0):
        raise ShapeError("stamps_b_s must be sorted")
    ins = np.searchsorted(b, a, side="right")
    ub = np.minimum(ins, b.size - 1)
    diff_ub = b[ub] - a
    lb = np.maximum(ins - 1, 0)
    diff_lb = np.where(ins > 0, a - b[lb], np.inf)
    take_ub = (diff_ub <= max_diff_s) & (diff_ub < diff_lb)
    take_lb = ~take_ub & (diff_lb <= max_diff_s) & (diff_lb <= diff_ub)
    in_range = (a >= b[0] - max_diff_s) & (a <= b[-1] + max_diff_s)
    keep = in_range & (take_ub | take_lb)
    idx_b = np.where(take_ub, ub, lb)
    return np.flatnonzero(keep).astype(np.int64), idx_b[keep].astype(np.int64)


def associate(
    est: Trajectory | ArrayLike, gt: Trajectory | ArrayLike, max_diff_s: float = 0.01
) -> tuple[I64, I64]:
    """Pair estimate and ground-truth poses by stamp; returns ``(idx_est, idx_gt)``.

    est, gt: trajectories or their (N,) stamp arrays in seconds, sorted. The shorter trajectory
    (the estimate on equal length) is walked and matched into the longer one, as evo does;
    ``idx_est`` and ``idx_gt`` are returned in increasing order of the walked trajectory.
    An empty result means nothing matched.
    """
    t_est = _stamps(est.stamps_s if isinstance(est, Trajectory) else est, "est stamps")
    t_gt = _stamps(gt.stamps_s if isinstance(gt, Trajectory) else gt, "gt stamps")
    if t_est.size <= t_gt.size:
        idx_est, idx_gt = match_stamps(t_est, t_gt, max_diff_s)
    else:
        idx_gt, idx_est = match_stamps(t_gt, t_est, max_diff_s)
    return idx_est, idx_gt
