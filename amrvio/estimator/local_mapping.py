"""Estimator stage of the monocular VO: map segments, keyframes, triangulation and local BA.

A segment is one map with its own gauge; ``world_from_segment`` (a Sim3) places it in the global
world. The stage decides when a frame becomes a keyframe (``frontend.keyframe_policy``),
re-tracks the keyframe's tracks from the images where they started (``frontend.anchor``),
triangulates new points and runs the sliding-window BA (``estimator.mapper``). The VI smoother
plugs in at this place.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.mapper import BAReport, Mapper, MapperConfig, TriangulationReport
from amrvio.frontend.anchor import AnchorConfig, AnchorImage, retrack_from_anchors
from amrvio.frontend.keyframe_policy import KeyframePolicyConfig, KeyframeReason, keyframe_decision
from amrvio.frontend.tracks import TrackSet
from amrvio.types.lie import Sim3, se3_matrix_inverse

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class MappingConfig:
    """Keyframe policy, anchor re-tracking at keyframes, and the mapper (triangulation, BA)."""

    keyframes: KeyframePolicyConfig = field(default_factory=KeyframePolicyConfig)
    anchor_refine: bool = True
    anchor: AnchorConfig = field(default_factory=AnchorConfig)
    mapper: MapperConfig = field(default_factory=MapperConfig)


@dataclass(frozen=True, slots=True)
class KeyframeReport:
    """A keyframe: its id in its segment, why it was made (None: the second keyframe of a new
    map, made by the initializer), tracks dropped by anchor re-tracking, the triangulation and the
    local BA reports (None for the keyframes of a new map)."""

    kf_id: int
    reason: KeyframeReason | None
    n_retrack_dropped: int
    triangulation: TriangulationReport | None
    ba: BAReport | None


@dataclass(frozen=True, slots=True)
class Segment:
    """One map (``mapper.map``, in segment units) and its place in the global world:
    ``p_world = s R p_segment + t``."""

    mapper: Mapper
    world_from_segment: Sim3

    def pose_in_world(self, T_cam_seg: F64) -> F64:
        """4x4 ``T_world_cam`` of a camera pose ``T_cam_seg`` (4x4) of this segment: the
        rotation is mapped by R, the position by the similarity."""
        return self.world_from_segment.transform_pose_matrix(se3_matrix_inverse(T_cam_seg))

    def points_in_world(self, scale: float = 1.0) -> F64:
        """(P, 3) map points in the global world, times ``scale``."""
        _, X = self.mapper.map.all_points()
        sim = self.world_from_segment
        return scale * (sim.s * X @ sim.R.T + sim.t)


class LocalMapping:
    """Owns the map segments and the keyframe images that current tracks are anchored in."""

    def __init__(self, K: F64, config: MappingConfig) -> None:
        self.cfg = config
        self.K = K
        self.segments: list[Segment] = []
        self.kf_images: dict[int, AnchorImage] = {}
        self.timings: dict[str, float] = {}

    @property
    def ba_span(self) -> int:
        """Keyframes in the local BA window (adjusted and held ones): an older keyframe no
        longer moves."""
        return self.cfg.mapper.ba_window + self.cfg.mapper.ba_fixed

    @property
    def current(self) -> Segment:
        if not self.segments:
            raise RuntimeError("LocalMapping: no map segment yet")
        return self.segments[-1]

    def new_segment(self, world_from_segment: Sim3) -> Segment:
        """Start a new, empty map; the previous one is done (:meth:`VoMap.compact`)."""
        if self.segments:
            self.segments[-1].mapper.map.compact()
        seg = Segment(Mapper(self.K, self.cfg.mapper), world_from_segment)
        self.segments.append(seg)
        self.kf_images = {}
        return seg

    def keyframe_due(self, index: int, n_inliers: int, tracks: TrackSet) -> KeyframeReason:
        """Whether frame ``index`` (tracked with ``n_inliers``) should become a keyframe."""
        m = self.current.mapper.map
        kf = m.keyframes[-1]
        return keyframe_decision(self.cfg.keyframes, index - kf.frame_index, n_inliers,
                                 int(m.points_of(kf.track_ids).sum()), kf.track_ids, kf.uv,
                                 tracks.ids, tracks.pts)

    def add_keyframe(self, index: int, T_cam_world: F64, img: U8, tracks: TrackSet,
                     reason: KeyframeReason) -> tuple[F64, KeyframeReport]:
        """Make frame ``index`` a keyframe: anchor re-tracking, triangulation, local BA.
        Returns the refined ``T_cam_world`` and the report. Call :meth:`seal_keyframe` after
        new tracks were detected in the image."""
        mapper = self.current.mapper
        m = mapper.map
        n_drop = 0
        if self.cfg.anchor_refine:
            t0 = time.perf_counter()
            pts, drop = retrack_from_anchors(img, tracks.pts, tracks.first_kf, tracks.first_uv,
                                             self.kf_images, self.cfg.anchor)
            tracks.move(pts)
            tracks.keep(~drop)
            n_drop = int(drop.sum())
            self.timings["anchor"] = self.timings.get("anchor", 0.0) + time.perf_counter() - t0
        kf = m.add_keyframe(index, T_cam_world, tracks.ids, tracks.pts)
        # triangulate tracks seen in an earlier keyframe and without a point yet
        tri = mapper.triangulate_new(kf.kf_id, tracks.ids, tracks.first_kf, tracks.first_uv,
                                       tracks.pts, tracks.next_id)
        ba = mapper.local_ba()
        return m.keyframes[kf.kf_id].T_cam_world.copy(), KeyframeReport(kf.kf_id, reason, n_drop,
                                                                        tri, ba)

    def seal_keyframe(self, kf_id: int, img: U8, tracks: TrackSet) -> None:
        """Record the keyframe's final observations (after detection added tracks), keep its
        image while some track is anchored in it, and drop the tracks of the keyframes that have
        left the BA window (:meth:`VoMap.retire_tracks`)."""
        m = self.current.mapper.map
        kf = m.keyframes[kf_id]
        kf.track_ids = tracks.ids.copy()
        kf.uv = tracks.pts.copy()
        # the next BA window is the newest ba_window + ba_fixed keyframes: older tracks are done
        m.retire_tracks(self.ba_span)
        self.kf_images[kf_id] = AnchorImage.of(img)
        used = {int(k) for k in np.unique(tracks.first_kf)}
        for key in list(self.kf_images):
            if key not in used:
                del self.kf_images[key]

    def keep_image(self, kf_id: int, img: U8) -> None:
        """Keep a keyframe image for anchor re-tracking (the first keyframe of a map)."""
        self.kf_images[kf_id] = AnchorImage.of(img)

    def all_timings(self) -> dict[str, float]:
        out = dict(self.timings)
        for sg in self.segments:
            for k, v in sg.mapper.timings.items():
                out[k] = out.get(k, 0.0) + v
        return out


__all__ = ["KeyframeReport", "LocalMapping", "MappingConfig", "Segment"]
