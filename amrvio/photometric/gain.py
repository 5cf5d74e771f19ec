"""Gain and offset between two exposures of the same scene, proof against clipping.

Model: ``y = a x + b`` for corresponding intensities (``x`` reference, ``y`` current) that are
clipped in neither frame. A camera with black level ``o`` whose exposure changes by a factor
``k`` gives ``y - o = k (x - o)``, so ``a = k`` and ``b = o (1 - k)``: the exposure step is
``log2(a)`` once the offset is fitted as a separate unknown.

Two biases that a plain robust fit suffers under clipping are removed here:

- censoring. Dropping the samples clipped in ``y`` removes those whose noise pushed them over the
  clip level and keeps those it pushed under, so near the clip level the kept ``y`` are low and
  the slope comes out flat. Each iteration therefore keeps only the samples inside a window of
  the *model*: ``x`` in ``[lo, hi]`` and ``y`` in ``[a lo + b, a hi + b]``, where the window is
  the intensity range in which neither frame comes within ``margin`` robust sigmas of a clip
  level. Selection on both variables through the model's window is the same whichever frame is
  called the reference.
- errors in both variables. Misregistration and resampling perturb ``x`` as much as ``y`` (in
  ratio ``a``), so the least-squares slope of ``y`` on ``x`` is attenuated by the squared
  correlation. The slope is the reduced major axis ``sign(Sxy) sqrt(Syy / Sxx)`` of the weighted
  samples, which is the errors-in-variables estimate for a noise ratio of ``a^2`` and exactly
  symmetric: swapping the frames gives ``1 / a`` and ``-b / a``.

Robustness: iteratively reweighted, Huber weights first (a convex start), then Tukey's biweight
(gross outliers such as occlusions and moving objects get zero weight), on the symmetric
residual ``(a x + b - y) / sqrt(a)`` with sigma = 1.4826 MAD. Samples may come in groups (rows
of a 2-D array, the patches around tracked points): between the two phases, whole rows whose
median residual is an outlier among the rows are dropped.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.photometric.affine import SATURATED_DN, UNDEREXPOSED_DN, AffineFit, AffineStatus

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class GainFitConfig:
    """Settings of :func:`fit_gain_offset`. ``clip_levels``: (low, high) in the units of the
    samples; ``margin``: robust sigmas kept clear of them; ``huber_k``/``tukey_k``: kernel widths
    in robust sigmas; ``huber_iterations`` before the Tukey ones (``max_iterations`` in all;
    two Huber steps give the Tukey phase the same start as four: the KITTI 00 sweep of steps of
    +-0.3 to +-1.5 EV under 0-40 % clipping, tests/data_real/test_exposure_clipping_real.py,
    had the same errors to 1e-3 EV, at 3.4 iterations per fit instead of 5.4);
    ``min_sigma``: floor of the robust sigma (about the quantisation noise); ``min_samples``;
    ``min_correlation``: a weaker weighted correlation of the kept samples means the two sets are
    not the same scene (a failed fit); ``fit_offset=False`` fits ``y = a x`` (linearised
    intensities); ``tol``: the iterations stop when ``a`` moves by less than ``tol a`` and ``b``
    by less than ``tol`` of full scale. ``group_k``: with grouped samples (2-D input, one row per
    patch), a row whose median residual lies beyond ``group_k`` robust sigmas of the rows'
    median residuals is dropped after the Huber iterations (a patch on an occlusion edge or a
    moving object is wrong as a whole, sample noise is not)."""

    clip_levels: tuple[float, float] = (UNDEREXPOSED_DN, SATURATED_DN)
    margin: float = 2.5
    huber_k: float = 1.345
    tukey_k: float = 4.685
    huber_iterations: int = 2
    max_iterations: int = 20
    min_sigma: float = 0.5
    min_samples: int = 20
    min_correlation: float = 0.5
    fit_offset: bool = True
    tol: float = 1e-4
    group_k: float = 2.0


@dataclass(frozen=True, slots=True, eq=False)
class _Samples:
    """The kept samples and their moments' integrands as the rows of one (6, n) matrix
    ``[1, x, y, xx, yy, xy]``, so that all weighted moments are one matrix-vector product."""

    x: F64
    y: F64
    m: F64

    @staticmethod
    def of(x: F64, y: F64) -> _Samples:
        m = np.empty((6, x.size))
        m[0] = 1.0
        m[1], m[2] = x, y
        np.multiply(x, x, out=m[3])
        np.multiply(y, y, out=m[4])
        np.multiply(x, y, out=m[5])
        return _Samples(x, y, m)


def _median(v: F64) -> float:
    """The upper median (one partition; np.median's NaN checks and averaging cost more here)."""
    k = v.size // 2
    return float(np.partition(v, k)[k])


def _line(smp: _Samples, w: F64, fit_offset: bool) -> tuple[float, float, float] | None:
    """Reduced-major-axis line (a, b) of weighted samples and their weighted correlation."""
    s, sx, sy, sxx, syy, sxy = (smp.m @ w).tolist()
    if not fit_offset:  # through the origin: a = sqrt(Syy / Sxx) about 0
        if not (sxx > 0 and syy > 0 and sxy > 0):
            return None
        return math.sqrt(syy / sxx), 0.0, sxy / math.sqrt(sxx * syy)
    if not s > 0:
        return None
    mx, my = sx / s, sy / s
    vxx, vyy, vxy = sxx / s - mx * mx, syy / s - my * my, sxy / s - mx * my
    if not (vxx > 1e-9 and vyy > 1e-9) or vxy <= 0:
        return None
    a = math.sqrt(vyy / vxx)
    return a, my - a * mx, vxy / math.sqrt(vxx * vyy)


def _group_inliers(r: F64, index: NDArray[np.intp], used: NDArray[np.bool_],
                   shape: tuple[int, int], cfg: GainFitConfig) -> F64:
    """1.0 for the samples (flat ``index`` into ``shape``) of rows whose median residual is not
    an outlier among the rows' medians, else 0.0 (rows without used samples carry no weight)."""
    n_rows, n_cols = shape
    full = np.full(n_rows * n_cols, np.inf)
    at = index[used]
    full[at] = r[used]
    srt = np.sort(full.reshape(shape), axis=1).ravel()  # unused (inf) last
    cnt = np.bincount(at // n_cols, minlength=n_rows)
    rows = np.flatnonzero(cnt)
    if rows.size < 3:
        return np.ones(r.size)
    c, base = cnt[rows], rows * n_cols
    med = 0.5 * (srt[base + (c - 1) // 2] + srt[base + c // 2])
    centre = _median(med)
    dev = np.abs(med - centre)
    spread = max(1.4826 * _median(dev), cfg.min_sigma)
    bad_rows = np.zeros(n_rows, dtype=bool)
    bad_rows[rows] = dev > cfg.group_k * spread
    return np.where(bad_rows[index // n_cols], 0.0, 1.0)


def _window(a: float, b: float, margin_dn: float, cfg: GainFitConfig) -> tuple[float, float]:
    """The x range whose model values stay ``margin`` clear of the clip levels in both frames."""
    sa = math.sqrt(a)
    mx, my = margin_dn / sa, margin_dn * sa
    low, high = cfg.clip_levels
    lo = max(low + mx, (low + my - b) / a)
    hi = min(high - mx, (high - my - b) / a)
    return lo, hi


def fit_gain_offset(
    x: NDArray[np.generic],
    y: NDArray[np.generic],
    *,
    mask: NDArray[np.bool_] | None = None,
    weights: NDArray[np.floating] | None = None,
    config: GainFitConfig | None = None,
) -> AffineFit:
    """Robust, clip-aware, symmetric fit of ``y = a x + b`` (see the module docstring).

    ``x``, ``y``: corresponding intensities of any equal shape (a 2-D shape groups the samples
    by row); samples at or beyond a clip level in either are left out. ``mask`` (same shape,
    True = usable): the caller's further exclusions (samples whose neighbourhood clips in either
    frame, or that lie outside either image).
    ``weights`` (same shape, >= 0): prior weights. Non-finite samples are dropped. Returns
    :class:`~amrvio.photometric.affine.AffineFit` (``n_used``: samples with non-zero final
    weight; ``rms_residual``: of those, in DN of ``y``; ``x_median``: their median ``x``).
    """
    cfg = config or GainFitConfig()
    xf = np.asarray(x, dtype=np.float64).ravel()
    yf = np.asarray(y, dtype=np.float64).ravel()
    if np.shape(x) != np.shape(y):
        raise ShapeError(f"x and y must have the same shape, got {np.shape(x)} and {np.shape(y)}")
    keep = np.isfinite(xf) & np.isfinite(yf)
    low, high = cfg.clip_levels
    keep &= (xf > low) & (xf < high) & (yf > low) & (yf < high)  # clipped in either
    if mask is not None:
        if np.shape(mask) != np.shape(x):
            raise ShapeError(f"mask shape {np.shape(mask)} differs from x shape {np.shape(x)}")
        keep &= np.asarray(mask, dtype=bool).ravel()
    prior = np.ones_like(xf)
    if weights is not None:
        if np.shape(weights) != np.shape(x):
            raise ShapeError(f"weights shape {np.shape(weights)} differs from x shape {np.shape(x)}")
        prior = np.asarray(weights, dtype=np.float64).ravel()
        keep &= np.isfinite(prior) & (prior > 0)
    n_total = int(xf.size)
    shape2d = (int(np.shape(x)[0]), int(np.shape(x)[1])) if np.ndim(x) == 2 else None
    index = np.flatnonzero(keep)
    xs, ys, ps = xf[keep], yf[keep], prior[keep]
    n_min = max(cfg.min_samples, 3)

    def failed(status: AffineStatus, n: int, it: int = 0) -> AffineFit:
        return AffineFit(1.0, 0.0, status, n, n_total, float("nan"), it)

    if xs.size < n_min:
        return failed(AffineStatus.TOO_FEW_SAMPLES, int(xs.size))
    smp = _Samples.of(xs, ys)
    start = _line(smp, ps, cfg.fit_offset)
    if start is None:
        return failed(AffineStatus.NO_CONTRAST, int(xs.size))
    a, b, rho = start
    w = ps
    inside = np.ones(xs.size, dtype=bool)
    r, absr, rw, z = (np.empty(xs.size) for _ in range(4))
    it = 0
    for it in range(1, cfg.max_iterations + 1):
        np.multiply(xs, a, out=z)  # a x
        np.subtract(z, ys, out=r)
        r += b
        r *= 1.0 / math.sqrt(a)  # the symmetric residual
        np.abs(r, out=absr)
        sigma = max(1.4826 * _median(absr[inside]), cfg.min_sigma)
        if it <= cfg.huber_iterations:
            c = cfg.huber_k * sigma
            np.maximum(absr, c, out=rw)
            np.divide(c, rw, out=rw)  # Huber: 1 inside c, c / |r| beyond
        else:
            if shape2d is not None and it == cfg.huber_iterations + 1:
                ps = ps * _group_inliers(r, index, inside & (w > 0), shape2d, cfg)
            np.multiply(absr, 1.0 / (cfg.tukey_k * sigma), out=rw)
            np.minimum(rw, 1.0, out=rw)
            np.multiply(rw, rw, out=rw)
            np.subtract(1.0, rw, out=rw)
            np.multiply(rw, rw, out=rw)  # Tukey's biweight
        lo, hi = _window(a, b, cfg.margin * sigma, cfg)
        z += ys  # = 2 a t_hat + b, t_hat the position along the line in units of x
        z -= a * (lo + hi) + b
        np.abs(z, out=z)
        inside = z <= a * (hi - lo)
        w = rw * ps
        w *= inside
        n_w = int(np.count_nonzero(w))
        if n_w < n_min:  # an empty window: the spread swamps the range
            status = AffineStatus.UNCORRELATED if rho < cfg.min_correlation else (
                AffineStatus.TOO_FEW_SAMPLES)
            return failed(status, n_w, it)
        new = _line(smp, w, cfg.fit_offset)
        if new is None:
            return failed(AffineStatus.NO_CONTRAST, n_w, it)
        da, db = new[0] - a, new[1] - b
        a, b, rho = new
        if it > cfg.huber_iterations and abs(da) < cfg.tol * a and abs(db) < cfg.tol * 255.0:
            break
    used = w > 0
    if rho < cfg.min_correlation:
        return failed(AffineStatus.UNCORRELATED, int(used.sum()), it)
    res = (a * xs + b - ys)[used]
    return AffineFit(a, b, AffineStatus.OK, int(used.sum()), n_total,
                     float(np.sqrt(np.mean(res * res))), it, _median(xs[used]))


__all__ = ["GainFitConfig", "fit_gain_offset"]
