"""Affine brightness compensation between two frames (seed §4: I_c ~ a I_r + b).

Used before KLT so that exposure jumps do not break tracks. The fit is robust and cheap: it
matches robust quantiles of the two images (the same scene under a gain/offset change maps
quantiles affinely). With known correspondences, use amrvio.photometric.affine.fit_affine_robust.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

QUANTILES = np.arange(5.0, 96.0, 5.0)


@dataclass(frozen=True, slots=True)
class AffineBrightness:
    """``I_cur ~ a * I_ref + b`` (intensities in [0, 255])."""

    a: float = 1.0
    b: float = 0.0

    def is_identity(self, tol_a: float = 0.03, tol_b: float = 3.0) -> bool:
        """True when the change is too small to matter (KLT absorbs it)."""
        return abs(self.a - 1.0) < tol_a and abs(self.b) < tol_b

    def apply(self, img: NDArray[np.uint8]) -> NDArray[np.uint8]:
        """Map a reference image into the brightness of the current one (uint8, clipped)."""
        if self.is_identity(1e-3, 0.5):
            return img
        # a 256-entry lookup table: the same float32 arithmetic per grey level, once
        lut = np.arange(256, dtype=np.float32) * np.float32(self.a) + np.float32(self.b)
        table = np.clip(lut + np.float32(0.5), 0, 255).astype(np.uint8)
        return np.asarray(table[img], dtype=np.uint8)


def image_quantiles(img: NDArray[np.uint8], stride: int = 4) -> NDArray[np.float64]:
    """The 5, 10, ..., 95 % intensity quantiles (19,) of a subsampled grey image."""
    if img.ndim != 2:
        raise ShapeError(f"expected an (H, W) grey image, got shape {img.shape}")
    return np.asarray(np.percentile(img[::stride, ::stride], QUANTILES), dtype=np.float64)


def fit_affine_quantiles(
    img_ref: NDArray[np.uint8], img_cur: NDArray[np.uint8], *, stride: int = 4
) -> AffineBrightness:
    """Affine (a, b) from the intensity quantiles of subsampled pixels."""
    return affine_from_quantiles(image_quantiles(img_ref, stride), image_quantiles(img_cur, stride))


def affine_from_quantiles(qr: NDArray[np.float64], qc: NDArray[np.float64]) -> AffineBrightness:
    """Least-squares affine (a, b) mapping reference quantiles (Q,) onto current ones (Q,);
    quantile pairs where either image saturates (<= 2 or >= 253) are left out."""
    ok = (qr > 2) & (qr < 253) & (qc > 2) & (qc < 253)
    if int(ok.sum()) < 3 or float(np.ptp(qr[ok])) < 1.0:
        return AffineBrightness()
    A = np.column_stack([qr[ok], np.ones(int(ok.sum()))])
    (a, b), *_ = np.linalg.lstsq(A, qc[ok], rcond=None)
    if not np.isfinite(a) or a <= 0.05:
        return AffineBrightness()
    return AffineBrightness(float(a), float(b))


__all__ = ["AffineBrightness", "affine_from_quantiles", "fit_affine_quantiles", "image_quantiles"]
