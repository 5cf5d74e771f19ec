"""Sparse direct image alignment over SE(3) plus affine brightness (seed §4).

Residual r(u) = I_c(w(u; xi)) - (a I_r(u) + b) with the warp w(u) = pi(K T_c_r d(u) K^-1 u);
Gauss-Newton (J^T W J) dtheta = -J^T W r with Huber weights, coarse-to-fine over an image
pyramid. Jacobians (seed §4): dr/da = -I_r(u), dr/db = -1,
dr/dxi = grad I_c(u') d(uv)/d(xi) (geometry.projection.project_jacobian, left perturbation,
fused with the gradient in ``_gradient_pose_jacobian``). Near-zero depth: pixels whose warped
point has Z <= geometry.projection.MIN_DEPTH are dropped.
"""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.geometry.checks import check_matrix, check_points
from amrvio.geometry.projection import MIN_DEPTH
from amrvio.types.lie import SE3, transform_points

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


class DirectStatus(Enum):
    """Outcome of a direct alignment."""

    OK = "ok"
    TOO_FEW_PIXELS = "too_few_pixels"
    DIVERGED = "diverged"


@dataclass(frozen=True, slots=True)
class DirectResult:
    """``T_cur_ref`` (4x4), the brightness ``I_c ~ a I_r + b``, pixels used and final RMS."""

    status: DirectStatus
    T_cur_ref: F64
    a: float
    b: float
    n_used: int
    rms: float

    @property
    def ok(self) -> bool:
        return self.status is DirectStatus.OK


@dataclass(frozen=True, slots=True)
class DirectConfig:
    """Pyramid levels, GN iterations per level, Huber threshold (intensity units)."""

    levels: int = 4
    iterations: int = 20
    huber: float = 9.0
    min_pixels: int = 30
    max_rms: float = 40.0
    estimate_affine: bool = True  # False: brightness constancy (a, b) = (a0, b0) (ablation)


