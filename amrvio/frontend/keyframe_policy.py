"""Keyframe policy of the monocular VO: time since the last keyframe, the share of its map
points still tracked, and the parallax of the common tracks (pure decision, no state)."""

from __future__ import annotations

from dataclasses import dataclass
from enum import Enum

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


class KeyframeReason(Enum):
    """Why a keyframe is made (or NONE)."""

    NONE = "none"
    MAX_GAP = "max_gap"
    TRACK_RATIO = "track_ratio"
    FEW_COMMON = "few_common"
    PARALLAX = "parallax"
    RELOCALISED = "relocalised"  # found again in the map after a loss


@dataclass(frozen=True, slots=True)
class KeyframePolicyConfig:
    """``max_gap`` frames at most between keyframes; a new one when fewer than
    ``min_track_ratio`` of the last keyframe's map points are PnP inliers, when fewer than
    ``min_common`` tracks are shared, or when their median parallax exceeds ``parallax_px``."""

    max_gap: int = 6
    min_track_ratio: float = 0.8
    parallax_px: float = 25.0
    min_common: int = 20


def keyframe_decision(config: KeyframePolicyConfig, frames_since_kf: int, n_inliers: int,
                      n_kf_points: int, kf_ids: I64, kf_uv: F64, ids: I64,
                      uv: F64) -> KeyframeReason:
    """Decide for the current frame. ``kf_ids`` (M,) / ``kf_uv`` (M, 2): tracks of the last
    keyframe; ``ids`` (N,) / ``uv`` (N, 2): current tracks (both sorted by id);
    ``n_kf_points``: how many of the keyframe's tracks have a map point."""
    if kf_uv.shape != (len(kf_ids), 2) or uv.shape != (len(ids), 2):
        raise ShapeError("keyframe_decision: uv arrays must be (N, 2) matching their ids")
    if frames_since_kf >= config.max_gap:
        return KeyframeReason.MAX_GAP
    if n_inliers < config.min_track_ratio * n_kf_points:
        return KeyframeReason.TRACK_RATIO
    common, ia, ib = np.intersect1d(kf_ids, ids, return_indices=True)
    if len(common) < config.min_common:
        return KeyframeReason.FEW_COMMON
    par = float(np.median(np.linalg.norm(kf_uv[ia] - uv[ib], axis=1)))
    return KeyframeReason.PARALLAX if par > config.parallax_px else KeyframeReason.NONE


__all__ = ["KeyframePolicyConfig", "KeyframeReason", "keyframe_decision"]
