"""Map recovery after a loss: keyframe retrieval by appearance, then PnP, in the map that was
being tracked (``estimator.relocalizer``), so that the trajectory keeps one map and one scale.

Every keyframe of every segment is described when it is sealed (ORB at its tracked pixels, in
a per-segment :class:`KeyframeDatabase`). After a loss, each new sharp frame is tried against
the segment that was lost until it is found again or a new map is initialised.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.keyframe_db import KeyframeDatabase
from amrvio.estimator.relocalizer import RelocConfig, RelocResult, relocalize
from amrvio.estimator.vo_map import VoMap

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class RecoveryConfig:
    """``enabled``: try relocalisation after a loss; ``reloc``: its gates; ``max_features``:
    descriptors kept per keyframe; ``max_bridge_frames``: after this many frames without a
    usable image (blurred, dark), the map is searched by appearance before the motion model is
    trusted again."""

    enabled: bool = True
    max_bridge_frames: int = 5
    reloc: RelocConfig = field(default_factory=RelocConfig)
    max_features: int = 1500


class MapRecovery:
    """Per-segment keyframe databases and the relocalisation attempts after a loss."""

    def __init__(self, K: F64, config: RecoveryConfig, seed: int) -> None:
        self.cfg = config
        self.K = K
        self.seed = seed
        self.dbs: dict[int, KeyframeDatabase] = {}
        self.target: int | None = None  # the segment to find again, while lost
        self.timings: dict[str, float] = {}

    def add_keyframe(self, segment: int, kf_id: int, image: U8, vomap: VoMap) -> None:
        """Describe keyframe ``kf_id`` of ``segment`` (call when its observations are final)."""
        if not self.cfg.enabled:
            return
        t0 = time.perf_counter()
        db = self.dbs.setdefault(segment, KeyframeDatabase(self.cfg.max_features, self.seed))
        kf = vomap.keyframes[kf_id]
        db.add(kf_id, image, kf.uv, kf.track_ids, priority=vomap.points_of(kf.track_ids))
        self.timings["reloc_db"] = self.timings.get("reloc_db", 0.0) + time.perf_counter() - t0

    def lost(self, segment: int) -> None:
        """Tracking of ``segment`` was lost: try to find it again from now on."""
        self.target = segment if self.cfg.enabled else None

    def give_up(self) -> None:
        """A new map was initialised: stop searching the old one."""
        self.target = None

    def attempt(self, image: U8, vomap: VoMap) -> RelocResult | None:
        """Try ``image`` in the lost segment's map (None when nothing is being searched)."""
        if self.target is None or self.target not in self.dbs:
            return None
        t0 = time.perf_counter()
        res = relocalize(image, self.K, vomap, self.dbs[self.target], self.cfg.reloc, self.seed)
        self.timings["reloc"] = self.timings.get("reloc", 0.0) + time.perf_counter() - t0
        if res.ok:
            self.target = None
        return res


__all__ = ["MapRecovery", "RecoveryConfig"]
