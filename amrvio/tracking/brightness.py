"""Brightness invariance for tracking (seed section 4: ``I_cur ~ a I_ref + b``).

Three modes, :class:`Invariance`:

- ``affine``: fit (a, b) between the two images from their intensity quantiles (the same scene
  under a gain/offset change maps quantiles affinely) and map the reference image into the
  brightness of the current one before tracking. Cheap, and it reports the change;
- ``normalise``: track on images normalised to a fixed mean and standard deviation (an affine
  change of intensity leaves them unchanged, apart from clipping). Per image, so it can be cached;
- ``none``: raw intensities.

With known correspondences, fit the change with :func:`amrvio.photometric.affine.fit_affine_robust`.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

QUANTILES = np.arange(5.0, 96.0, 5.0)
U8 = NDArray[np.uint8]


class Invariance(enum.Enum):
    """How the tracker copes with a brightness change between two images."""

    AFFINE = "affine"
    NORMALISE = "normalise"
    NONE = "none"


@dataclass(frozen=True, slots=True)
class AffineBrightness:
    """``I_cur ~ a * I_ref + b`` (intensities in [0, 255])."""

    a: float = 1.0
    b: float = 0.0

    def is_identity(self, tol_a: float = 0.03, tol_b: float = 3.0) -> bool:
        """True when the change is too small to matter (KLT absorbs it)."""
        return abs(self.a - 1.0) < tol_a and abs(self.b) < tol_b

    def apply(self, img: U8) -> U8:
        """Map a reference image into the brightness of the current one (uint8, clipped)."""
        if self.is_identity(1e-3, 0.5):
            return img
        # a 256-entry lookup table: the same float32 arithmetic per grey level, once
        lut = np.arange(256, dtype=np.float32) * np.float32(self.a) + np.float32(self.b)
        table = np.clip(lut + np.float32(0.5), 0, 255).astype(np.uint8)
        # cv2.LUT gives table[img] at a fraction of NumPy's fancy-indexing cost
        return np.asarray(cv2.LUT(np.ascontiguousarray(img, dtype=np.uint8), table),
                          dtype=np.uint8)


def image_quantiles(img: U8, stride: int = 4) -> NDArray[np.float64]:
    """The 5, 10, ..., 95 % intensity quantiles (19,) of a subsampled grey image."""
    if img.ndim != 2:
        raise ShapeError(f"expected an (H, W) grey image, got shape {img.shape}")
    sub = img[::stride, ::stride]
    if sub.dtype != np.uint8 or sub.size == 0:
        return np.asarray(np.percentile(sub, QUANTILES), dtype=np.float64)
    # np.percentile's linear rule, read off the 256-bin histogram instead of a sort (the
    # same arithmetic, so the same values; a hundredth of the cost)
    n = sub.size
    q = np.true_divide(QUANTILES, 100)
    virtual = (n - 1) * q
    below = np.floor(virtual)
    gamma = virtual - below
    lo = np.clip(below, 0, n - 1).astype(np.int64)
    hi = np.clip(below + 1, 0, n - 1).astype(np.int64)
    cdf = np.cumsum(np.bincount(sub.ravel(), minlength=256))
    a = np.searchsorted(cdf, lo, side="right").astype(np.float64)
    b = np.searchsorted(cdf, hi, side="right").astype(np.float64)
    d = b - a
    return np.where(gamma >= 0.5, b - d * (1.0 - gamma), a + d * gamma)


def fit_affine_quantiles(img_ref: U8, img_cur: U8, *, stride: int = 4) -> AffineBrightness:
    """Affine (a, b) from the intensity quantiles of subsampled pixels."""
    return affine_from_quantiles(image_quantiles(img_ref, stride), image_quantiles(img_cur, stride))


def affine_from_quantiles(qr: NDArray[np.float64], qc: NDArray[np.float64]) -> AffineBrightness:
    """Least-squares affine (a, b) mapping reference quantiles (Q,) onto current ones (Q,);
    quantile pairs where either image saturates (<= 2 or >= 253) are left out."""
    ok = (qr > 2) & (qr < 253) & (qc > 2) & (qc < 253)
    if int(ok.sum()) < 3 or float(np.ptp(qr[ok])) < 1.0:
        return AffineBrightness()
    x, y = qr[ok], qc[ok]
    dx = x - x.mean()  # least squares in closed form (lstsq costs ten times more per frame)
    a = float(dx @ (y - y.mean())) / float(dx @ dx)
    b = float(y.mean()) - a * float(x.mean())
    if not np.isfinite(a) or a <= 0.05:
        return AffineBrightness()
    return AffineBrightness(a, b)


def normalise_for_tracking(image: U8) -> U8:
    """(H, W) uint8 -> uint8 ``128 + 40 (I - mean) / std``: invariant to affine brightness."""
    img = np.asarray(image)
    if img.ndim != 2 or img.shape[0] < 8 or img.shape[1] < 8:
        raise ShapeError(f"image must be a (H,W) grey image of at least 8x8, got {img.shape}")
    mean, std = cv2.meanStdDev(img)
    s = max(float(std[0, 0]), 1e-3)
    alpha = 40.0 / s
    beta = 128.0 - alpha * float(mean[0, 0])
    # addWeighted saturates to 0..255 (no abs, unlike convertScaleAbs).
    out: U8 = cv2.addWeighted(img, alpha, img, 0.0, beta, dtype=cv2.CV_8U)
    return out


__all__ = [
    "AffineBrightness",
    "Invariance",
    "affine_from_quantiles",
    "fit_affine_quantiles",
    "image_quantiles",
    "normalise_for_tracking",
]
