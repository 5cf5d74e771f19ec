"""Rotation, rigid and similarity transforms: SO3, SE3 and Sim3.

Frame convention, used everywhere in amrvio: ``T_a_b`` maps points expressed in frame ``b`` into
frame ``a``: ``p_a = T_a_b.act(p_b)``. Hence ``T_a_b @ T_b_c == T_a_c`` and
``T_a_b.inverse() == T_b_a``. ``T_world_cam`` is the camera pose in the world.

Tangent-space layout: SE3 ``xi = [rho, phi]`` (translation part first, then rotation), Sim3
``xi = [rho, phi, sigma]`` with ``s = exp(sigma)``. Exponentials use closed forms with Taylor
series near zero, so rotations of 1e-12 rad are not rounded to the identity (unlike
``cv2.Rodrigues``, which returns exactly zero below ~1e-5 rad).

References: Barfoot, "State Estimation for Robotics" (2017) §7.1; Eade, "Lie groups for 2D and 3D
transformations" (Sim3 Jacobian, §6).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ShapeError

F64 = NDArray[np.float64]

_SMALL = 1e-6


def _as_vec(x: ArrayLike, n: int, name: str) -> F64:
    v = np.asarray(x, dtype=np.float64)
    if v.shape != (n,):
        raise ShapeError(f"{name} must have shape ({n},), got {v.shape}")
    if not np.all(np.isfinite(v)):
        raise ShapeError(f"{name} contains non-finite values")
    return v


def _frozen(a: F64) -> F64:
    a = np.array(a, dtype=np.float64, copy=True)
    a.setflags(write=False)
    return a


def hat(v: ArrayLike) -> F64:
    """Skew-symmetric matrix of a 3-vector (3,) -> (3, 3), or of a batch (N, 3) -> (N, 3, 3)."""
    w = np.asarray(v, dtype=np.float64)
    if w.shape[-1:] != (3,):
        raise ShapeError(f"hat expects (...,3), got {w.shape}")
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1] = -w[..., 2]
    out[..., 0, 2] = w[..., 1]
    out[..., 1, 0] = w[..., 2]
    out[..., 1, 2] = -w[..., 0]
    out[..., 2, 0] = -w[..., 1]
    out[..., 2, 1] = w[..., 0]
    return out


def vee(m: ArrayLike) -> F64:
    """Inverse of :func:`hat`: (…, 3, 3) -> (…, 3)."""
    a = np.asarray(m, dtype=np.float64)
    return np.stack([a[..., 2, 1], a[..., 0, 2], a[..., 1, 0]], axis=-1)


def _so3_coeffs(theta: F64) -> tuple[F64, F64, F64]:
    """A = sin t / t, B = (1 - cos t) / t^2, C = (t - sin t) / t^3, with Taylor series near 0."""
    t2 = theta * theta
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - t2 / 6.0 + t2 * t2 / 120.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - t2 / 24.0 + t2 * t2 / 720.0, (1.0 - np.cos(safe)) / (safe * safe))
    c = np.where(
        small, 1.0 / 6.0 - t2 / 120.0 + t2 * t2 / 5040.0, (safe - np.sin(safe)) / safe**3
    )
    return a, b, c


def so3_exp(omegas: ArrayLike) -> F64:
    """Rodrigues' formula, batched: rotation vectors (N, 3) -> matrices (N, 3, 3); (3,) -> (3, 3)."""
    w = np.asarray(omegas, dtype=np.float64)
    if w.shape[-1:] != (3,) or w.ndim not in (1, 2):
        raise ShapeError(f"so3_exp expects (3,) or (N,3), got {w.shape}")
    theta = np.linalg.norm(w, axis=-1)
    a, b, _ = _so3_coeffs(theta)
    W = hat(w)
    eye = np.eye(3)
    return eye + a[..., None, None] * W + b[..., None, None] * (W @ W)


def _rotation_batch(rots: ArrayLike, what: str) -> tuple[F64, bool]:
    """``rots`` as (N, 3, 3) float64 and whether it was one (3, 3) matrix (may be a view: read only)."""
    R = np.asarray(rots, dtype=np.float64)
    if R.shape[-2:] != (3, 3) or R.ndim not in (2, 3):
        raise ShapeError(f"{what} must be (3,3) or (N,3,3), got {R.shape}")
    return R.reshape(-1, 3, 3), R.ndim == 2