def _sample(img: NDArray[np.float32], uv: F64) -> F64:
    """Bilinear samples of a float image at (N, 2) pixel positions (border replicated)."""
    m = uv.astype(np.float32).reshape(-1, 1, 2)
    out = cv2.remap(img, m, None, interpolation=cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return np.asarray(out, dtype=np.float64).reshape(-1)


def _pyramid(img: U8, levels: int) -> list[NDArray[np.float32]]:
    pyr = [img.astype(np.float32)]
    for _ in range(levels - 1):
        pyr.append(cv2.pyrDown(pyr[-1]))
    return pyr


def _gradient_pose_jacobian(gx: F64, gy: F64, P_cam: F64, iz: F64, fx: float, fy: float) -> F64:
    """(N, 6) d(I_c(uv))/d(xi) = [gx, gy] . d(uv)/d(xi) for camera points (N, 3), 1/Z ``iz``.

    The chain rule of ``geometry.projection.project_jacobian`` (left perturbation, [rho, phi])
    fused with the image gradient: 6 columns instead of a (N, 2, 6) block, in the operation
    order the VO's figures were made with (tests check it against project_jacobian).
    """
    gP = np.column_stack([gx * fx * iz, gy * fy * iz,
                          -(gx * fx * P_cam[:, 0] + gy * fy * P_cam[:, 1]) * iz * iz])
    X, Y, Z = P_cam[:, 0], P_cam[:, 1], P_cam[:, 2]
    # gP @ (-[P]x) for the rotation part
    Jrot = np.column_stack([gP[:, 2] * Y - gP[:, 1] * Z,
                            gP[:, 0] * Z - gP[:, 2] * X,
                            gP[:, 1] * X - gP[:, 0] * Y])
    return np.column_stack([gP, Jrot])


def align_direct(
    img_ref: U8,
    img_cur: U8,
    pts_ref_px: F64,
    depth_ref: F64,
    K: F64,
    *,
    T_init: F64 | None = None,
    a0: float = 1.0,
    b0: float = 0.0,
    config: DirectConfig | None = None,
) -> DirectResult:
    """Align ``img_cur`` to ``img_ref`` given (N, 2) reference pixels with (N,) depths.

    Returns ``T_cur_ref`` mapping reference-camera points into the current camera, and (a, b).
    """
    cfg = config or DirectConfig()
    u = check_points("pts_ref_px", pts_ref_px, 2)
    d = np.asarray(depth_ref, dtype=np.float64).reshape(-1)
    Km = check_matrix("K", K, (3, 3))
    if len(d) != len(u):
        raise ShapeError(f"depth_ref must have {len(u)} entries, got {len(d)}")
    if img_ref.ndim != 2 or img_cur.ndim != 2:
        raise ShapeError("align_direct expects (H, W) grey images")
    good = np.isfinite(d) & (d > 0)
    u, d = u[good], d[good]
    T = np.eye(4) if T_init is None else check_matrix("T_init", T_init, (4, 4)).copy()
    a, b = float(a0), float(b0)
    if len(u) < cfg.min_pixels:
        return DirectResult(DirectStatus.TOO_FEW_PIXELS, T, a, b, len(u), float("inf"))
    pr = _pyramid(img_ref, cfg.levels)
    pc = _pyramid(img_cur, cfg.levels)
    rms = float("inf")
    n_used = 0
    for lvl in range(cfg.levels - 1, -1, -1):
        s = 0.5**lvl
        fx, fy = Km[0, 0] * s, Km[1, 1] * s
        cx, cy = (Km[0, 2] + 0.5) * s - 0.5, (Km[1, 2] + 0.5) * s - 0.5
        ul = (u + 0.5) * s - 0.5
        Ir = _sample(pr[lvl], ul)
        # 3D points in the reference camera
        P_ref = np.column_stack([(ul[:, 0] - cx) / fx * d, (ul[:, 1] - cy) / fy * d, d])
        Ic = pc[lvl]
        gx = cv2.Sobel(Ic, cv2.CV_32F, 1, 0, ksize=3, scale=1.0 / 8)
        gy = cv2.Sobel(Ic, cv2.CV_32F, 0, 1, ksize=3, scale=1.0 / 8)
        h, w = Ic.shape
        for _ in range(cfg.iterations):
            P = transform_points(T, P_ref)
            z = P[:, 2]
            ok = z > MIN_DEPTH
            zs = np.where(ok, z, 1.0)
            # the pinhole of geometry.projection.project, written as x / z (figures unchanged)
            uc = np.column_stack([fx * P[:, 0] / zs + cx, fy * P[:, 1] / zs + cy])
            ok &= (uc[:, 0] >= 1) & (uc[:, 0] < w - 2) & (uc[:, 1] >= 1) & (uc[:, 1] < h - 2)
            n_used = int(ok.sum())
            if n_used < cfg.min_pixels:
                return DirectResult(DirectStatus.TOO_FEW_PIXELS, T, a, b, n_used, rms)
            Pk, zk, uk = P[ok], zs[ok], uc[ok]
            r = _sample(Ic, uk) - (a * Ir[ok] + b)  # seed §4 residual
            gxs, gys = _sample(gx, uk), _sample(gy, uk)
            J_xi = _gradient_pose_jacobian(gxs, gys, Pk, 1.0 / zk, fx, fy)
            J = np.column_stack([J_xi, -Ir[ok], -np.ones(n_used)])  # dr/da=-I_r, dr/db=-1
            ar = np.abs(r)
            wgt = np.where(ar <= cfg.huber, 1.0, cfg.huber / np.maximum(ar, 1e-12))
            H = J.T @ (J * wgt[:, None])
            g = J.T @ (wgt * r)
            H[6, 6] += 1e-3 * n_used  # weak prior keeps (a, b) well posed on flat patches
            H[7, 7] += 1e-6 * n_used
            npar = 8 if cfg.estimate_affine else 6
            try:
                dx = np.zeros(8)
                dx[:npar] = -np.linalg.solve(H[:npar, :npar] + 1e-9 * np.eye(npar), g[:npar])
            except np.linalg.LinAlgError:
                return DirectResult(DirectStatus.DIVERGED, T, a, b, n_used, rms)
            T = SE3.exp(dx[:6]).matrix() @ T
            a += float(dx[6])
            b += float(dx[7])
            rms = float(np.sqrt(np.mean(r * r)))
            if np.linalg.norm(dx[:6]) < 1e-7:
                break
    if not np.isfinite(rms) or rms > cfg.max_rms or not (a > 0):
        return DirectResult(DirectStatus.DIVERGED, T, a, b, n_used, rms)
    return DirectResult(DirectStatus.OK, T, a, b, n_used, rms)


def select_gradient_pixels(img: U8, n: int, border: int = 8) -> F64:
    """Up to ``n`` (N, 2) pixels with the strongest gradients, spread over a 16x16 grid."""
    g = cv2.magnitude(cv2.Sobel(img, cv2.CV_32F, 1, 0), cv2.Sobel(img, cv2.CV_32F, 0, 1))
    h, w = img.shape
    g[:border] = 0
    g[h - border:] = 0
    g[:, :border] = 0
    g[:, w - border:] = 0
    per = max(1, n // 256)
    out = []
    for r0 in np.linspace(0, h, 17).astype(int)[:-1]:
        for c0 in np.linspace(0, w, 17).astype(int)[:-1]:
            blk = g[r0 : r0 + max(1, h // 16), c0 : c0 + max(1, w // 16)]
            if blk.size == 0:
                continue
            idx = np.argsort(blk.ravel())[::-1][:per]
            rr, cc = np.unravel_index(idx, blk.shape)
            keep = blk[rr, cc] > 5.0
            out.append(np.column_stack([cc[keep] + c0, rr[keep] + r0]))
    return np.vstack(out).astype(np.float64) if out else np.zeros((0, 2))


__all__ = ["DirectConfig", "DirectResult", "DirectStatus", "align_direct",
           "select_gradient_pixels"]
