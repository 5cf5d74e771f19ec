"""amrvio.tracking: detector (mask, buckets, exclusion) and pyramidal LK (brightness invariance,
forward-backward and epipolar checks) against known shifts and injected outliers."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data as skdata

from amrvio.errors import ShapeError
from amrvio.tracking.brightness import AffineBrightness, Invariance, normalise_for_tracking
from amrvio.tracking.detect import DetectorConfig, detect_corners
from amrvio.tracking.lk import EpipolarConfig, LkConfig, LkTracker

W, H = 480, 320


def _img() -> np.ndarray:
    g = np.asarray(skdata.grass(), dtype=np.uint8)
    g = cv2.resize(g, (W, H), interpolation=cv2.INTER_AREA)
    # keep away from saturation so that the affine change stays affine
    return (40 + 0.6 * cv2.GaussianBlur(g, (0, 0), 1.0)).astype(np.uint8)


def _shift(img: np.ndarray, dx: float, dy: float) -> np.ndarray:
    M = np.array([[1.0, 0, dx], [0, 1.0, dy]])
    return cv2.warpAffine(img, M, (img.shape[1], img.shape[0]), flags=cv2.INTER_LINEAR,
                          borderMode=cv2.BORDER_REFLECT)


def _interior(pts: np.ndarray, m: float = 25.0) -> np.ndarray:
    keep = (pts[:, 0] > m) & (pts[:, 0] < W - m) & (pts[:, 1] > m) & (pts[:, 1] < H - m)
    return pts[keep]


# ---- detector ---------------------------------------------------------------------------------

def test_detector_respects_the_mask() -> None:
    img = _img()
    mask = np.zeros((H, W), np.uint8)
    mask[:, : W // 2] = 255  # left half only
    pts = detect_corners(img, DetectorConfig(max_corners=200, min_distance_px=6), mask=mask)
    assert len(pts) >= 100
    assert pts[:, 0].max() < W // 2
    with pytest.raises(ShapeError):
        detect_corners(img, DetectorConfig(), mask=np.zeros((10, 10), np.uint8))


def test_detector_border_and_exclusion_distance() -> None:
    img = _img()
    cfg = DetectorConfig(max_corners=300, min_distance_px=9, border_px=15)
    first = detect_corners(img, cfg)
    assert len(first) >= 200
    assert first.min() >= 15 and first[:, 0].max() < W - 15 and first[:, 1].max() < H - 15
    d_self = np.linalg.norm(first[:, None] - first[None], axis=2) + 1e9 * np.eye(len(first))
    assert d_self.min() >= 9.0 - 1e-9  # corners keep min_distance_px between themselves
    more = detect_corners(img, cfg, n_wanted=150, existing_px=first)
    assert 0 < len(more) <= 150
    d = np.linalg.norm(more[:, None] - first[None], axis=2).min(axis=1)
    assert d.min() > 9.0 - 1.0  # the exclusion disc is drawn on rounded pixel positions


def test_detector_buckets_fill_every_cell_and_respect_the_cap() -> None:
    img = _img()
    cfg = DetectorConfig(max_corners=240, min_distance_px=5, grid_rows=4, grid_cols=6)
    pts = detect_corners(img, cfg)
    cells = (np.minimum(pts[:, 1] * 4 // H, 3) * 6 + np.minimum(pts[:, 0] * 6 // W, 5)).astype(int)
    counts = np.bincount(cells, minlength=24)
    assert counts.min() > 0
    assert counts.max() <= int(np.ceil(240 / 24)) + 1  # per-cell cap
    # without buckets the strongest corners crowd into the most textured cells
    free = detect_corners(img, DetectorConfig(max_corners=240, min_distance_px=5))
    free_cells = (np.minimum(free[:, 1] * 4 // H, 3) * 6 + np.minimum(free[:, 0] * 6 // W, 5)).astype(int)
    assert np.bincount(free_cells, minlength=24).max() > counts.max()
    # existing points fill their cell first: a full cell gets nothing new
    full = np.column_stack([np.linspace(5, W / 6 - 5, 11), np.full(11, 10.0)])  # cell 0
    new = detect_corners(img, cfg, n_wanted=100, existing_px=full)
    new_cells = (np.minimum(new[:, 1] * 4 // H, 3) * 6 + np.minimum(new[:, 0] * 6 // W, 5)).astype(int)
    assert not np.any(new_cells == 0)


def test_detector_empty_and_flat_images() -> None:
    assert detect_corners(_img(), DetectorConfig(), n_wanted=0).shape == (0, 2)
    assert detect_corners(np.full((64, 64), 90, np.uint8), DetectorConfig()).shape == (0, 2)
    with pytest.raises(ShapeError):
        detect_corners(np.zeros((64, 64), np.float32), DetectorConfig())


# ---- tracker ----------------------------------------------------------------------------------

def _lk(mode: Invariance, **kw: object) -> LkTracker:
    return LkTracker(LkConfig(invariance=mode, epipolar=None, **kw))  # type: ignore[arg-type]


@pytest.mark.parametrize("mode", [Invariance.AFFINE, Invariance.NORMALISE])
@pytest.mark.parametrize("gain,offset", [(1.0, 0.0), (1.6, -30.0), (0.6, 20.0)])
def test_subpixel_shift_under_gain_and_offset(mode: Invariance, gain: float, offset: float) -> None:
    img0 = _img()
    dx, dy = 3.37, -2.61
    img1 = AffineBrightness(gain, offset).apply(_shift(img0, dx, dy))
    pts = _interior(detect_corners(img0, DetectorConfig(max_corners=300, min_distance_px=8)))
    res = _lk(mode).track(img0, img1, pts)
    assert res.ok.mean() > 0.9
    flow = res.pts[res.ok] - pts[res.ok]
    assert np.abs(np.median(flow, axis=0) - [dx, dy]).max() < 0.05
    assert np.median(np.linalg.norm(flow - [dx, dy], axis=1)) < 0.05
    if mode is Invariance.AFFINE:
        assert res.brightness.a == pytest.approx(gain, rel=0.05)
    else:
        assert res.brightness == AffineBrightness()


def test_no_invariance_fails_under_a_strong_gain_change() -> None:
    img0 = _img()
    dx, dy = 3.37, -2.61
    img1 = AffineBrightness(1.8, -40.0).apply(_shift(img0, dx, dy))
    pts = _interior(detect_corners(img0, DetectorConfig(max_corners=300, min_distance_px=8)))

    def good(mode: Invariance) -> float:
        res = _lk(mode, max_error=None).track(img0, img1, pts)
        err = np.linalg.norm(res.pts - (pts + [dx, dy]), axis=1)
        return float(np.mean(res.ok & (err < 0.05)))

    assert good(Invariance.AFFINE) > 0.9 and good(Invariance.NORMALISE) > 0.9
    assert good(Invariance.NONE) < 0.5 * good(Invariance.AFFINE)


def test_predicted_positions_reach_a_large_shift() -> None:
    img0 = _img()
    dx, dy = 40.3, -25.7  # beyond what 1 pyramid level and a 21 px window can find
    img1 = _shift(img0, dx, dy)
    pts = _interior(detect_corners(img0, DetectorConfig(max_corners=300, min_distance_px=8)), 60)
    lk = _lk(Invariance.NONE, pyr_levels=1)
    blind = lk.track(img0, img1, pts)
    guided = lk.track(img0, img1, pts, pts_pred=pts + [dx + 1.5, dy - 1.0])
    err_g = np.linalg.norm(guided.pts - (pts + [dx, dy]), axis=1)
    assert np.mean(guided.ok & (err_g < 0.05)) > 0.9
    err_b = np.linalg.norm(blind.pts - (pts + [dx, dy]), axis=1)
    assert np.mean(blind.ok & (err_b < 0.05)) < 0.2


def test_forward_backward_check_rejects_occluded_points() -> None:
    img0 = _img()
    img1 = _shift(img0, 2.2, 1.4)
    rng = np.random.default_rng(3)
    img1[100:220, 150:330] = rng.integers(0, 255, (120, 180), dtype=np.uint8)  # occluder
    pts = _interior(detect_corners(img0, DetectorConfig(max_corners=300, min_distance_px=8)))
    occluded = (pts[:, 0] > 160) & (pts[:, 0] < 320) & (pts[:, 1] > 110) & (pts[:, 1] < 210)
    assert occluded.sum() >= 10
    with_fb = _lk(Invariance.NONE, fb_thresh_px=0.5).track(img0, img1, pts)
    assert with_fb.ok[occluded].mean() < 0.2 and with_fb.ok[~occluded].mean() > 0.8
    assert with_fb.n_fb_rejected >= 1
    no_fb = _lk(Invariance.NONE, fb_thresh_px=None).track(img0, img1, pts)
    assert no_fb.n_fb_rejected == 0 and no_fb.ok[occluded].mean() > with_fb.ok[occluded].mean()
    # the backward pass's own pyramid: as deep as the forward pass, the same result; at full
    # resolution only it is cheaper but lets more occluded points through (why the VO keeps
    # the full depth), and the positions stay those of the forward pass
    same = _lk(Invariance.NONE, fb_thresh_px=0.5, fb_pyr_levels=3).track(img0, img1, pts)
    assert np.array_equal(same.ok, with_fb.ok) and np.array_equal(same.pts, with_fb.pts)
    fine = _lk(Invariance.NONE, fb_thresh_px=0.5, fb_pyr_levels=0).track(img0, img1, pts)
    assert fine.ok[occluded].mean() > with_fb.ok[occluded].mean()
    assert fine.ok[~occluded].mean() > 0.8 and np.array_equal(fine.pts, with_fb.pts)


def _scene_pair() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two views of random 3-D points: K, and their (N, 2) projections before/after a move."""
    rng = np.random.default_rng(7)
    K = np.array([[400.0, 0, 240], [0, 400.0, 160], [0, 0, 1]])
    X = np.column_stack([rng.uniform(-3, 3, 200), rng.uniform(-2, 2, 200), rng.uniform(4, 12, 200)])
    R = cv2.Rodrigues(np.array([0.02, -0.05, 0.01]))[0]
    t = np.array([0.4, 0.05, 0.1])
    x0 = (X / X[:, 2:]) @ K.T
    Xc = X @ R.T + t
    x1 = (Xc / Xc[:, 2:]) @ K.T
    return K, x0[:, :2], x1[:, :2]