def so3_log(rots: ArrayLike) -> F64:
    """Inverse of :func:`so3_exp`: (N, 3, 3) -> (N, 3), (3, 3) -> (3,). Accurate near 0 and pi."""
    R, single = _rotation_batch(rots, "so3_log input")
    tr = np.trace(R, axis1=1, axis2=2)
    cos_t = np.clip((tr - 1.0) / 2.0, -1.0, 1.0)
    axis_sin = vee(R - np.transpose(R, (0, 2, 1))) / 2.0  # sin(t) * axis
    sin_t = np.linalg.norm(axis_sin, axis=1)
    theta = np.arctan2(sin_t, cos_t)
    out = np.empty((R.shape[0], 3))
    near_pi = cos_t < -0.99
    regular = ~near_pi
    if np.any(regular):
        t = theta[regular]
        s = sin_t[regular]
        small = t < 1e-4
        factor = np.where(small, 1.0 + t * t / 6.0, t / np.where(small, 1.0, s))
        out[regular] = axis_sin[regular] * factor[:, None]
    for i in np.flatnonzero(near_pi):
        # R = I + sin t K + (1 - cos t) K^2  =>  (R + R^T)/2 - cos t I = (1 - cos t) a a^T
        t = theta[i]
        M = (R[i] + R[i].T) / 2.0 - cos_t[i] * np.eye(3)
        k = int(np.argmax(np.diag(M)))
        a = M[:, k] / np.sqrt(max(M[k, k], 1e-300))
        a /= np.linalg.norm(a)
        if np.dot(a, axis_sin[i]) < 0.0:
            a = -a
        out[i] = a * t
    return out[0] if single else out


def so3_left_jacobian(omega: ArrayLike) -> F64:
    """Left Jacobian J_l(phi) of SO3 (Barfoot eq. 7.77): V in the SE3 exponential."""
    w = _as_vec(omega, 3, "omega")
    theta = np.linalg.norm(w)
    _, b, c = _so3_coeffs(np.asarray(theta))
    W = hat(w)
    return np.eye(3) + float(b) * W + float(c) * (W @ W)


def se3_matrix(R: ArrayLike, t: ArrayLike) -> F64:
    """4x4 homogeneous matrix of a rotation (3, 3) and a translation (3,) (no orthonormalisation)."""
    T = np.eye(4)
    T[:3, :3] = R
    T[:3, 3] = np.asarray(t, dtype=np.float64).reshape(3)
    return T


def se3_matrix_inverse(T: F64) -> F64:
    """Inverse of a 4x4 rigid transform: [R^T, -R^T t]."""
    Ti = np.eye(4)
    Ti[:3, :3] = T[:3, :3].T
    Ti[:3, 3] = -T[:3, :3].T @ T[:3, 3]
    return Ti


def transform_points(T: F64, points: F64) -> F64:
    """``R p + t`` for (N, 3) points: one 4x4 transform for all, or (N, 4, 4), one per point."""
    if T.ndim == 3:
        return np.asarray(np.einsum("nij,nj->ni", T[:, :3, :3], points) + T[:, :3, 3],
                          dtype=np.float64)
    return np.asarray(points @ T[:3, :3].T + T[:3, 3], dtype=np.float64)


