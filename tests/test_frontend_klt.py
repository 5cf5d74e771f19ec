"""KLT front-end: bucketed detection, tracking through a known shift under an exposure step."""

from __future__ import annotations

from dataclasses import replace

import cv2
import numpy as np
import pytest
from skimage import data as skdata

from amrvio.frontend.klt import KltConfig, KltTracker, detect_bucketed
from amrvio.photometric.affine import fit_affine_robust
from amrvio.tracking.brightness import (
    AffineBrightness,
    fit_affine_quantiles,
)
from amrvio.tracking.detect import DetectorConfig


def _img() -> np.ndarray:
    g = np.asarray(skdata.grass(), dtype=np.uint8)
    g = cv2.resize(g, (480, 320), interpolation=cv2.INTER_AREA)
    # keep away from saturation so that the affine change stays affine
    return (40 + 0.6 * cv2.GaussianBlur(g, (0, 0), 1.0)).astype(np.uint8)


def _shift(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    M = np.array([[1.0, 0, dx], [0, 1.0, dy]])
    return cv2.warpAffine(img, M, (img.shape[1], img.shape[0]), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REFLECT)


def test_detect_bucketed_spreads_corners_and_respects_existing() -> None:
    img = _img()
    cfg = KltConfig(detector=DetectorConfig(max_corners=300, quality_level=0.001, min_distance_px=8,
                                             border_px=8, grid_rows=4, grid_cols=6))
    pts = detect_bucketed(img, np.zeros((0, 2)), 300, cfg)
    assert 200 <= len(pts) <= 300
    h, w = img.shape
    cells = (np.minimum(pts[:, 1] * 4 // h, 3) * 6 + np.minimum(pts[:, 0] * 6 // w, 5)).astype(int)
    counts = np.bincount(cells, minlength=24)
    assert counts.min() > 0  # every cell is populated
    more = detect_bucketed(img, pts, 100, cfg)
    d = np.linalg.norm(more[:, None, :] - pts[None, :, :], axis=2).min(axis=1)
    assert np.all(d >= 7.0)


@pytest.mark.parametrize("gain,offset", [(1.0, 0.0), (1.7, -35.0), (0.6, 20.0)])
def test_klt_tracks_known_shift_through_exposure_step(gain: float, offset: float) -> None:
    img0 = _img()
    dx, dy = 6.3, -4.2
    img1 = AffineBrightness(gain, offset).apply(_shift(img0, dx, dy))
    cfg = KltConfig(detector=replace(KltConfig().detector, max_corners=400))
    pts = detect_bucketed(img0, np.zeros((0, 2)), 400, cfg)
    pts = pts[(pts[:, 0] > 20) & (pts[:, 0] < 460) & (pts[:, 1] > 20) & (pts[:, 1] < 300)]
    res = KltTracker(cfg).track(img0, img1, pts)
    assert abs(res.brightness.a - gain) < 0.05 * gain
    assert res.ok.mean() > 0.9
    err = np.linalg.norm(res.pts[res.ok] - (pts[res.ok] + [dx, dy]), axis=1)
    assert np.median(err) < 0.05


def test_affine_fits_recover_gain_and_offset() -> None:
    img = _img()
    a, b = 1.4, -12.0
    img2 = AffineBrightness(a, b).apply(img)
    q = fit_affine_quantiles(img, img2)
    assert abs(q.a - a) < 0.02 and abs(q.b - b) < 2.0
    s = fit_affine_robust(img.ravel()[::7], img2.ravel()[::7])
    assert abs(s.a - a) < 0.01 and abs(s.b - b) < 1.0


def test_klt_empty_input() -> None:
    img = _img()
    res = KltTracker().track(img, img, np.zeros((0, 2)))
    assert len(res.pts) == 0 and len(res.ok) == 0