def test_epipolar_check_removes_injected_outliers() -> None:
    """Image pair: a random-dot texture warped so that each dot moves by its true 3-D flow,
    except 20 dots pasted at wrong places (flow-consistent but geometrically wrong)."""
    K, x0, x1 = _scene_pair()
    n = len(x0)
    rng = np.random.default_rng(11)
    bad = rng.choice(n, 20, replace=False)
    x1_obs = x1.copy()
    x1_obs[bad] += rng.uniform(8, 15, (20, 2)) * rng.choice([-1, 1], (20, 2))
    img0 = np.full((H, W), 60, np.uint8)
    img1 = np.full((H, W), 60, np.uint8)
    patch = rng.integers(90, 230, (n, 9, 9)).astype(np.uint8)
    patch = np.stack([cv2.GaussianBlur(p, (3, 3), 0.8) for p in patch])
    for img, pts in ((img0, x0), (img1, x1_obs)):
        for p, (u, v) in zip(patch, pts, strict=True):
            ui, vi = int(round(u)), int(round(v))
            if 6 <= ui < W - 6 and 6 <= vi < H - 6:
                img[vi - 4 : vi + 5, ui - 4 : ui + 5] = p
    inside = np.all((x0 > 8) & (x0 < [W - 8, H - 8]) & (x1_obs > 8) & (x1_obs < [W - 8, H - 8]), axis=1)
    # track exactly the patch centres (rounded, as pasted), predicted at their true positions
    p0 = np.round(x0[inside])
    pred = np.round(x1_obs[inside])
    is_bad = np.isin(np.flatnonzero(inside), bad)
    assert is_bad.sum() >= 10
    cfg = LkConfig(invariance=Invariance.NONE, win_size=9, pyr_levels=0,
                   epipolar=EpipolarConfig(thresh_px=1.0))
    res = LkTracker(cfg).track(img0, img1, p0, pts_pred=pred, K=K)
    res_off = LkTracker(LkConfig(invariance=Invariance.NONE, win_size=9, pyr_levels=0,
                                 epipolar=None)).track(img0, img1, p0, pts_pred=pred)
    assert res_off.ok[is_bad].mean() > 0.8  # tracking alone keeps the outliers
    assert res.ok[is_bad].mean() < 0.2
    assert res.ok[~is_bad].mean() > 0.8
    assert res.n_epi_rejected >= int(0.8 * is_bad.sum())


