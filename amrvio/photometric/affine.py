"""Affine brightness model between two images: I_cur ~= a * I_ref + b (seed section 4).

Two estimators on paired intensities ``(x_i, y_i)`` (reference, current):

- :func:`fit_affine_closed_form` solves the 2x2 normal equations of seed Problem 3;
- :func:`fit_affine_robust` masks saturated / under-exposed samples and runs IRLS with Huber weights
  (seed section 6.2: saturated pixels and shadows treated as outliers by a robust kernel).

Pairs must be *corresponding* pixels: the same pixel when the camera is still, or samples around
tracked features when it moves (see :mod:`amrvio.diagnostics.exposure`).

EV: with a linear response and zero offset, a change of exposure time by a factor k scales every
intensity by k, so ``ev = log2(a)``. With a nonlinear response, fit on linearised intensities
(``G^-1(I)``, see :func:`linearise`), otherwise log2(a) under-reports the exposure change.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

SATURATED_DN = 250.0
UNDEREXPOSED_DN = 5.0


class AffineStatus(enum.Enum):
    OK = "ok"
    TOO_FEW_SAMPLES = "too_few_samples"
    NO_CONTRAST = "no_contrast"
    UNCORRELATED = "uncorrelated"  # the two sample sets do not look like one scene


@dataclass(frozen=True, slots=True)
class AffineFit:
    """Result of an affine brightness fit ``y ~= a * x + b``.

    ``a = 1, b = 0`` when ``status`` is not OK. ``n_used`` counts unmasked samples;
    ``rms_residual`` is over those (DN); ``x_median``: median of the used ``x``. ``ev`` is
    ``log2(a)`` (see module docstring).
    """

    a: float
    b: float
    status: AffineStatus
    n_used: int
    n_total: int
    rms_residual: float
    iterations: int = 0
    x_median: float = float("nan")

    @property
    def ok(self) -> bool:
        return self.status is AffineStatus.OK

    @property
    def ev(self) -> float:
        """``log2(a)``: the exposure step when the offset is ~0 and the response is linear."""
        return math.log2(self.a) if self.a > 0 else float("nan")


def _as_pairs(x: NDArray[np.generic], y: NDArray[np.generic]) -> tuple[
    NDArray[np.float64], NDArray[np.float64]
]:
    xf = np.asarray(x, dtype=np.float64).ravel()
    yf = np.asarray(y, dtype=np.float64).ravel()
    if np.shape(x) != np.shape(y):
        raise ShapeError(f"x and y must have the same shape, got {np.shape(x)} and {np.shape(y)}")
    return xf, yf


def _solve_weighted(
    x: NDArray[np.float64],
    y: NDArray[np.float64],
    w: NDArray[np.float64] | None,
    fit_offset: bool = True,
) -> tuple[float, float] | None:
    if not fit_offset:  # y = a x: a = Sxy / Sxx
        ww = np.ones_like(x) if w is None else w
        sxx0 = float((ww * x) @ x)
        if sxx0 <= 1e-12 * max(float(ww.sum()), 1e-300):
            return None
        return float((ww * x) @ y) / sxx0, 0.0
    # Normal equations of seed Problem 3, weighted: [Sxx Sx; Sx S1][a b]^T = [Sxy Sy]^T.
    if w is None:
        s1 = float(x.size)
        sx, sy = float(x.sum()), float(y.sum())
        sxx, sxy = float(x @ x), float(x @ y)
    else:
        s1 = float(w.sum())
        wx = w * x
        sx, sy = float(wx.sum()), float(w @ y)
        sxx, sxy = float(wx @ x), float(wx @ y)
    det = sxx * s1 - sx * sx
    # Contrast check, scale-free: det / s1^2 is the weighted variance of x.
    if s1 <= 0 or det <= 1e-9 * s1 * s1:
        return None
    a = (sxy * s1 - sx * sy) / det
    b = (sxx * sy - sx * sxy) / det
    return a, b


def fit_affine_closed_form(x: NDArray[np.generic], y: NDArray[np.generic]) -> AffineFit:
    """Least-squares ``min_{a,b} sum (a x_i + b - y_i)^2`` by the normal equations (seed Problem 3).

    ``x``, ``y``: paired intensities of any equal shape. Non-finite pairs are dropped. No masking.
    """
    xf, yf = _as_pairs(x, y)
    keep = np.isfinite(xf) & np.isfinite(yf)
    xf, yf = xf[keep], yf[keep]
    n_total = int(keep.size)
    if xf.size < 2:
        return AffineFit(1.0, 0.0, AffineStatus.TOO_FEW_SAMPLES, int(xf.size), n_total, float("nan"))
    sol = _solve_weighted(xf, yf, None)
    if sol is None:
        return AffineFit(1.0, 0.0, AffineStatus.NO_CONTRAST, int(xf.size), n_total, float("nan"))
    a, b = sol
    r = a * xf + b - yf
    return AffineFit(a, b, AffineStatus.OK, int(xf.size), n_total, float(np.sqrt(np.mean(r * r))),
                     0, float(np.median(xf)))


def valid_intensity_mask(
    x: NDArray[np.generic],
    y: NDArray[np.generic],
    low: float = UNDEREXPOSED_DN,
    high: float = SATURATED_DN,
) -> NDArray[np.bool_]:
    """True where both raw intensities lie strictly inside (low, high) and are finite."""
    xf = np.asarray(x, dtype=np.float64)
    yf = np.asarray(y, dtype=np.float64)
    return (xf > low) & (xf < high) & (yf > low) & (yf < high)


def fit_affine_robust(
    x: NDArray[np.generic],
    y: NDArray[np.generic],
    *,
    mask: NDArray[np.bool_] | None = None,
    weights: NDArray[np.floating] | None = None,
    low: float = UNDEREXPOSED_DN,
    high: float = SATURATED_DN,
    huber_k: float = 1.345,
    min_sigma: float = 0.5,
    max_iter: int = 15,
    tol: float = 1e-7,
    min_samples: int = 20,
    fit_offset: bool = True,
) -> AffineFit:
    """Robust affine fit: masked, then IRLS with Huber weights.

    Samples where either intensity is ``<= low`` or ``>= high`` are masked (clipped values do not
    follow the affine model). Masking on the observed ``y`` alone would censor the noise near the
    clip levels and bias ``a`` low, so each iteration also masks samples whose *predicted*
    ``a x + b`` lies within ``3 sigma`` of a clip level. ``mask`` (same shape) replaces the
    ``low/high`` test on the inputs (use it when ``x, y`` were linearised from raw intensities;
    the prediction test then uses ``low/high`` in the units of ``y``). ``weights`` (same shape,
    >= 0) multiply the Huber weights. Huber threshold: ``huber_k * sigma``, sigma = 1.4826 * MAD
    of the residuals (floored at ``min_sigma`` DN, about the quantisation noise).
    ``fit_offset=False`` fits ``y = a x`` (b = 0), the model of linearised intensities.
    """
    xf, yf = _as_pairs(x, y)
    n_total = int(xf.size)
    keep = np.isfinite(xf) & np.isfinite(yf)
    if mask is None:
        keep &= (xf > low) & (xf < high) & (yf > low) & (yf < high)
    else:
        m = np.asarray(mask, dtype=bool)
        if m.shape != np.shape(x):
            raise ShapeError(f"mask shape {m.shape} differs from x shape {np.shape(x)}")
        keep &= m.ravel()
    prior: NDArray[np.float64] | None = None
    if weights is not None:
        pw = np.asarray(weights, dtype=np.float64)
        if pw.shape != np.shape(x):
            raise ShapeError(f"weights shape {pw.shape} differs from x shape {np.shape(x)}")
        pw = pw.ravel()
        keep &= np.isfinite(pw) & (pw > 0)
        prior = pw[keep]
    xs, ys = xf[keep], yf[keep]
    n_used = int(xs.size)
    if n_used < max(min_samples, 2):
        return AffineFit(1.0, 0.0, AffineStatus.TOO_FEW_SAMPLES, n_used, n_total, float("nan"))
    sol = _solve_weighted(xs, ys, prior, fit_offset)
    if sol is None:
        return AffineFit(1.0, 0.0, AffineStatus.NO_CONTRAST, n_used, n_total, float("nan"))
    a, b = sol
    it = 0
    inside = np.ones(n_used, dtype=bool)
    for it in range(1, max_iter + 1):
        r = a * xs + b - ys
        sigma = max(1.4826 * float(np.median(np.abs(r[inside]))), min_sigma)
        c = huber_k * sigma
        absr = np.abs(r)
        w = np.where(absr <= c, 1.0, c / np.maximum(absr, 1e-300))  # Huber IRLS weights
        if prior is not None:
            w = w * prior
        pred = a * xs + b
        inside = (pred > low + 3.0 * sigma) & (pred < high - 3.0 * sigma)
        if int(inside.sum()) < max(min_samples, 2):
            inside[:] = True
        new = _solve_weighted(xs, ys, np.where(inside, w, 0.0), fit_offset)
        if new is None:
            return AffineFit(1.0, 0.0, AffineStatus.NO_CONTRAST, n_used, n_total, float("nan"), it)
        da, db = new[0] - a, new[1] - b
        a, b = new
        if abs(da) < tol * max(1.0, abs(a)) and abs(db) < tol * max(1.0, abs(b)):
            break
    r = (a * xs + b - ys)[inside]
    n_in = int(inside.sum())
    return AffineFit(a, b, AffineStatus.OK, n_in, n_total, float(np.sqrt(np.mean(r * r))), it,
                     float(np.median(xs[inside])))


def linearise(
    image: NDArray[np.generic], inverse_response: NDArray[np.floating]
) -> NDArray[np.float64]:
    """Map raw intensities (uint8, or float samples) through G^-1, rescaled to 0..255 linear DN.

    ``inverse_response``: (256,) DSO pcalib values (G^-1 of each DN), monotone.
    """
    lut = np.asarray(inverse_response, dtype=np.float64)
    if lut.shape != (256,) or not np.all(np.isfinite(lut)):
        raise ShapeError(f"inverse_response must be (256,) finite, got {lut.shape}")
    span = lut[255] - lut[0]
    if span <= 0:
        raise ShapeError("inverse_response must increase from DN 0 to DN 255")
    scaled = (lut - lut[0]) * (255.0 / span)
    img = np.asarray(image)
    if np.issubdtype(img.dtype, np.integer):
        out: NDArray[np.float64] = scaled[np.clip(img, 0, 255).astype(np.intp)]
        return out
    # Sub-pixel samples: interpolate the LUT between DN values.
    return np.asarray(np.interp(img, np.arange(256.0), scaled), dtype=np.float64)
