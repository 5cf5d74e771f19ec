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
from numba import njit
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


_STATUS = (AffineStatus.OK, AffineStatus.TOO_FEW_SAMPLES, AffineStatus.NO_CONTRAST,
           AffineStatus.UNCORRELATED)  # the kernel's status codes


@njit(cache=True, nogil=True)
def _select(v: F64, k: int) -> float:
    """The ``k``-th smallest entry of ``v``, which is reordered in place (Hoare's quickselect,
    median-of-three pivots)."""
    lo, hi = 0, v.size - 1
    while hi > lo:
        p0, p1, p2 = v[lo], v[(lo + hi) // 2], v[hi]
        pivot = max(min(p0, p1), min(max(p0, p1), p2))
        i, j = lo, hi
        while i <= j:
            while v[i] < pivot:
                i += 1
            while v[j] > pivot:
                j -= 1
            if i <= j:
                v[i], v[j] = v[j], v[i]
                i += 1
                j -= 1
        if k <= j:
            hi = j
        elif k >= i:
            lo = i
        else:
            break
    return float(v[k])


@njit(cache=True, nogil=True)
def _upper_median(v: F64) -> float:
    """The upper median of a non-empty vector (left as it is)."""
    return _select(v.copy(), v.size // 2)


@njit(cache=True, nogil=True)
def _insertion_sort(v: F64, n: int) -> None:
    """Sort ``v[:n]`` in place (the few samples of one patch)."""
    for i in range(1, n):
        t, j = v[i], i - 1
        while j >= 0 and v[j] > t:
            v[j + 1] = v[j]
            j -= 1
        v[j + 1] = t


@njit(cache=True, nogil=True)
def _rma(s: float, sx: float, sy: float, sxx: float, syy: float, sxy: float, fit_offset: bool
         ) -> tuple[bool, float, float, float]:
    """Reduced-major-axis line (ok, a, b, weighted correlation) from the weighted sums of
    ``1, x, y, xx, yy, xy``."""
    if not fit_offset:  # through the origin: a = sqrt(Syy / Sxx) about 0
        if not (sxx > 0 and syy > 0 and sxy > 0):
            return False, 1.0, 0.0, 0.0
        return True, math.sqrt(syy / sxx), 0.0, sxy / math.sqrt(sxx * syy)
    if not s > 0:
        return False, 1.0, 0.0, 0.0
    mx, my = sx / s, sy / s
    vxx, vyy, vxy = sxx / s - mx * mx, syy / s - my * my, sxy / s - mx * my
    if not (vxx > 1e-9 and vyy > 1e-9) or vxy <= 0:
        return False, 1.0, 0.0, 0.0
    a = math.sqrt(vyy / vxx)
    return True, a, my - a * mx, vxy / math.sqrt(vxx * vyy)


@njit(cache=True, nogil=True)
def _group_inliers(r: F64, row: NDArray[np.intp], used: NDArray[np.bool_], group_k: float,
                   min_sigma: float) -> F64:
    """1.0 for the samples of rows (``row``: each sample's row, non-decreasing) whose median
    residual over their used samples is not an outlier among the rows' medians, else 0.0 (rows
    without used samples carry no weight in that judgement)."""
    n = r.size
    out = np.ones(n)
    starts = np.empty(n + 1, np.intp)  # runs of one row
    n_runs = 0
    for i in range(n):
        if i == 0 or row[i] != row[i - 1]:
            starts[n_runs] = i
            n_runs += 1
    starts[n_runs] = n
    med = np.empty(n_runs)
    has = np.zeros(n_runs, np.bool_)
    buf = np.empty(n)
    n_rows = 0
    for j in range(n_runs):
        c = 0
        for i in range(starts[j], starts[j + 1]):
            if used[i]:
                buf[c] = r[i]
                c += 1
        if c > 0:
            _insertion_sort(buf, c)
            med[j] = 0.5 * (buf[(c - 1) // 2] + buf[c // 2])
            has[j] = True
            n_rows += 1
    if n_rows < 3:
        return out
    meds = med[has]
    centre = _upper_median(meds)
    spread = max(1.4826 * _upper_median(np.abs(meds - centre)), min_sigma)
    for j in range(n_runs):
        if has[j] and abs(med[j] - centre) > group_k * spread:
            out[starts[j]:starts[j + 1]] = 0.0
    return out


@njit(cache=True, nogil=True)
def _sums(xs: F64, ys: F64, w: F64) -> tuple[int, float, float, float, float, float, float]:
    """The count of non-zero weights and the weighted sums of ``1, x, y, xx, yy, xy``."""
    n = 0
    s = sx = sy = sxx = syy = sxy = 0.0
    for i in range(xs.size):
        wi, xi, yi = w[i], xs[i], ys[i]
        if wi != 0.0:
            n += 1
            s += wi
            sx += wi * xi
            sy += wi * yi
            sxx += wi * xi * xi
            syy += wi * yi * yi
            sxy += wi * xi * yi
    return n, s, sx, sy, sxx, syy, sxy


@njit(cache=True, nogil=True)
def _window(a: float, b: float, margin_dn: float, low: float, high: float) -> tuple[float, float]:
    """The x range whose model values stay ``margin`` clear of the clip levels in both frames."""
    sa = math.sqrt(a)
    mx, my = margin_dn / sa, margin_dn * sa
    return max(low + mx, (low + my - b) / a), min(high - mx, (high - my - b) / a)


@njit(cache=True, nogil=True)
def _fit(xf: F64, yf: F64, keep_in: NDArray[np.bool_], prior: F64, n_cols: int, low: float,
         high: float, margin: float, huber_k: float, tukey_k: float, huber_iterations: int,
         max_iterations: int, min_sigma: float, min_samples: int, min_correlation: float,
         fit_offset: bool, tol: float, group_k: float
         ) -> tuple[int, float, float, int, float, int, float]:
    """The iteratively reweighted fit of :func:`fit_gain_offset` on flat samples (``n_cols`` > 0:
    rows of that many samples). Returns (status code of ``_STATUS``, a, b, n_used, rms residual,
    iterations, median x of the used samples)."""
    n = xf.size
    keep = np.empty(n, np.bool_)
    for i in range(n):
        xi, yi, pi = xf[i], yf[i], prior[i]
        keep[i] = (keep_in[i] and np.isfinite(xi) and np.isfinite(yi) and np.isfinite(pi)
                   and pi > 0 and low < xi < high and low < yi < high)  # clipped in either
    index = np.flatnonzero(keep)
    m = index.size
    xs, ys, ps = xf[index], yf[index], prior[index].copy()
    n_min = max(min_samples, 3)
    nan = np.nan
    if m < n_min:
        return 1, 1.0, 0.0, m, nan, 0, nan
    _, s0, sx, sy, sxx, syy, sxy = _sums(xs, ys, ps)
    ok, a, b, rho = _rma(s0, sx, sy, sxx, syy, sxy, fit_offset)
    if not ok:
        return 2, 1.0, 0.0, m, nan, 0, nan
    w = ps.copy()
    inside = np.ones(m, np.bool_)
    r, absr, buf = np.empty(m), np.empty(m), np.empty(m)
    it = 0
    for it in range(1, max_iterations + 1):
        inv_sa = 1.0 / math.sqrt(a)
        n_in = 0
        for i in range(m):
            r[i] = (a * xs[i] - ys[i] + b) * inv_sa  # the symmetric residual
            absr[i] = abs(r[i])
            if inside[i]:
                buf[n_in] = absr[i]
                n_in += 1
        sigma = max(1.4826 * _select(buf[:n_in], n_in // 2), min_sigma)
        huber = it <= huber_iterations
        if not huber and n_cols > 0 and it == huber_iterations + 1:
            ps *= _group_inliers(r, index // n_cols, inside & (w > 0), group_k, min_sigma)
        c, s_tukey = huber_k * sigma, 1.0 / (tukey_k * sigma)
        lo, hi = _window(a, b, margin * sigma, low, high)
        mid, half = a * (lo + hi) + b, a * (hi - lo)
        for i in range(m):
            # 2 a t_hat + b, t_hat the position along the line in units of x
            inside[i] = abs(a * xs[i] + ys[i] - mid) <= half
            w[i] = 0.0
            if inside[i]:
                if huber:
                    w[i] = c / max(absr[i], c) * ps[i]  # Huber: 1 inside c, c / |r| beyond
                else:
                    u = min(absr[i] * s_tukey, 1.0)
                    w[i] = (1.0 - u * u) ** 2 * ps[i]  # Tukey's biweight
        n_w, s0, sx, sy, sxx, syy, sxy = _sums(xs, ys, w)
        if n_w < n_min:  # an empty window: the spread swamps the range
            return (3 if rho < min_correlation else 1), 1.0, 0.0, n_w, nan, it, nan
        ok, a_new, b_new, rho = _rma(s0, sx, sy, sxx, syy, sxy, fit_offset)
        if not ok:
            return 2, 1.0, 0.0, n_w, nan, it, nan
        da, db = a_new - a, b_new - b
        a, b = a_new, b_new
        if it > huber_iterations and abs(da) < tol * a and abs(db) < tol * 255.0:
            break
    used = w > 0
    n_used = int(used.sum())
    if rho < min_correlation:
        return 3, 1.0, 0.0, n_used, nan, it, nan
    res = (a * xs + b - ys)[used]
    return 0, a, b, n_used, math.sqrt(np.mean(res * res)), it, _upper_median(xs[used])


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
    if np.shape(x) != np.shape(y):
        raise ShapeError(f"x and y must have the same shape, got {np.shape(x)} and {np.shape(y)}")
    for name, extra in (("mask", mask), ("weights", weights)):
        if extra is not None and np.shape(extra) != np.shape(x):
            raise ShapeError(f"{name} shape {np.shape(extra)} differs from x shape {np.shape(x)}")
    xf = np.ascontiguousarray(x, dtype=np.float64).ravel()
    yf = np.ascontiguousarray(y, dtype=np.float64).ravel()
    keep = (np.ones(xf.size, dtype=bool) if mask is None
            else np.ascontiguousarray(mask, dtype=bool).ravel())
    prior = (np.ones(xf.size) if weights is None
             else np.ascontiguousarray(weights, dtype=np.float64).ravel())
    n_cols = int(np.shape(x)[1]) if np.ndim(x) == 2 else 0
    low, high = cfg.clip_levels
    code, a, b, n_used, rms, it, x_med = _fit(
        xf, yf, keep, prior, n_cols, float(low), float(high), cfg.margin, cfg.huber_k,
        cfg.tukey_k, cfg.huber_iterations, cfg.max_iterations, cfg.min_sigma, cfg.min_samples,
        cfg.min_correlation, cfg.fit_offset, cfg.tol, cfg.group_k)
    return AffineFit(a, b, _STATUS[code], n_used, int(xf.size), rms, it, x_med)


__all__ = ["GainFitConfig", "fit_gain_offset"]
