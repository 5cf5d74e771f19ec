"""A timed sequence of poses ``T_world_x`` stored as arrays (one value, never mutated)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError
from amrvio.types.lie import SE3, SO3, Sim3, interpolate_se3, matrix_to_quat_wxyz, quat_wxyz_to_matrix

F64 = NDArray[np.float64]


def _readonly(a: ArrayLike) -> F64:
    out = np.array(a, dtype=np.float64, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, slots=True, eq=False)
class Trajectory:
    """Poses ``T_world_x`` at ``stamps_s``.

    stamps_s: (N,) seconds, strictly increasing. positions_m: (N, 3). quats_wxyz: (N, 4) unit
    quaternions (normalised on construction; sign made w >= 0).
    """

    stamps_s: F64
    positions_m: F64
    quats_wxyz: F64

    def __post_init__(self) -> None:
        t = np.asarray(self.stamps_s, dtype=np.float64)
        p = np.asarray(self.positions_m, dtype=np.float64)
        q = np.asarray(self.quats_wxyz, dtype=np.float64)
        n = t.shape[0] if t.ndim == 1 else -1
        if t.ndim != 1 or p.shape != (n, 3) or q.shape != (n, 4):
            raise ShapeError(
                f"trajectory arrays must be (N,), (N,3), (N,4); got {t.shape}, {p.shape}, {q.shape}"
            )
        for name, a in (("stamps", t), ("positions", p), ("quaternions", q)):
            if not np.all(np.isfinite(a)):
                bad = int(np.flatnonzero(~np.all(np.isfinite(a.reshape(n, -1)), axis=1))[0])
                raise ShapeError(f"{name} contain a non-finite value at index {bad}")
        if n > 1 and np.any(np.diff(t) <= 0):
            bad = int(np.flatnonzero(np.diff(t) <= 0)[0]) + 1
            raise ShapeError(f"stamps are not strictly increasing at index {bad}")
        norms = np.linalg.norm(q, axis=1)
        if n and np.any(norms < 1e-9):
            raise ShapeError("a quaternion is zero")
        qn = q / norms[:, None] if n else q
        qn = np.where(qn[:, :1] < 0, -qn, qn) if n else qn
        object.__setattr__(self, "stamps_s", _readonly(t))
        object.__setattr__(self, "positions_m", _readonly(p))
        object.__setattr__(self, "quats_wxyz", _readonly(qn))

    @staticmethod
    def from_poses(stamps_s: ArrayLike, poses: Sequence[SE3]) -> Trajectory:
        t = np.asarray(stamps_s, dtype=np.float64)
        if len(poses) == 0:
            return Trajectory(t.reshape(0), np.zeros((0, 3)), np.zeros((0, 4)))
        Rs = np.stack([T.rot.R for T in poses])
        ps = np.stack([T.t for T in poses])
        return Trajectory(t, ps, matrix_to_quat_wxyz(Rs).reshape(-1, 4))

    @staticmethod
    def from_matrices(stamps_s: ArrayLike, T: ArrayLike) -> Trajectory:
        """From (N, 4, 4) or (N, 3, 4) pose matrices."""
        m = np.asarray(T, dtype=np.float64)
        if m.ndim != 3 or m.shape[1:] not in ((4, 4), (3, 4)):
            raise ShapeError(f"pose matrices must be (N,4,4) or (N,3,4), got {m.shape}")
        Rs = m[:, :3, :3]
        U, _, Vt = np.linalg.svd(Rs)
        Rs = U @ Vt  # nearest rotations; files store rounded values
        return Trajectory(np.asarray(stamps_s, dtype=np.float64), m[:, :3, 3], matrix_to_quat_wxyz(Rs).reshape(-1, 4))

    def __len__(self) -> int:
        return int(self.stamps_s.shape[0])

    def rotations(self) -> F64:
        """(N, 3, 3) rotation matrices R_world_x."""
        if len(self) == 0:
            return np.zeros((0, 3, 3))
        return quat_wxyz_to_matrix(self.quats_wxyz).reshape(-1, 3, 3)

    def matrices(self) -> F64:
        """(N, 4, 4) homogeneous pose matrices."""
        T = np.tile(np.eye(4), (len(self), 1, 1))
        T[:, :3, :3] = self.rotations()
        T[:, :3, 3] = self.positions_m
        return T

    def pose(self, i: int) -> SE3:
        return SE3(SO3.from_matrix(quat_wxyz_to_matrix(self.quats_wxyz[i])), self.positions_m[i])

    def poses(self) -> list[SE3]:
        return [SE3(SO3.from_matrix(R), p) for R, p in zip(self.rotations(), self.positions_m, strict=True)]

    def select(self, indices: ArrayLike) -> Trajectory:
        idx = np.asarray(indices)
        return Trajectory(self.stamps_s[idx], self.positions_m[idx], self.quats_wxyz[idx])

    def path_length_m(self) -> float:
        if len(self) < 2:
            return 0.0
        return float(np.linalg.norm(np.diff(self.positions_m, axis=0), axis=1).sum())

    def transformed(self, S: SE3 | Sim3) -> Trajectory:
        """Left-multiply every pose by S (a change of world frame): T' = S @ T.

        With a Sim3, positions are scaled and rotated; orientations are rotated by S.R.
        """
        s = S.s if isinstance(S, Sim3) else 1.0
        p = s * (self.positions_m @ S.R.T) + S.t
        R = S.R[None] @ self.rotations()
        return Trajectory(self.stamps_s, p, matrix_to_quat_wxyz(R).reshape(-1, 4))

    def right_multiplied(self, T: SE3) -> Trajectory:
        """Right-multiply every pose by T (a change of body frame): T_world_y = T_world_x @ T_x_y."""
        R = self.rotations()
        p = self.positions_m + np.einsum("nij,j->ni", R, T.t)
        return Trajectory(self.stamps_s, p, matrix_to_quat_wxyz(R @ T.R).reshape(-1, 4))

    def with_stamps(self, stamps_s: ArrayLike) -> Trajectory:
        return Trajectory(np.asarray(stamps_s, dtype=np.float64), self.positions_m, self.quats_wxyz)

    def interpolated_at(self, stamps_s: ArrayLike) -> Trajectory:
        """Poses at ``stamps_s`` (M,), each inside [first, last] stamp: positions linearly,
        rotations by geodesic interpolation (slerp) between the bracketing poses
        (:func:`amrvio.types.lie.interpolate_se3`)."""
        t = np.asarray(stamps_s, dtype=np.float64)
        if t.ndim != 1 or len(self) < 2:
            raise ShapeError(f"need (M,) stamps and a trajectory of >= 2 poses, got {t.shape} and {len(self)}")
        if t.size and (t.min() < self.stamps_s[0] or t.max() > self.stamps_s[-1]):
            raise ShapeError(
                f"stamps [{t.min():.9f}, {t.max():.9f}] s leave the trajectory's span "
                f"[{self.stamps_s[0]:.9f}, {self.stamps_s[-1]:.9f}] s"
            )
        hi = np.clip(np.searchsorted(self.stamps_s, t, side="right"), 1, len(self) - 1)
        lo = hi - 1
        alpha = (t - self.stamps_s[lo]) / (self.stamps_s[hi] - self.stamps_s[lo])
        T = self.matrices()
        out = interpolate_se3(T[lo], T[hi], alpha).reshape(-1, 4, 4)
        return Trajectory(t, out[:, :3, 3], matrix_to_quat_wxyz(out[:, :3, :3]).reshape(-1, 4))
