"""Input checks for the geometry functions: a precise ShapeError instead of a wrong answer."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

F64 = NDArray[np.float64]


def check_points(name: str, arr: NDArray[np.floating], dim: int) -> F64:
    """Return ``arr`` as float64 ``(N, dim)``; raise ShapeError on a wrong shape or NaN/inf."""
    a = np.asarray(arr, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != dim:
        raise ShapeError(f"{name} must have shape (N, {dim}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ShapeError(f"{name} contains NaN or inf")
    return a


def check_matrix(name: str, arr: NDArray[np.floating], shape: tuple[int, int]) -> F64:
    """Return ``arr`` as a finite float64 matrix of ``shape``; raise ShapeError otherwise."""
    a = np.asarray(arr, dtype=np.float64)
    if a.shape != shape:
        raise ShapeError(f"{name} must have shape {shape}, got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ShapeError(f"{name} contains NaN or inf")
    return a


__all__ = ["F64", "check_matrix", "check_points"]