def interpolate_se3(T0: ArrayLike, T1: ArrayLike, alpha: ArrayLike) -> F64:
    """Pose interpolation on 4x4 matrices, batched: (N, 4, 4), (N, 4, 4), (N,) -> (N, 4, 4), or
    one (4, 4) pair with a scalar ``alpha``. alpha = 0 gives T0, 1 gives T1.

    Rotation along the geodesic, R0 exp(alpha log(R0^T R1)) (slerp); translation linearly,
    (1 - alpha) t0 + alpha t1 (the trajectory interpolation convention, as in evo)."""
    A = np.asarray(T0, dtype=np.float64)
    B = np.asarray(T1, dtype=np.float64)
    a = np.asarray(alpha, dtype=np.float64)
    single = A.shape == (4, 4)
    A3, B3, a1 = A.reshape(-1, 4, 4), B.reshape(-1, 4, 4), a.reshape(-1)
    if A3.shape != B3.shape or A.shape[-2:] != (4, 4) or a1.shape != (A3.shape[0],):
        raise ShapeError(
            f"interpolate_se3 needs (N,4,4), (N,4,4), (N,) or (4,4), (4,4), (); got "
            f"{A.shape}, {B.shape}, {a.shape}"
        )
    R0 = A3[:, :3, :3]
    delta = so3_log(np.transpose(R0, (0, 2, 1)) @ B3[:, :3, :3]).reshape(-1, 3)
    out = np.tile(np.eye(4), (A3.shape[0], 1, 1))
    out[:, :3, :3] = R0 @ so3_exp(a1[:, None] * delta).reshape(-1, 3, 3)
    out[:, :3, 3] = (1 - a1)[:, None] * A3[:, :3, 3] + a1[:, None] * B3[:, :3, 3]
    return out[0] if single else out


def quat_wxyz_to_matrix(quats: ArrayLike) -> F64:
    """Unit quaternions (N, 4) [w, x, y, z] -> rotation matrices (N, 3, 3); (4,) -> (3, 3)."""
    q = np.asarray(quats, dtype=np.float64)
    if q.shape[-1:] != (4,) or q.ndim not in (1, 2):
        raise ShapeError(f"quaternions must be (4,) or (N,4), got {q.shape}")
    n = np.linalg.norm(q, axis=-1, keepdims=True)
    if np.any(~np.isfinite(q)) or np.any(n < 1e-12):
        raise ShapeError("quaternion is zero or non-finite")
    q = q / n
    w, x, y, z = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    R = np.empty(q.shape[:-1] + (3, 3))
    R[..., 0, 0] = 1 - 2 * (y * y + z * z)
    R[..., 0, 1] = 2 * (x * y - w * z)
    R[..., 0, 2] = 2 * (x * z + w * y)
    R[..., 1, 0] = 2 * (x * y + w * z)
    R[..., 1, 1] = 1 - 2 * (x * x + z * z)
    R[..., 1, 2] = 2 * (y * z - w * x)
    R[..., 2, 0] = 2 * (x * z - w * y)
    R[..., 2, 1] = 2 * (y * z + w * x)
    R[..., 2, 2] = 1 - 2 * (x * x + y * y)
    return R


def matrix_to_quat_wxyz(rots: ArrayLike) -> F64:
    """Rotation matrices (N, 3, 3) -> unit quaternions (N, 4) [w, x, y, z] with w >= 0."""
    R, single = _rotation_batch(rots, "rotation matrices")
    # Shepperd's method: pick the largest of 4 candidates for numerical stability.
    tr = np.trace(R, axis1=1, axis2=2)
    cand = np.stack([tr, R[:, 0, 0], R[:, 1, 1], R[:, 2, 2]], axis=1)
    k = np.argmax(cand, axis=1)
    q = np.empty((R.shape[0], 4))
    for i in range(R.shape[0]):
        m = R[i]
        if k[i] == 0:
            s = np.sqrt(max(tr[i] + 1.0, 0.0)) * 2.0
            q[i] = [0.25 * s, (m[2, 1] - m[1, 2]) / s, (m[0, 2] - m[2, 0]) / s, (m[1, 0] - m[0, 1]) / s]
        elif k[i] == 1:
            s = np.sqrt(max(1.0 + m[0, 0] - m[1, 1] - m[2, 2], 0.0)) * 2.0
            q[i] = [(m[2, 1] - m[1, 2]) / s, 0.25 * s, (m[0, 1] + m[1, 0]) / s, (m[0, 2] + m[2, 0]) / s]
        elif k[i] == 2:
            s = np.sqrt(max(1.0 + m[1, 1] - m[0, 0] - m[2, 2], 0.0)) * 2.0
            q[i] = [(m[0, 2] - m[2, 0]) / s, (m[0, 1] + m[1, 0]) / s, 0.25 * s, (m[1, 2] + m[2, 1]) / s]
        else:
            s = np.sqrt(max(1.0 + m[2, 2] - m[0, 0] - m[1, 1], 0.0)) * 2.0
            q[i] = [(m[1, 0] - m[0, 1]) / s, (m[0, 2] + m[2, 0]) / s, (m[1, 2] + m[2, 1]) / s, 0.25 * s]
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    q[q[:, 0] < 0] *= -1.0
    return q[0] if single else q


