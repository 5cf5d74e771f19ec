"""The tracker's guided re-track: map-point tracks that KLT lost under a wrong motion prediction
are tracked again from their projections at the pose PnP found from the others.

The scene has two textured layers, far (20 m, top half) and near (2 m, bottom half); the camera
moves 0.4 m sideways while the motion model predicts no motion; half the far tracks and all
the near ones have a map point. The far points move 10 px and
KLT follows them from where they were; the near points move 100 px, beyond the reach of the
three-level pyramid without a prediction."""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from amrvio.estimator.vo_map import VoMap
from amrvio.frontend.tracker import Tracker, TrackingConfig
from amrvio.frontend.tracking_types import TrackOutcome

W, H, F = 640, 480, 500.0
K = np.array([[F, 0.0, W / 2], [0.0, F, H / 2], [0.0, 0.0, 1.0]])
Z_FAR, Z_NEAR, TX = 20.0, 2.0, 0.4


def _texture(seed: int, width: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    noise = rng.uniform(0, 255, size=(H // 2, width)).astype(np.float32)
    tex = cv2.GaussianBlur(noise, (0, 0), 2.0)
    tex = (tex - tex.min()) / (tex.max() - tex.min())
    return (30 + 190 * tex).astype(np.uint8)


def _images() -> tuple[np.ndarray, np.ndarray]:
    """The two views: each layer's texture, shifted by -F * TX / Z in the second."""
    far, near = _texture(1, W + 300), _texture(2, W + 300)
    x0 = 150  # texture column at image column 0 in the first view
    img0 = np.vstack([far[:, x0:x0 + W], near[:, x0:x0 + W]])
    d_far, d_near = round(F * TX / Z_FAR), round(F * TX / Z_NEAR)  # 10 and 100 px
    img1 = np.vstack([far[:, x0 + d_far:x0 + d_far + W], near[:, x0 + d_near:x0 + d_near + W]])
    return img0, img1


def _run(guided: bool) -> tuple[TrackOutcome, int, np.ndarray, int]:
    """(outcome, PnP inliers, camera position, near map points among the inliers)."""
    img0, img1 = _images()
    base = TrackingConfig()
    cfg = dataclasses.replace(base, klt=dataclasses.replace(base.klt, guided_retrack=guided))
    tracker = Tracker(K, cfg, seed=0)
    tracker.restart(img0, keep_tracks=False)
    tr = tracker.tracks  # moved into the second view by track()
    ids, u, v = tr.ids.copy(), tr.pts[:, 0].copy(), tr.pts[:, 1].copy()
    keep = np.abs(v - H / 2) > 15  # away from the layers' border (occlusion)
    keep &= (v >= H / 2) | (np.arange(len(ids)) % 2 == 0)  # half the far tracks have a point
    depth = np.where(v < H / 2, Z_FAR, Z_NEAR)
    xyz = np.column_stack([(u - K[0, 2]) / F, (v - K[1, 2]) / F, np.ones_like(u)]) * depth[:, None]
    m = VoMap()
    m.ensure_capacity(int(ids.max()) + 1)
    m.set_points(ids[keep], xyz[keep])
    tracker.adopt_map_pose(np.eye(4), np.eye(4))  # the motion model: no motion
    step = tracker.track(img1, False, m, 1.0)
    T_world_cam = np.linalg.inv(step.T_cam_world)
    near = 0
    if step.observations is not None:
        near_ids = set(ids[v >= H / 2].tolist())
        near = sum(i in near_ids for i in step.observations.ids.tolist())
    return step.report.outcome, step.report.n_inliers, T_world_cam[:3, 3], near


def test_the_near_layer_is_recovered_from_the_pose_of_the_far_one() -> None:
    outcome, n_inl, c, near = _run(guided=True)
    outcome_off, n_off, c_off, near_off = _run(guided=False)
    assert outcome is TrackOutcome.TRACKED and outcome_off is TrackOutcome.TRACKED
    # without the re-track PnP sees the far layer only; with it, the near layer comes back
    assert near_off <= 0.1 * n_off
    assert near >= 0.4 * n_inl
    assert n_inl >= 1.6 * n_off
    # the camera moved TX along x: the near layer's parallax pins it down
    assert np.linalg.norm(c - [TX, 0.0, 0.0]) < 0.01
    assert np.linalg.norm(c - [TX, 0.0, 0.0]) <= np.linalg.norm(c_off - [TX, 0.0, 0.0])
