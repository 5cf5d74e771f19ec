"""Clip-aware symmetric gain/offset fit (amrvio.photometric.gain) and the brightness-mapped
tracks of the diagnostics (amrvio.diagnostics.tracks)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from amrvio.diagnostics.tracks import (
    TrackingConfig,
    histogram_quantiles,
    map_brightness,
    prepare_track_frame,
    track_between,
)
from amrvio.errors import ShapeError
from amrvio.photometric.affine import AffineStatus, fit_affine_robust
from amrvio.photometric.gain import GainFitConfig, fit_gain_offset
from amrvio.tracking.brightness import QUANTILES, AffineBrightness
from amrvio.tracking.detect import detect_corners
from amrvio.tracking.lk import LkTracker


def _pairs(a: float, b: float, n: int = 20000, noise: float = 8.0, seed: int = 0,
           t_range: tuple[float, float] = (0.0, 255.0), lo: float = 0.0, hi: float = 255.0,
           ) -> tuple[np.ndarray, np.ndarray]:
    """True intensities t, observed x = clip(t + e0), y = clip(a t + b + a e1): noise in both
    frames in the ratio a (misregistration scales with the contrast), clipped at lo/hi."""
    rng = np.random.default_rng(seed)
    t = rng.uniform(t_range[0], t_range[1], n)
    x = np.clip(t + noise * rng.normal(size=n), lo, hi)
    y = np.clip(a * t + b + a * noise * rng.normal(size=n), lo, hi)
    return x, y


@pytest.mark.parametrize(("a", "b", "t_range", "noise"), [
    (1.5, -15.0, (0.0, 255.0), 8.0),  # a third of the samples clipped, both ends
    (2.83, -20.0, (0.0, 120.0), 4.0),  # +1.5 EV
    (0.35, 4.0, (100.0, 255.0), 8.0),  # -1.5 EV from a saturated frame
    (0.5, 3.0, (20.0, 255.0), 6.0),
])
def test_gain_fit_recovers_truth_under_clipping_and_noise_in_both(
        a: float, b: float, t_range: tuple[float, float], noise: float) -> None:
    x, y = _pairs(a, b, t_range=t_range, noise=noise)
    clipped = float(np.mean((x <= 5) | (x >= 250) | (y <= 5) | (y >= 250)))
    assert clipped > 0.02
    fit = fit_gain_offset(x, y)
    assert fit.ok
    assert fit.a == pytest.approx(a, rel=0.01)
    assert fit.b == pytest.approx(b, abs=1.0)


@pytest.mark.parametrize(("a", "b"), [(1.5, -15.0), (0.667, 10.0)])
def test_gain_fit_is_not_attenuated_by_noise_in_the_reference(a: float, b: float) -> None:
    """Misregistration perturbs both frames; over a 100 DN range with 8 DN of it the slope of
    y on x is attenuated by several per cent, the reduced major axis is not."""
    x, y = _pairs(a, b, t_range=(40.0, 140.0), noise=8.0)
    assert fit_gain_offset(x, y).a == pytest.approx(a, rel=0.01)
    assert fit_affine_robust(x, y).a < a * 0.97


def test_gain_fit_fails_as_data_when_the_noise_swamps_the_range() -> None:
    for noise in (15.0, 25.0):
        fit = fit_gain_offset(*_pairs(2.83, -20.0, t_range=(0.0, 120.0), noise=noise))
        assert not fit.ok and (fit.a, fit.b) == (1.0, 0.0)
        assert fit.status in (AffineStatus.UNCORRELATED, AffineStatus.TOO_FEW_SAMPLES)


def test_gain_fit_is_symmetric_in_the_two_frames() -> None:
    x, y = _pairs(1.7, -12.0, seed=3)
    f = fit_gain_offset(x, y)
    r = fit_gain_offset(y, x)
    assert r.a == pytest.approx(1.0 / f.a, rel=1e-6)
    assert r.b == pytest.approx(-f.b / f.a, abs=1e-4)


def test_gain_fit_ignores_gross_outliers_and_honours_mask_and_weights() -> None:
    x, y = _pairs(1.3, 5.0, seed=4, noise=2.0)
    rng = np.random.default_rng(5)
    idx = rng.choice(x.size, x.size // 5, replace=False)
    y2 = y.copy()
    y2[idx] = rng.uniform(0, 255, idx.size)  # 20 % occlusions / moving objects
    fit = fit_gain_offset(x, y2)
    assert fit.a == pytest.approx(1.3, rel=0.01)
    mask = np.ones(x.size, bool)
    mask[idx] = False
    assert fit_gain_offset(x, y2, mask=mask).a == pytest.approx(1.3, rel=0.005)
    w = mask.astype(float)
    assert fit_gain_offset(x, y2, weights=w).a == pytest.approx(
        fit_gain_offset(x, y2, mask=mask).a, rel=1e-9)


def test_gain_fit_through_origin_and_failures() -> None:
    x, y = _pairs(0.6, 0.0, seed=6)
    f = fit_gain_offset(x, y, config=GainFitConfig(fit_offset=False))
    assert f.a == pytest.approx(0.6, rel=0.01) and f.b == 0.0
    assert fit_gain_offset(np.ones(5), np.ones(5)).status is AffineStatus.TOO_FEW_SAMPLES
    assert fit_gain_offset(np.full(100, 80.0), np.full(100, 90.0)).status is AffineStatus.NO_CONTRAST
    rng = np.random.default_rng(7)
    unrelated = fit_gain_offset(rng.uniform(20, 230, 5000), rng.uniform(20, 230, 5000))
    assert unrelated.status is AffineStatus.UNCORRELATED and unrelated.a == 1.0
    nan = np.full(100, np.nan)
    assert fit_gain_offset(nan, nan).status is AffineStatus.TOO_FEW_SAMPLES
    with pytest.raises(ShapeError):
        fit_gain_offset(np.ones(3), np.ones(4))
    with pytest.raises(ShapeError):
        fit_gain_offset(np.ones(30), np.ones(30), mask=np.ones(29, bool))


def _scene(shape: tuple[int, int] = (240, 320), seed: int = 1) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = np.zeros(shape, np.float32)
    for s in (2, 4, 8, 16, 32):
        n = rng.normal(size=(shape[0] // s + 2, shape[1] // s + 2)).astype(np.float32)
        base += cv2.resize(n, (shape[1], shape[0]), interpolation=cv2.INTER_CUBIC)[: shape[0], : shape[1]]
    base = (base - base.min()) / (base.max() - base.min())
    return np.asarray(np.clip(10 + 235 * base, 0, 255), np.uint8)


def test_histogram_quantiles_match_numpy_percentiles() -> None:
    img = _scene()
    q = histogram_quantiles(img)
    ref = np.percentile(img, QUANTILES)
    assert q.shape == (19,)
    assert np.max(np.abs(q - ref)) < 1.0
    assert np.all(np.diff(q) >= 0)


def test_map_brightness_matches_the_tracking_lut() -> None:
    img = _scene()
    ch = AffineBrightness(1.5, -15.0)
    assert np.array_equal(map_brightness(img, ch), ch.apply(img))
    assert map_brightness(img, AffineBrightness()) is img


def test_tracks_survive_a_clipping_gain_step() -> None:
    """A 1.5x gain step with 20 % of the pixels saturated: the mapped reference keeps the tracks
    on the true shift, where LK on raw intensities loses them."""
    img = _scene((300, 400), seed=2)
    M = np.array([[1, 0, 3.4], [0, 1, -2.2]], dtype=np.float32)
    moved = cv2.warpAffine(img, M, (400, 300), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    hi = float(np.percentile(moved, 80))
    cur = np.clip(np.round(1.5 * moved.astype(np.float64) + (255.0 - 1.5 * hi)), 0, 255).astype(np.uint8)
    assert np.mean(cur >= 255) > 0.15
    cfg = TrackingConfig()
    tracker = LkTracker(cfg.lk)
    f0, f1 = prepare_track_frame(tracker, img), prepare_track_frame(tracker, cur)
    pts = detect_corners(f0.image.lk, cfg.detector)
    inner = (pts[:, 0] > 12) & (pts[:, 0] < 388) & (pts[:, 1] > 12) & (pts[:, 1] < 288)
    pts = pts[inner]
    res = track_between(tracker, f0, f1, pts)
    err = np.linalg.norm(res.pts - (pts + [3.4, -2.2]), axis=1)
    assert res.brightness.a == pytest.approx(1.5, rel=0.1)
    assert res.ok.mean() > 0.8 and np.median(err[res.ok]) < 0.15
    plain = tracker.track(f0.image, f1.image, pts)
    err_plain = np.linalg.norm(plain.pts - (pts + [3.4, -2.2]), axis=1)
    assert np.mean(plain.ok & (err_plain < 0.5)) < np.mean(res.ok & (err < 0.5)) - 0.2