def test_wide_images_are_tracked_on_a_reduced_level_in_full_resolution_pixels() -> None:
    big = cv2.resize(_img(), (2 * W, 2 * H), interpolation=cv2.INTER_CUBIC)
    dx, dy = 4.6, -3.0
    img1 = AffineBrightness(1.4, -10.0).apply(_shift(big, dx, dy))
    lk = LkTracker(LkConfig(invariance=Invariance.NORMALISE, epipolar=None, max_width_px=W))
    t0, t1 = lk.prepare(big), lk.prepare(img1)
    assert t0.levels == 1 and t0.lk.shape == (H, W)
    assert np.array_equal(t0.lk, cv2.pyrDown(normalise_for_tracking(big)))
    pts = detect_corners(t0.lk, DetectorConfig(max_corners=200, min_distance_px=8)) * t0.scale
    pts = pts[(pts[:, 0] > 50) & (pts[:, 0] < 2 * W - 50) & (pts[:, 1] > 50) & (pts[:, 1] < 2 * H - 50)]
    res = lk.track(t0, t1, pts)
    assert res.ok.mean() > 0.9
    assert np.abs(np.median(res.pts[res.ok] - pts[res.ok], axis=0) - [dx, dy]).max() < 0.1


def test_tracker_bad_and_empty_input() -> None:
    img = _img()
    lk = LkTracker()
    res = lk.track(img, img, np.zeros((0, 2)))
    assert res.pts.shape == (0, 2) and res.ok.shape == (0,)
    with pytest.raises(ShapeError):
        lk.track(img, img, np.zeros((5, 3)))
    with pytest.raises(ShapeError):
        lk.track(img, img[:100], np.zeros((5, 2)))
    with pytest.raises(ShapeError):
        lk.track(img, img, np.zeros((5, 2)), pts_pred=np.zeros((4, 2)))
    with pytest.raises(ShapeError):
        lk.prepare(img.astype(np.float32))


