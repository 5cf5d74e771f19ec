"""The monocular VO map as plain data: keyframes and points indexed by track id.

Only :class:`VoMap` methods change it (one place that mutates the window). The points of old
tracks move to a compact archive as the keyframes that saw them leave the BA window
(:class:`PointTable`), so a long run keeps about 33 bytes per map point instead of 25 per track id.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


_NO_IDS = np.zeros(0, dtype=np.int64)
_NO_UV = np.zeros((0, 2))
_NO_IDS.setflags(write=False)
_NO_UV.setflags(write=False)


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


class PointTable:
    """Map points by track id. Ids from ``base`` on live in dense arrays (index ``id - base``:
    the recent tracks, which triangulation and BA write); older ids that have a point live in a
    sorted archive of (id, xyz). ``table[ids]`` reads (N, 3) points of any ids (zeros where there
    is none), ``table[ids] = X`` writes them (an archived id is updated in place, or inserted)."""

    def __init__(self) -> None:
        self.base = 0
        self._xyz = np.zeros((0, 3))
        self._has = np.zeros(0, dtype=bool)
        self._old_ids = np.zeros(0, dtype=np.int64)
        self._old_xyz = np.zeros((0, 3))
        self._old_has = np.zeros(0, dtype=bool)

    @property
    def end(self) -> int:
        """One past the largest id the dense arrays hold."""
        return self.base + len(self._has)

    @property
    def nbytes(self) -> int:
        return sum(a.nbytes for a in (self._xyz, self._has, self._old_ids, self._old_xyz, self._old_has))

    def ensure_capacity(self, n_tracks: int, first: int = 0) -> None:
        """Grow the dense arrays to hold track ids < ``n_tracks``. A table that holds nothing
        yet starts them at ``first``, the lowest id it is expected to hold (a new map's first
        track: the ids are global); a lower id still reads and writes, in the archive."""
        if not len(self._has) and not len(self._old_ids) and first > self.base:
            self.base = first
        if n_tracks <= self.end:
            return
        cap = max(n_tracks - self.base, 2 * len(self._has), 1024)
        xyz, has = np.zeros((cap, 3)), np.zeros(cap, dtype=bool)
        xyz[: len(self._xyz)] = self._xyz
        has[: len(self._has)] = self._has
        self._xyz, self._has = xyz, has

    def _split(self, ids: I64) -> tuple[NDArray[np.bool_], I64, NDArray[np.bool_], I64]:
        """(dense mask, dense index, archived mask, archive index) of ``ids``."""
        rel = ids - self.base
        dense = (rel >= 0) & (rel < len(self._has))
        pos = np.searchsorted(self._old_ids, ids)
        pos_c = np.minimum(pos, max(len(self._old_ids) - 1, 0))
        old = (ids < self.base) & (pos < len(self._old_ids))
        old[old] = self._old_ids[pos_c[old]] == ids[old]
        return dense, rel, old, pos_c

    def __getitem__(self, ids: I64) -> F64:
        ids = np.asarray(ids, dtype=np.int64)
        out = np.zeros((*ids.shape, 3))
        dense, rel, old, pos = self._split(ids)
        out[dense] = self._xyz[rel[dense]]
        out[old] = self._old_xyz[pos[old]]
        return out

    def __setitem__(self, ids: I64, xyz: F64) -> None:
        self.set(ids, xyz, None)

    def set(self, ids: I64, xyz: F64 | None, has: bool | None) -> None:
        """Write points (``xyz`` (N, 3), or None to keep them) and/or their flag (``has``)."""
        ids = np.asarray(ids, dtype=np.int64)
        if len(ids) and int(ids.max()) >= self.end:
            self.ensure_capacity(int(ids.max()) + 1)
        X = None if xyz is None else np.broadcast_to(np.asarray(xyz, dtype=np.float64), (len(ids), 3))
        dense, rel, old, pos = self._split(ids)
        for where, idx, pts, flags in ((dense, rel, self._xyz, self._has), (old, pos, self._old_xyz, self._old_has)):
            if X is not None:
                pts[idx[where]] = X[where]
            if has is not None:
                flags[idx[where]] = has
        new = (ids < self.base) & ~old
        if new.any() and (has or (X is not None and has is None)):
            # an old track's point made only now (rare: a relocalisation that resumed old tracks)
            add = ids[new]
            ids_all = np.concatenate([self._old_ids, add])
            order = np.argsort(ids_all, kind="stable")
            X_add = X[new] if X is not None else np.zeros((len(add), 3))
            self._old_ids = ids_all[order]
            self._old_xyz = np.vstack([self._old_xyz, X_add])[order]
            self._old_has = np.concatenate([self._old_has, np.full(len(add), bool(has) if has is not None
                                                                    else False)])[order]

    def has(self, ids: I64) -> NDArray[np.bool_]:
        """(N,) bool: which of these track ids have a point."""
        ids = np.asarray(ids, dtype=np.int64)
        dense, rel, old, pos = self._split(ids)
        out = np.zeros(len(ids), dtype=bool)
        out[dense] = self._has[rel[dense]]
        out[old] = self._old_has[pos[old]]
        return out

    def archive_below(self, new_base: int) -> None:
        """Move the points of ids below ``new_base`` to the archive (ids without a point are
        forgotten) and shift the dense arrays; nothing when ``new_base`` is not past ``base``."""
        shift = min(new_base, self.end) - self.base
        if shift <= 0:
            return
        keep = np.flatnonzero(self._has[:shift])
        self._old_ids = np.concatenate([self._old_ids, self.base + keep.astype(np.int64)])
        self._old_xyz = np.vstack([self._old_xyz, self._xyz[keep]])
        self._old_has = np.concatenate([self._old_has, np.ones(len(keep), dtype=bool)])
        self._xyz, self._has = self._xyz[shift:].copy(), self._has[shift:].copy()
        self.base += shift

    def all_points(self) -> tuple[I64, F64]:
        """The ids that have a point, increasing, and their (P, 3) points."""
        dense = np.flatnonzero(self._has)
        ids = np.concatenate([self._old_ids[self._old_has], self.base + dense.astype(np.int64)])
        return ids, np.vstack([self._old_xyz[self._old_has], self._xyz[dense]])


@dataclass(slots=True)
class VoMap:
    """Keyframes and map points of one map segment. Point ``i`` belongs to track ``i``:
    ``xyz[ids]`` reads (N, 3) points (see :class:`PointTable`)."""

    keyframes: list[Keyframe] = field(default_factory=list)
    xyz: PointTable = field(default_factory=PointTable)
    n_retired: int = 0  # the oldest keyframes whose tracks were dropped (:meth:`retire_tracks`)

    def ensure_capacity(self, n_tracks: int, first: int = 0) -> None:
        """Grow the per-track arrays to hold track ids < ``n_tracks`` (from ``first`` in a new
        map: :meth:`PointTable.ensure_capacity`)."""
        self.xyz.ensure_capacity(n_tracks, first)

    def add_keyframe(self, frame_index: int, T_cam_world: F64, track_ids: I64, uv: F64) -> Keyframe:
        kf = Keyframe(len(self.keyframes), frame_index, T_cam_world.copy(), track_ids.copy(),
                      uv.copy())
        self.keyframes.append(kf)
        return kf

    def set_points(self, track_ids: I64, xyz: F64) -> None:
        self.xyz.set(track_ids, xyz, True)

    def remove_points(self, track_ids: I64) -> None:
        self.xyz.set(track_ids, None, False)

    def points_of(self, track_ids: I64) -> NDArray[np.bool_]:
        """(N,) bool: which of these track ids have a map point."""
        return self.xyz.has(track_ids)

    def set_pose(self, kf_id: int, T_cam_world: F64) -> None:
        self.keyframes[kf_id].T_cam_world = T_cam_world.copy()

    def retire_tracks(self, keep_last: int) -> None:
        """Drop the tracks of all but the newest ``keep_last`` keyframes; their poses stay. The
        local BA window is the only reader of an older keyframe's tracks, so with ``keep_last``
        at least its size nothing changes but the memory, which then stays bounded. The points
        of the track ids below all the kept keyframes' (the newest holds the live tracks) go to
        the archive once they fill half the dense arrays."""
        end = max(len(self.keyframes) - keep_last, 0)
        for kf in self.keyframes[self.n_retired:end]:
            kf.track_ids, kf.uv = _NO_IDS, _NO_UV
        self.n_retired = max(self.n_retired, end)
        kept = [int(kf.track_ids.min()) for kf in self.keyframes[end:] if len(kf.track_ids)]
        if kept and 2 * (min(kept) - self.xyz.base) >= self.xyz.end - self.xyz.base:
            self.xyz.archive_below(min(kept))

    def compact(self) -> None:
        """The map is done (a new segment took over; nothing tracks in it again): every
        keyframe drops its tracks and every point moves to the archive, so that a finished map
        holds its keyframe poses and its points and nothing else. Reads of both stay the same."""
        self.retire_tracks(0)
        self.xyz.archive_below(self.xyz.end)

    def all_points(self) -> tuple[I64, F64]:
        return self.xyz.all_points()


__all__ = ["Keyframe", "PointTable", "VoMap"]
