"""Keyframe policy (each reason, closed cases) and anchor re-tracking (known image shift)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from skimage import data as skdata

from amrvio.errors import ShapeError
from amrvio.frontend.anchor import AnchorConfig, AnchorImage, retrack_from_anchors
from amrvio.frontend.keyframe_policy import (
    KeyframePolicyConfig,
    KeyframeReason,
    keyframe_decision,
)

CFG = KeyframePolicyConfig(max_gap=6, min_track_ratio=0.8, parallax_px=25.0, min_common=20)


def _grid(n: int) -> np.ndarray:
    g = np.arange(n, dtype=np.float64)
    return np.column_stack([10 + 7 * (g % 10), 10 + 7 * (g // 10)])


def test_keyframe_reasons() -> None:
    ids = np.arange(100, dtype=np.int64)
    uv = _grid(100)
    assert keyframe_decision(CFG, 2, 90, 100, ids, uv, ids, uv + 5) is KeyframeReason.NONE
    assert keyframe_decision(CFG, 6, 90, 100, ids, uv, ids, uv) is KeyframeReason.MAX_GAP
    assert keyframe_decision(CFG, 2, 79, 100, ids, uv, ids, uv) is KeyframeReason.TRACK_RATIO
    few = ids[:19]
    assert (keyframe_decision(CFG, 2, 90, 100, ids, uv, few, uv[:19])
            is KeyframeReason.FEW_COMMON)
    # median parallax 30 px > 25 px, measured on the common tracks only
    assert (keyframe_decision(CFG, 2, 90, 100, ids, uv, ids[50:], uv[50:] + [18.0, 24.0])
            is KeyframeReason.PARALLAX)


def test_keyframe_decision_rejects_wrong_shapes() -> None:
    ids = np.arange(5, dtype=np.int64)
    with pytest.raises(ShapeError):
        keyframe_decision(CFG, 0, 5, 5, ids, np.zeros((4, 2)), ids, np.zeros((5, 2)))


def _texture() -> np.ndarray:
    return cv2.GaussianBlur(np.asarray(skdata.brick(), dtype=np.uint8), (0, 0), 1.2)


def test_anchor_retracking_removes_drift_and_drops_disagreeing_tracks() -> None:
    tex = _texture()
    shift = np.array([3.25, -1.5])  # the current image is the anchor moved by this (px)
    M = np.array([[1.0, 0, shift[0]], [0, 1.0, shift[1]]])
    h, w = tex.shape
    ref = tex
    cur = np.clip(1.3 * cv2.warpAffine(tex, M, (w, h), flags=cv2.INTER_CUBIC) - 10.0, 0,
                  255).astype(np.uint8)  # with a brightness change
    corners = cv2.goodFeaturesToTrack(ref, 200, 0.01, 12, blockSize=5).reshape(-1, 2)
    inside = np.all((corners > 40) & (corners < np.array([w, h]) - 40), axis=1)
    first_uv = corners[inside].astype(np.float64)
    n = len(first_uv)
    truth = first_uv + shift
    rng = np.random.default_rng(0)
    drifted = truth + rng.uniform(-0.6, 0.6, (n, 2))  # accumulated frame-to-frame drift
    drifted[:5] += 6.0  # five tracks that slid onto another corner
    first_kf = np.zeros(n, dtype=np.int64)
    first_kf[-3:] = -1  # no anchor yet: left alone
    pts, drop = retrack_from_anchors(cur, drifted, first_kf, first_uv,
                                     {0: AnchorImage.of(ref)}, AnchorConfig())
    keep = ~drop & (first_kf >= 0)
    assert drop[:5].all() and int(drop.sum()) <= 7
    err = np.linalg.norm(pts[keep] - truth[keep], axis=1)
    assert np.median(err) < 0.05 and err.max() < 0.3
    assert np.array_equal(pts[-3:], drifted[-3:])


def test_anchor_retracking_rejects_wrong_shapes() -> None:
    img = np.zeros((50, 60), dtype=np.uint8)
    with pytest.raises(ShapeError):
        retrack_from_anchors(img, np.zeros((3, 2)), np.zeros(2, dtype=np.int64),
                             np.zeros((3, 2)), {}, AnchorConfig())
