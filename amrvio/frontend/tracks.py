"""The track set: the points followed from image to image, kept as one structure so that its
parallel arrays can only change together."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]

#: ``first_kf`` of a track that no keyframe has seen yet (only before the map exists).
UNANCHORED = -1


class TrackSet:
    """N tracks: ``ids`` (N,) unique and increasing, ``pts`` (N, 2) pixel positions in the last
    image, ``first_kf`` (N,) the keyframe where each track was first seen and ``first_uv`` (N, 2)
    its position there (the anchor for triangulation and re-tracking)."""

    def __init__(self) -> None:
        self.ids: I64 = np.zeros(0, dtype=np.int64)
        self.pts: F64 = np.zeros((0, 2))
        self.first_kf: I64 = np.zeros(0, dtype=np.int64)
        self.first_uv: F64 = np.zeros((0, 2))
        self.next_id = 0

    def __len__(self) -> int:
        return len(self.ids)

    def clear(self) -> None:
        """Drop every track (ids keep increasing)."""
        self.keep(np.zeros(len(self.ids), dtype=bool))

    def keep(self, mask: NDArray[np.bool_]) -> None:
        """Keep the tracks where the (N,) ``mask`` is true."""
        if mask.shape != self.ids.shape:
            raise ShapeError(f"TrackSet.keep: mask {mask.shape} for {len(self.ids)} tracks")
        self.ids, self.pts = self.ids[mask], self.pts[mask]
        self.first_kf, self.first_uv = self.first_kf[mask], self.first_uv[mask]

    def move(self, pts: F64) -> None:
        """New (N, 2) positions of all tracks."""
        if pts.shape != self.pts.shape:
            raise ShapeError(f"TrackSet.move: {pts.shape} positions for {len(self.ids)} tracks")
        self.pts = pts

    def add(self, pts: F64, kf_id: int) -> None:
        """Start (M, 2) new tracks, first seen in keyframe ``kf_id`` (or UNANCHORED)."""
        n = len(pts)
        if n == 0:
            return
        self.ids = np.concatenate([self.ids, np.arange(self.next_id, self.next_id + n, dtype=np.int64)])
        self.next_id += n
        self.pts = np.vstack([self.pts, pts])
        self.first_kf = np.concatenate([self.first_kf, np.full(n, kf_id)])
        self.first_uv = np.vstack([self.first_uv, pts])

    def reset(self, ids: I64, pts: F64) -> None:
        """Replace every track by existing ones: (M,) increasing ``ids`` below ``next_id`` (e.g.
        map points found again by relocalisation) at (M, 2) ``pts``, seen in no keyframe yet."""
        ids = np.asarray(ids, dtype=np.int64)
        if pts.shape != (len(ids), 2) or (len(ids) and (np.any(np.diff(ids) <= 0)
                                                        or ids[-1] >= self.next_id)):
            raise ShapeError("TrackSet.reset: ids must be increasing and known, pts (M, 2)")
        self.ids, self.pts = ids.copy(), np.asarray(pts, dtype=np.float64).copy()
        self.first_kf = np.full(len(ids), UNANCHORED, dtype=np.int64)
        self.first_uv = self.pts.copy()

    def anchor(self, kf_id: int, first_uv: F64) -> None:
        """All tracks were first seen in keyframe ``kf_id`` at (N, 2) ``first_uv``."""
        self.first_kf = np.full(len(self.ids), kf_id, dtype=np.int64)
        self.first_uv = np.asarray(first_uv, dtype=np.float64).copy()


__all__ = ["UNANCHORED", "TrackSet"]
