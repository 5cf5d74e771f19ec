"""Deprecated: lead switches over (pipeline/vo.py, bench/bench_vo.py, tests/test_vo_pipeline.py).

New names: amrvio.geometry.projection.project, amrvio.types.lie.se3_matrix_inverse (invert_T),
se3_matrix (rt_to_T), so3_exp (so3_exp_small), SE3.exp(xi).matrix() (se3_exp)."""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.geometry.projection import project
from amrvio.types.lie import SE3
from amrvio.types.lie import se3_matrix as rt_to_T
from amrvio.types.lie import se3_matrix_inverse as invert_T
from amrvio.types.lie import so3_exp as so3_exp_small


def se3_exp(xi: ArrayLike) -> NDArray[np.float64]:
    """4x4 SE(3) exponential of xi = [rho, phi]: SE3.exp(xi).matrix()."""
    return SE3.exp(xi).matrix()


__all__ = ["invert_T", "project", "rt_to_T", "se3_exp", "so3_exp_small"]