def test_tracking_is_deterministic() -> None:
    img0 = _img()
    img1 = _shift(img0, 5.5, 2.5)
    pts = detect_corners(img0, DetectorConfig(max_corners=300, min_distance_px=8, grid_rows=3,
                                              grid_cols=4))
    a = LkTracker().track(img0, img1, pts)
    b = LkTracker().track(img0, img1, pts)
    assert np.array_equal(a.pts, b.pts) and np.array_equal(a.ok, b.ok)


def test_image_quantiles_equal_numpy_percentile() -> None:
    """The histogram read-off gives np.percentile's values exactly (uint8 images of any size,
    stride and intensity spread)."""
    from amrvio.tracking.brightness import QUANTILES, image_quantiles

    rng = np.random.default_rng(4)
    for k in range(300):
        h, w = (int(v) for v in rng.integers(1, 200, 2))
        if k % 3 == 0:
            img = rng.integers(0, 256, (h, w), dtype=np.uint8)
        elif k % 3 == 1:
            img = np.full((h, w), int(rng.integers(0, 256)), dtype=np.uint8)
        else:
            img = np.clip(rng.normal(rng.uniform(0, 255), rng.uniform(0, 40), (h, w)), 0,
                          255).astype(np.uint8)
        stride = int(rng.integers(1, 6))
        assert np.array_equal(image_quantiles(img, stride),
                              np.percentile(img[::stride, ::stride], QUANTILES))


def test_brightness_memo_follows_a_refilled_buffer() -> None:
    """A caller that refills one image buffer gets the brightness change of the new content,
    as a fresh tracker computes it."""
    img = _img()
    pts = detect_corners(img, DetectorConfig(max_corners=80, border_px=30))
    buf = img.copy()
    tr = LkTracker(LkConfig(epipolar=None))
    tr.track(buf, img, pts)
    buf[:] = np.clip(1.4 * img.astype(np.float64) + 10, 0, 255).astype(np.uint8)  # same array
    memo = tr.track(buf, img, pts)
    fresh = LkTracker(LkConfig(epipolar=None)).track(buf.copy(), img, pts)
    assert memo.brightness == fresh.brightness
    assert not memo.brightness.is_identity()
    assert np.array_equal(memo.pts, fresh.pts)
