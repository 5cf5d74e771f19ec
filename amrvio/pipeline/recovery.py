"""Map recovery after a loss: keyframe retrieval by appearance, then PnP, in the map that was
being tracked (``estimator.relocalizer``), so that the trajectory keeps one map and one scale.

Every keyframe is described when it is sealed (ORB at its tracked pixels, in the current
segment's :class:`KeyframeDatabase`, which keeps the newest ``max_keyframes``). After a loss,
each new sharp frame is tried against the segment that was lost until it is found again or a new
map is initialised.

Keyframes and queries are described on the image the tracker works on: an image wider than the
tracker's ``max_width_px`` is reduced by the same pyramid levels first (pixels stay in full
resolution outside). ORB's 31-pixel patch on a blurred 1080p frame sees smooth gradients: on the
phone recording, full-resolution descriptors matched the keyframes before a keyframe at a median
reprojection error of mostly 150-900 pixels at its tracked pose; 12 of its 57 keyframes were found
in the keyframes before them (22 of 57 at the tracker's level).
"""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.keyframe_db import KeyframeDatabase
from amrvio.estimator.local_mapping import Segment
from amrvio.estimator.relocalizer import RelocConfig, RelocResult, describe_query, relocalize
from amrvio.estimator.segment_link import LinkConfig, link_segments
from amrvio.estimator.vo_map import VoMap
from amrvio.tracking.lk import reduced, reduction_levels
from amrvio.tracking.orb import OrbFeatures
from amrvio.types.lie import se3_matrix_inverse

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class RecoveryConfig:
    """``enabled``: try relocalisation after a loss; ``reloc``: its gates; ``max_features``:
    descriptors kept per keyframe; ``max_keyframes``: keyframes kept of the current map, the newest
    (the oldest is forgotten when one more is sealed, and an older map's database when a new map
    starts: the memory stays bounded on a long run, and the search is for the recent map, not a
    loop closure); ``max_bridge_frames``: after this many frames without a
    usable image (blurred, dark), the map is searched by appearance before the motion model is
    trusted again; ``link``: placing a new map by the points it shares with the previous one."""

    enabled: bool = True
    max_bridge_frames: int = 5
    link: LinkConfig = field(default_factory=LinkConfig)
    reloc: RelocConfig = field(default_factory=RelocConfig)
    max_features: int = 1500
    max_keyframes: int = 300


class MapRecovery:
    """The current segment's keyframe database and the relocalisation attempts after a loss."""

    def __init__(self, K: F64, config: RecoveryConfig, seed: int, max_width_px: int | None = None) -> None:
        self.cfg = config
        self.K = K
        self.seed = seed
        self.max_width_px = max_width_px  # the tracker's: wider images are described reduced
        self.dbs: dict[int, KeyframeDatabase] = {}
        self.target: int | None = None  # the segment to find again, while lost
        self.tried = -1  # the last frame searched
        self.timings: dict[str, float] = {}

    def add_keyframe(self, segment: int, kf_id: int, image: U8, vomap: VoMap) -> None:
        """Describe keyframe ``kf_id`` of ``segment`` (call when its observations are final)."""
        if not self.cfg.enabled:
            return
        t0 = time.perf_counter()
        if segment not in self.dbs:
            # a new map: the older maps' databases are never searched again (a loss searches
            # the map just lost, and a new map ends that search), so they go
            self.dbs = {s: db for s, db in self.dbs.items() if s > segment}
            self.dbs[segment] = KeyframeDatabase(self.cfg.max_features, self.seed)
        db = self.dbs[segment]
        kf = vomap.keyframes[kf_id]
        small, scale = self._reduced(image)
        db.add(kf_id, small, kf.uv / scale, kf.track_ids, priority=vomap.points_of(kf.track_ids))
        while len(db) > self.cfg.max_keyframes:
            db.remove(db.entries()[0].kf_id)
        self.timings["reloc_db"] = self.timings.get("reloc_db", 0.0) + time.perf_counter() - t0

    def lost(self, segment: int) -> None:
        """Tracking of ``segment`` was lost: try to find it again from now on."""
        self.target = segment if self.cfg.enabled else None

    def give_up(self) -> None:
        """A new map was initialised: stop searching the old one."""
        self.target = None

    def attempt(self, image: U8, vomap: VoMap, frame: int) -> RelocResult | None:
        """Try ``image`` (frame index ``frame``) in the lost segment's map; None when nothing is
        being searched or this frame was tried already (a failed search after a gap is not
        repeated when tracking then loses the same frame)."""
        if self.target is None or self.target not in self.dbs or frame == self.tried:
            return None
        self.tried = frame
        t0 = time.perf_counter()
        small, scale = self._reduced(image)
        feats = describe_query(small, self.cfg.reloc)
        feats = OrbFeatures(feats.uv * scale, feats.descriptors, feats.octave)
        res = relocalize(feats, self.K, vomap, self.dbs[self.target], self.cfg.reloc, self.seed,
                         image_shape_hw=(int(image.shape[0]), int(image.shape[1])))
        self.timings["reloc"] = self.timings.get("reloc", 0.0) + time.perf_counter() - t0
        if res.ok:
            self.target = None
        return res

    def _reduced(self, image: U8) -> tuple[U8, float]:
        """``image`` reduced as the tracker reduces it (``cv2.pyrDown`` per level) and the image
        pixels per pixel of the result."""
        levels = reduction_levels(image.shape[1], self.max_width_px)
        return reduced(image, levels), float(2 ** levels)


def implausible_jump(T_cam_world: F64, T_last: F64 | None, segment_scale: float,
                     typical_speed: float, frames_since: int) -> float | None:
    """The distance (global units) of a relocalised pose from the last known one when it
    exceeds three times what the recent speed covers in the frames since (at least 5 frames'
    worth), else None: a repeated structure (shelves, posters) can look like the place."""
    if T_last is None:
        return None
    c_new = se3_matrix_inverse(T_cam_world)[:3, 3]
    c_old = se3_matrix_inverse(T_last)[:3, 3]
    dist = float(np.linalg.norm(c_new - c_old)) * segment_scale
    bound = 3.0 * typical_speed * max(frames_since, 5)
    return dist if dist > bound else None


def link_to_previous(segments: list[Segment], seg_id: int, config: LinkConfig,
                     seed: int) -> tuple[Segment, str]:
    """Place ``segments[seg_id]`` (a new map) in the world through the points it shares with the
    previous segment (replacing it in the list when linked); the segment and an event string."""
    seg, prev = segments[seg_id], segments[seg_id - 1]
    link = link_segments(seg.mapper.map, prev.mapper.map, config, seed)
    if link.old_from_new is None:
        return seg, f"segment_link_failed:{link.n_common}:{link.n_inliers}"
    linked = dataclasses.replace(seg, world_from_segment=prev.world_from_segment @ link.old_from_new)
    segments[seg_id] = linked
    return linked, f"segment_linked:{link.n_inliers}/{link.n_common}:s={link.old_from_new.s:.4g}"


__all__ = ["MapRecovery", "RecoveryConfig", "implausible_jump", "link_to_previous"]