def _project_to_so3(R: F64) -> F64:
    U, _, Vt = np.linalg.svd(R)
    D = np.diag([1.0, 1.0, np.linalg.det(U @ Vt)])
    return np.asarray(U @ D @ Vt, dtype=np.float64)


def _apply(R: F64, t: F64, scale: float, points: ArrayLike) -> F64:
    p = np.asarray(points, dtype=np.float64)
    if p.shape == (3,):
        return np.asarray(scale * (R @ p) + t, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 3:
        raise ShapeError(f"points must be (3,) or (N,3), got {p.shape}")
    return np.asarray(scale * (p @ R.T) + t, dtype=np.float64)


@dataclass(frozen=True, slots=True, eq=False)
class SO3:
    """A 3-D rotation stored as an orthonormal matrix ``R`` (3, 3), det +1."""

    R: F64

    def __post_init__(self) -> None:
        R = np.asarray(self.R, dtype=np.float64)
        if R.shape != (3, 3) or not np.all(np.isfinite(R)):
            raise ShapeError(f"SO3 needs a finite (3,3) matrix, got shape {R.shape}")
        if np.abs(R @ R.T - np.eye(3)).max() > 1e-6 or np.linalg.det(R) < 0:
            raise ShapeError("SO3 matrix is not a rotation (R R^T != I or det < 0)")
        object.__setattr__(self, "R", _frozen(R))

    @staticmethod
    def identity() -> SO3:
        return SO3(np.eye(3))

    @staticmethod
    def exp(omega: ArrayLike) -> SO3:
        return SO3(so3_exp(_as_vec(omega, 3, "omega")))

    @staticmethod
    def from_matrix(R: ArrayLike, orthonormalize: bool = True) -> SO3:
        m = np.asarray(R, dtype=np.float64)
        if m.shape != (3, 3) or not np.all(np.isfinite(m)):
            raise ShapeError(f"rotation must be a finite (3,3) matrix, got {m.shape}")
        return SO3(_project_to_so3(m) if orthonormalize else m)

    @staticmethod
    def from_quat_wxyz(q: ArrayLike) -> SO3:
        return SO3(quat_wxyz_to_matrix(_as_vec(q, 4, "quat_wxyz")))

    def log(self) -> F64:
        return np.asarray(so3_log(self.R), dtype=np.float64)

    def matrix(self) -> F64:
        return np.array(self.R)

    def quat_wxyz(self) -> F64:
        return np.asarray(matrix_to_quat_wxyz(self.R), dtype=np.float64)

    def inverse(self) -> SO3:
        return SO3(self.R.T)

    def __matmul__(self, other: SO3) -> SO3:
        return SO3(_project_to_so3(self.R @ other.R))

    def act(self, points: ArrayLike) -> F64:
        return _apply(self.R, np.zeros(3), 1.0, points)

    def angle(self) -> float:
        return float(np.linalg.norm(self.log()))

    def interpolate(self, other: SO3, alpha: float) -> SO3:
        """Geodesic interpolation: alpha=0 -> self, alpha=1 -> other."""
        delta = (self.inverse() @ other).log()
        return self @ SO3.exp(alpha * delta)


@dataclass(frozen=True, slots=True, eq=False)
class SE3:
    """A rigid transform ``p_a = R p_b + t`` (see the module docstring for ``T_a_b``)."""

    rot: SO3
    t: F64

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", _frozen(_as_vec(self.t, 3, "SE3 translation")))

    @staticmethod
    def identity() -> SE3:
        return SE3(SO3.identity(), np.zeros(3))

    @staticmethod
    def exp(xi: ArrayLike) -> SE3:
        v = _as_vec(xi, 6, "se3 tangent [rho, phi]")
        rho, phi = v[:3], v[3:]
        return SE3(SO3.exp(phi), so3_left_jacobian(phi) @ rho)

    @staticmethod
    def from_matrix(T: ArrayLike) -> SE3:
        m = np.asarray(T, dtype=np.float64)
        if m.shape not in ((4, 4), (3, 4)) or not np.all(np.isfinite(m)):
            raise ShapeError(f"SE3 matrix must be finite (4,4) or (3,4), got {m.shape}")
        return SE3(SO3.from_matrix(m[:3, :3]), m[:3, 3])

    @staticmethod
    def from_quat_wxyz(q: ArrayLike, t: ArrayLike) -> SE3:
        return SE3(SO3.from_quat_wxyz(q), np.asarray(t, dtype=np.float64))

    @property
    def R(self) -> F64:
        return self.rot.R

    def log(self) -> F64:
        phi = self.rot.log()
        rho = np.linalg.solve(so3_left_jacobian(phi), self.t)
        return np.concatenate([rho, phi])

    def matrix(self) -> F64:
        T = np.eye(4)
        T[:3, :3] = self.rot.R
        T[:3, 3] = self.t
        return T

    def inverse(self) -> SE3:
        Rt = self.rot.R.T
        return SE3(SO3(Rt), -Rt @ self.t)

    def __matmul__(self, other: SE3) -> SE3:
        return SE3(self.rot @ other.rot, self.rot.R @ other.t + self.t)

    def act(self, points: ArrayLike) -> F64:
        return _apply(self.rot.R, self.t, 1.0, points)

    def interpolate(self, other: SE3, alpha: float) -> SE3:
        """Rotation by slerp, translation linearly (:func:`interpolate_se3`)."""
        return SE3.from_matrix(interpolate_se3(self.matrix(), other.matrix(), alpha))


@dataclass(frozen=True, slots=True, eq=False)
class Sim3:
    """A similarity transform ``p_a = s R p_b + t`` with scale ``s > 0``."""

    rot: SO3
    t: F64
    s: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", _frozen(_as_vec(self.t, 3, "Sim3 translation")))
        s = float(self.s)
        if not np.isfinite(s) or s <= 0.0:
            raise ShapeError(f"Sim3 scale must be finite and > 0, got {s}")
        object.__setattr__(self, "s", s)

    @staticmethod
    def identity() -> Sim3:
        return Sim3(SO3.identity(), np.zeros(3), 1.0)

    @staticmethod
    def from_se3(T: SE3, s: float = 1.0) -> Sim3:
        return Sim3(T.rot, T.t, s)

    @staticmethod
    def from_matrix(M: ArrayLike) -> Sim3:
        m = np.asarray(M, dtype=np.float64)
        if m.shape != (4, 4) or not np.all(np.isfinite(m)):
            raise ShapeError(f"Sim3 matrix must be finite (4,4), got {m.shape}")
        sR = m[:3, :3]
        s = float(np.cbrt(np.linalg.det(sR)))
        if s <= 0:
            raise ShapeError("Sim3 matrix has non-positive scale")
        return Sim3(SO3.from_matrix(sR / s), m[:3, 3], s)

    @staticmethod
    def _v_matrix(phi: F64, sigma: float) -> F64:
        """V(phi, sigma) with t = V rho (Eade, 'Lie groups for computer vision', Sim3 section)."""
        theta = float(np.linalg.norm(phi))
        W = hat(phi)
        if abs(sigma) < 1e-8:
            # first order in sigma: at order zero, exp and log fell on different sides of the
            # switch (log(exp(1e-8)) < 1e-8) and the round trip was off by 2e-8
            _, b, c = _so3_coeffs(np.asarray(theta))
            if theta < 1e-2:
                db, dc = 1.0 / 3.0, 1.0 / 8.0  # their limits; the O(theta^2) rest times sigma < 1e-12
            else:
                st, ct = np.sin(theta), np.cos(theta)
                db = (st - theta * ct) / theta**3
                dc = (0.5 - (theta * st + ct - 1.0) / theta**2) / theta**2
            a0, b0, c0 = 1.0 + 0.5 * sigma, float(b) + sigma * db, float(c) + sigma * dc
        else:
            es = np.exp(sigma)
            a0 = float(np.expm1(sigma)) / sigma  # not (es - 1) / sigma: cancellation near 0
            # below theta = 1e-4 the closed forms cancel; their values at theta = 0 are off by
            # O(theta^2), which W and W^2 make O(theta^3) in V
            if theta < 1e-4 and abs(sigma) < 1e-4:  # and these cancel too: their series
                b0 = 0.5 + sigma / 3.0 + sigma * sigma / 8.0
                c0 = 1.0 / 6.0 + sigma / 8.0 + sigma * sigma / 20.0
            elif theta < 1e-4:
                b0 = (es * (sigma - 1.0) + 1.0) / sigma**2
                c0 = (es * (sigma * sigma - 2.0 * sigma + 2.0) - 2.0) / (2.0 * sigma**3)
            else:
                st, ct = np.sin(theta), np.cos(theta)
                den = sigma * sigma + theta * theta
                b0 = (
                    (es * (sigma * st - theta * ct) + theta) / (theta * den)
                )
                c0 = (a0 - (es * (sigma * ct + theta * st) - sigma) / den) / (theta * theta)
        return np.asarray(a0 * np.eye(3) + b0 * W + c0 * (W @ W), dtype=np.float64)

    @staticmethod
    def exp(xi: ArrayLike) -> Sim3:
        v = _as_vec(xi, 7, "sim3 tangent [rho, phi, sigma]")
        rho, phi, sigma = v[:3], v[3:6], float(v[6])
        return Sim3(SO3.exp(phi), Sim3._v_matrix(phi, sigma) @ rho, float(np.exp(sigma)))

    def log(self) -> F64:
        phi = self.rot.log()
        sigma = float(np.log(self.s))
        rho = np.linalg.solve(Sim3._v_matrix(phi, sigma), self.t)
        return np.concatenate([rho, phi, [sigma]])

    @property
    def R(self) -> F64:
        return self.rot.R

    def matrix(self) -> F64:
        M = np.eye(4)
        M[:3, :3] = self.s * self.rot.R
        M[:3, 3] = self.t
        return M

    def inverse(self) -> Sim3:
        Rt = self.rot.R.T
        return Sim3(SO3(Rt), -(Rt @ self.t) / self.s, 1.0 / self.s)

    def __matmul__(self, other: Sim3) -> Sim3:
        return Sim3(self.rot @ other.rot, self.s * (self.rot.R @ other.t) + self.t, self.s * other.s)

    def act(self, points: ArrayLike) -> F64:
        return _apply(self.rot.R, self.t, self.s, points)

    @staticmethod
    def from_srt(s: float, R: ArrayLike, t: ArrayLike) -> Sim3:
        """From scale ``s``, rotation ``R`` (3, 3; checked, not re-orthonormalised) and ``t`` (3,)."""
        return Sim3(SO3(np.asarray(R, dtype=np.float64)), np.asarray(t, dtype=np.float64), s)

    def srt(self) -> tuple[float, F64, F64]:
        """(s, R (3, 3), t (3,)) with ``p_a = s R p_b + t``."""
        return self.s, np.array(self.rot.R), np.array(self.t)

    def transform_pose(self, T_b_x: SE3) -> SE3:
        """Change of world frame for a pose: ``T_a_x = S_a_b * T_b_x`` with the scale applied to
        the position only, so the result stays rigid: R = R_S R_T, t = (s R_S) t_T + t_S.
        (Maps a camera pose T_world_cam of a map segment into the global frame.)"""
        R = self.rot.R @ T_b_x.rot.R
        return SE3(SO3(R), self.s * self.rot.R @ T_b_x.t + self.t)

    def transform_pose_matrix(self, T_b_x: F64) -> F64:
        """:meth:`transform_pose` on a 4x4 pose matrix (no validation, no re-orthonormalisation)."""
        out = np.array(T_b_x, dtype=np.float64, copy=True)
        out[:3, 3] = self.s * self.rot.R @ out[:3, 3] + self.t
        out[:3, :3] = self.rot.R @ out[:3, :3]
        return out

    def to_se3(self) -> SE3:
        """The rigid part (R, t), dropping the scale."""
        return SE3(self.rot, self.t)

    def interpolate(self, other: Sim3, alpha: float) -> Sim3:
        rot = self.rot.interpolate(other.rot, alpha)
        t = (1 - alpha) * self.t + alpha * other.t
        s = float(np.exp((1 - alpha) * np.log(self.s) + alpha * np.log(other.s)))
        return Sim3(rot, t, s)
