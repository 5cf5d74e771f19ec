"""The monocular VO map as plain data: keyframes and points indexed by track id.

Only :class:`VoMap` methods change it (one place that mutates the window).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(slots=True)
class Keyframe:
    """A keyframe: frame index, ``T_cam_world`` (4x4, updated by BA), and the tracks it saw:
    ``track_ids`` (M,) with their (M, 2) pinhole pixel positions ``uv`` (empty once the keyframe
    has left the BA window: :meth:`VoMap.retire_tracks`)."""

    kf_id: int
    frame_index: int
    T_cam_world: F64
    track_ids: I64
    uv: F64


@dataclass(slots=True)
class VoMap:
    """Keyframes and map points of one map segment. Point ``i`` belongs to track ``i``."""

    keyframes: list[Keyframe] = field(default_factory=list)
    xyz: F64 = field(default_factory=lambda: np.zeros((0, 3)))
    has_point: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    n_retired: int = 0  # the oldest keyframes whose tracks were dropped (:meth:`retire_tracks`)

    def ensure_capacity(self, n_tracks: int) -> None:
        """Grow the per-track arrays to hold track ids < ``n_tracks``."""
        if n_tracks <= len(self.has_point):
            return
        cap = max(n_tracks, 2 * len(self.has_point), 1024)
        xyz = np.zeros((cap, 3))
        hp = np.zeros(cap, dtype=bool)
        xyz[: len(self.xyz)] = self.xyz
        hp[: len(self.has_point)] = self.has_point
        self.xyz, self.has_point = xyz, hp

    def add_keyframe(self, frame_index: int, T_cam_world: F64, track_ids: I64, uv: F64) -> Keyframe:
        kf = Keyframe(len(self.keyframes), frame_index, T_cam_world.copy(), track_ids.copy(),
                      uv.copy())
        self.keyframes.append(kf)
        return kf

    def set_points(self, track_ids: I64, xyz: F64) -> None:
        self.ensure_capacity(int(track_ids.max()) + 1 if len(track_ids) else 0)
        self.xyz[track_ids] = xyz
        self.has_point[track_ids] = True

    def remove_points(self, track_ids: I64) -> None:
        self.has_point[track_ids] = False

    def points_of(self, track_ids: I64) -> NDArray[np.bool_]:
        """(N,) bool: which of these track ids have a map point."""
        ok = track_ids < len(self.has_point)
        out = np.zeros(len(track_ids), dtype=bool)
        out[ok] = self.has_point[track_ids[ok]]
        return out

    def set_pose(self, kf_id: int, T_cam_world: F64) -> None:
        self.keyframes[kf_id].T_cam_world = T_cam_world.copy()

    def retire_tracks(self, keep_last: int) -> None:
        """Drop the tracks of all but the newest ``keep_last`` keyframes; their poses stay. The
        local BA window is the only reader of an older keyframe's tracks, so with ``keep_last``
        at least its size nothing changes but the memory, which then stays bounded."""
        end = max(len(self.keyframes) - keep_last, 0)
        for kf in self.keyframes[self.n_retired:end]:
            kf.track_ids = np.zeros(0, dtype=np.int64)
            kf.uv = np.zeros((0, 2))
        self.n_retired = max(self.n_retired, end)

    def all_points(self) -> tuple[I64, F64]:
        ids = np.flatnonzero(self.has_point).astype(np.int64)
        return ids, self.xyz[ids].copy()


__all__ = ["Keyframe", "VoMap"]
