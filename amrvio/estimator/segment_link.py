"""Linking a new map segment to the one it replaced, through the points both maps hold.

Track ids are global: a track that survived the loss of tracking has a point in the old map and,
once the new map is initialised with it, a point in the new one. The similarity between the two
maps (scale, rotation, translation) follows from those 3-D/3-D pairs (Umeyama inside RANSAC), so
the new segment continues at the old one's scale instead of a guessed one.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.estimator.vo_map import VoMap
from amrvio.geometry.align import umeyama
from amrvio.types.lie import Sim3

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class LinkConfig:
    """``min_common``: shared points needed; ``min_inlier_ratio``: share of them the similarity
    must explain within ``rel_thresh`` times their median spread; ``iterations``: RANSAC draws."""

    min_common: int = 12
    min_inlier_ratio: float = 0.5
    rel_thresh: float = 0.1
    iterations: int = 100


@dataclass(frozen=True, slots=True)
class SegmentLink:
    """``old_from_new`` (None when the maps could not be linked), the shared points and the
    inliers of the similarity."""

    old_from_new: Sim3 | None
    n_common: int
    n_inliers: int


def link_segments(new_map: VoMap, old_map: VoMap, config: LinkConfig, seed: int) -> SegmentLink:
    """The similarity taking ``new_map`` coordinates to ``old_map`` ones, from their shared points."""
    ids, Y = new_map.all_points()
    common = old_map.points_of(ids)
    n = int(common.sum())
    if n < config.min_common:
        return SegmentLink(None, n, 0)
    X = old_map.xyz[ids[common]]
    Y = Y[common]
    spread = float(np.median(np.linalg.norm(X - np.median(X, axis=0), axis=1)))
    tau = config.rel_thresh * spread
    rng = np.random.default_rng(seed)
    best = np.zeros(n, dtype=bool)
    for _ in range(config.iterations):
        pick = rng.choice(n, 3, replace=False)
        try:
            S = umeyama(Y[pick], X[pick], with_scale=True)
        except ShapeError:  # collinear draw
            continue
        inl = np.linalg.norm(S.act(Y) - X, axis=1) < tau
        if inl.sum() > best.sum():
            best = inl
    if best.sum() < max(config.min_common, config.min_inlier_ratio * n):
        return SegmentLink(None, n, int(best.sum()))
    try:
        S = umeyama(Y[best], X[best], with_scale=True)
    except ShapeError:
        return SegmentLink(None, n, int(best.sum()))
    return SegmentLink(S, n, int(best.sum()))


__all__ = ["LinkConfig", "SegmentLink", "link_segments"]
