"""Least-squares similarity alignment of two point sets (Umeyama 1991).

``umeyama(src, dst, with_scale)`` returns the ``Sim3`` ``S`` minimising
``sum_i w_i ||dst_i - (s R src_i + t)||^2``; ``S.act(src)`` is then as close as possible to
``dst``. With ``with_scale=False`` the scale is fixed to 1 (a rigid, SE3 alignment).

Reference: S. Umeyama, "Least-squares estimation of transformation parameters between two point
patterns", IEEE PAMI 13(4), 1991 (equation numbers below refer to it).
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.types.lie import SO3, Sim3

F64 = NDArray[np.float64]

# A singular value below this fraction of the largest one counts as zero (rank test).
_RANK_RTOL = 1e-10


def _points(x: ArrayLike, name: str) -> F64:
    p = np.asarray(x, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ShapeError(f"{name} must be (N, 3) points, got shape {p.shape}")
    if not np.all(np.isfinite(p)):
        raise ShapeError(f"{name} contains non-finite values")
    return p


def umeyama(
    src: ArrayLike,
    dst: ArrayLike,
    with_scale: bool,
    weights: ArrayLike | None = None,
) -> Sim3:
    """Sim3 ``S`` with ``dst ~= S.act(src)`` in the weighted least-squares sense.

    Args:
        src: (N, 3) points to be moved (for example estimated positions).
        dst: (N, 3) target points (for example ground-truth positions), row i matches src row i.
        with_scale: estimate the scale ``s``; otherwise ``s = 1``.
        weights: optional (N,) non-negative weights; at least 3 must be positive.

    Raises:
        ShapeError: wrong shapes, non-finite values, fewer than 3 points, zero variance of
            ``src`` or ``dst``, or (nearly) collinear points, for which the rotation is not defined.
    """
    x = _points(src, "src")
    y = _points(dst, "dst")
    if x.shape != y.shape:
        raise ShapeError(f"src and dst must have the same shape, got {x.shape} and {y.shape}")
    n = x.shape[0]
    if weights is None:
        w = np.full(n, 1.0 / max(n, 1))
    else:
        w = np.asarray(weights, dtype=np.float64)
        if w.shape != (n,):
            raise ShapeError(f"weights must have shape ({n},), got {w.shape}")
        if not np.all(np.isfinite(w)) or np.any(w < 0.0):
            raise ShapeError("weights must be finite and non-negative")
    if int(np.count_nonzero(w > 0.0)) < 3:
        raise ShapeError(f"Umeyama alignment needs at least 3 points, got {int(np.sum(w > 0))}")
    w = w / w.sum()

    mean_x = w @ x  # eq. 34
    mean_y = w @ y  # eq. 35
    xc = x - mean_x
    yc = y - mean_y
    var_x = float(w @ np.sum(xc * xc, axis=1))  # eq. 36
    var_y = float(w @ np.sum(yc * yc, axis=1))
    scale_ref = max(float(np.abs(x).max()), float(np.abs(y).max()), 1.0)
    if var_x <= (1e-12 * scale_ref) ** 2 or var_y <= (1e-12 * scale_ref) ** 2:
        raise ShapeError("Umeyama alignment: the points have zero variance (all identical)")
    cov = (yc * w[:, None]).T @ xc  # eq. 38, Sigma_xy
    u, d, vt = np.linalg.svd(cov)
    if d[1] <= _RANK_RTOL * d[0]:
        raise ShapeError(
            "Umeyama alignment: the points are collinear, so the rotation about their line is "
            "undefined (use more poses or poses that do not lie on a line)"
        )
    S = np.eye(3)
    if np.linalg.det(u) * np.linalg.det(vt) < 0.0:
        S[2, 2] = -1.0  # eq. 43: keep det(R) = +1
    R = u @ S @ vt  # eq. 40
    s = float(np.trace(np.diag(d) @ S) / var_x) if with_scale else 1.0  # eq. 42
    if not s > 0.0:
        raise ShapeError(f"Umeyama alignment produced a non-positive scale {s}")
    t = mean_y - s * (R @ mean_x)  # eq. 41
    return Sim3(SO3(R), t, s)
