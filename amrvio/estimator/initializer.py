"""Initializer stage: builds the first map of a segment from two views.

It keeps a reference image and the tracks seen since; each frame it scores the two-view
geometry between the reference and the current tracks (``geometry.two_view``: homography or
essential matrix, chosen by score, accepted on the quality of the triangulated points). There
is no fixed window: the reference is kept while enough of its tracks survive and moved when they
do not. While the camera only rotates, each attempt still gives the rotation to the reference,
so the caller can keep the frame posed. On success it creates the two keyframes and their points
in the mapper it is given, bundle-adjusts them, and poses the frames in between by PnP. Every
attempt returns an :class:`InitResult`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.mapper import Mapper
from amrvio.frontend.tracking_types import Observations
from amrvio.frontend.tracks import TrackSet
from amrvio.geometry.pnp import solve_pnp
from amrvio.geometry.two_view import (
    TwoViewConfig,
    TwoViewModel,
    TwoViewResult,
    TwoViewStatus,
    two_view_init,
)
from amrvio.types.lie import SE3

STILL_MRAD = 2.2
"""Median track motion, as an angle (px / focal length, in mrad), below which a camera counts as
standing still: in the initialiser's ``static`` label, the VIO's static start and its
zero-velocity detection. An angle
because the same standstill moves its tracks twice as many pixels at twice the resolution: the
simulator's replay of EuRoC V1_01, whose MAV stands for its first seconds, moved them 0.29 px
in 0.43 s at 376x240 (f = 229 px) and 0.54 px at 752x480 (f = 459 px), 1.2 mrad at both; the
old gate of 0.5 px took the static start at the first resolution and refused it at the second.
2.2 mrad is 0.5 px at f = 229 px, 1.0 px at 459 px and 1.6 px at KITTI's 718 px."""


def angle_px(mrad: float, focal_px: float) -> float:
    """An angle of ``mrad`` milliradians as pixels of a camera with focal length ``focal_px``."""
    return 1e-3 * mrad * focal_px

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class InitConfig:
    """Two-view gates; ``min_shared_ratio``: the reference is replaced when fewer than this share
    of its tracks (and fewer than twice ``two_view.min_points``) survive; ``max_history``: frames
    since the reference kept for posing by PnP after the map exists; ``static_flow_mrad``: median
    flow, as an angle (px / focal length, mrad), under which a low-parallax pair counts as a
    camera at rest; PnP gates for posing the
    frames between the two views."""

    two_view: TwoViewConfig = field(default_factory=TwoViewConfig)
    min_shared_ratio: float = 0.3
    max_history: int = 300
    static_flow_mrad: float = STILL_MRAD
    min_pnp_inliers: int = 25
    pnp_thresh_px: float = 1.0


@dataclass(frozen=True, slots=True)
class InitResult:
    """One initialisation attempt: the two-view status and model, the reference frame, the tracks
    shared with it, parallax (median and the gated order statistic) and flow, triangulated points,
    whether the camera looked static, whether the attempt ends here (``restart``: a new reference
    is taken), and ``T_cur_ref`` (4x4): the rotation to the reference (zero translation) when the
    camera was found rotating or at rest, else None."""

    status: TwoViewStatus
    model: TwoViewModel
    ref_index: int
    n_shared_tracks: int
    median_parallax_deg: float
    parallax_deg: float
    median_flow_px: float
    n_points: int
    static: bool
    restart: bool
    T_cur_ref: F64 | None = None

    @property
    def ok(self) -> bool:
        return self.status is TwoViewStatus.OK


@dataclass(frozen=True, slots=True)
class FramePose:
    """A frame between the two initial views: ``T_cam_kf0`` (4x4) from PnP, or None."""

    index: int
    T_cam_kf0: F64 | None
    observations: Observations | None


@dataclass(frozen=True, slots=True)
class NewMap:
    """What a successful initialisation made: the keyframe ids, the refined pose of the current
    frame ``T_cam_world`` (4x4), the per-frame velocity, and the poses of the frames between."""

    kf0: int
    kf1: int
    T_cam_world: F64
    velocity: F64
    between: tuple[FramePose, ...]


class Initializer:
    """Construct with the pinhole ``K`` (3x3), the config and the RANSAC seed."""

    def __init__(self, K: F64, config: InitConfig, seed: int) -> None:
        self.cfg = replace(config, two_view=replace(config.two_view, seed=seed))
        self.K = K
        self.seed = seed
        self.ref_index = 0
        self.ref_img: U8 | None = None
        self.ref_ids: I64 = np.zeros(0, dtype=np.int64)
        self.ref_pts: F64 = np.zeros((0, 2))
        # (frame index, track ids, pixels) of each frame since the reference
        self.history: list[tuple[int, I64, F64]] = []
        self._last: TwoViewResult | None = None
        self.timings: dict[str, float] = {}

    def begin(self, index: int, img: U8, tracks: TrackSet, keep_history: bool) -> None:
        """Frame ``index`` becomes the reference. ``keep_history`` (a retry in the same place)
        keeps the frames of the failed attempt, so that they still get a pose by PnP."""
        history = self.history[-self.cfg.max_history:] if keep_history else []
        self.ref_index = index
        self.ref_img = img
        self.ref_ids = tracks.ids.copy()
        self.ref_pts = tracks.pts.copy()
        if history and history[-1][0] == index:
            history = history[:-1]
        self.history = [*history, (index, tracks.ids.copy(), tracks.pts.copy())]

    def attempt(self, index: int, tracks: TrackSet) -> InitResult:
        """Score the two-view geometry between the reference and the current tracks."""
        self.history.append((index, tracks.ids.copy(), tracks.pts.copy()))
        ref_mask = np.isin(self.ref_ids, tracks.ids)
        cur_mask = np.isin(tracks.ids, self.ref_ids)
        # both arrays are sorted by id (ids only ever get filtered), so they align
        t0 = time.perf_counter()
        tv = two_view_init(self.ref_pts[ref_mask], tracks.pts[cur_mask], self.K, self.cfg.two_view)
        self.timings["init"] = self.timings.get("init", 0.0) + time.perf_counter() - t0
        self._last = tv
        if len(self.history) > self.cfg.max_history:
            self.history = [self.history[0], *self.history[-self.cfg.max_history:]]
        static = (tv.status is TwoViewStatus.LOW_PARALLAX
                  and tv.median_flow_px < angle_px(self.cfg.static_flow_mrad, float(self.K[0, 0])))
        n_shared = int(cur_mask.sum())
        few = n_shared < max(2 * self.cfg.two_view.min_points,
                             self.cfg.min_shared_ratio * len(self.ref_ids))
        restart = not tv.ok and few
        rotating = tv.model is TwoViewModel.ROTATION
        return InitResult(tv.status, tv.model, self.ref_index, n_shared, tv.median_parallax_deg,
                          tv.parallax_deg, tv.median_flow_px,
                          int(tv.point_valid.sum()) if tv.ok else 0, static, restart,
                          tv.T_c2_c1.copy() if rotating else None)

    def build(self, index: int, tracks: TrackSet, mapper: Mapper) -> NewMap:
        """After a successful :meth:`attempt` at frame ``index``: the first two keyframes, their
        points and a local BA in ``mapper``; the tracks keep those seen in the reference, first
        seen in keyframe 0; the frames in between are posed by PnP."""
        tv = self._last
        if tv is None or not tv.ok:
            raise RuntimeError("Initializer.build without a successful attempt")
        m = mapper.map
        ref_mask = np.isin(self.ref_ids, tracks.ids)
        ref_ids, ref_pts = self.ref_ids[ref_mask], self.ref_pts[ref_mask]
        cur_mask = np.isin(tracks.ids, self.ref_ids)
        T0 = np.eye(4)
        kf0 = m.add_keyframe(self.ref_index, T0, ref_ids, ref_pts)
        m.ensure_capacity(tracks.next_id, first=int(ref_ids.min()) if len(ref_ids) else 0)
        good = tv.point_valid
        m.set_points(ref_ids[good], tv.points_c1[good])
        tracks.keep(cur_mask)
        tracks.anchor(kf0.kf_id, ref_pts)
        kf1 = m.add_keyframe(index, tv.T_c2_c1, tracks.ids, tracks.pts)
        mapper.local_ba()
        T1 = m.keyframes[kf1.kf_id].T_cam_world
        between = []
        for fi, ids_f, pts_f in self.history:
            if fi in (self.ref_index, index):
                continue
            between.append(self._pose_between(fi, ids_f, pts_f, mapper, T0))
        # per-frame velocity from the init baseline (geometric mean of the motion)
        n_frames = max(index - self.ref_index, 1)
        xi = SE3.from_matrix(T1).log() / n_frames
        velocity = SE3.exp(np.asarray(xi, dtype=np.float64)).matrix()
        self._last = None
        self.history = []  # these frames belong to this map now; a later attempt starts afresh
        return NewMap(kf0.kf_id, kf1.kf_id, T1.copy(), velocity, tuple(between))

    def _pose_between(self, fi: int, ids_f: I64, pts_f: F64, mapper: Mapper, T0: F64) -> FramePose:
        m = mapper.map
        has = m.points_of(ids_f)
        if int(has.sum()) >= self.cfg.min_pnp_inliers:
            r = solve_pnp(m.xyz[ids_f[has]], pts_f[has], self.K, T_guess=T0,
                          ransac_thresh_px=self.cfg.pnp_thresh_px, seed=self.seed)
            if r.ok:
                obs = Observations(ids_f[has][r.inliers], pts_f[has][r.inliers])
                return FramePose(fi, r.T_cam_world.copy(), obs)
        return FramePose(fi, None, None)


__all__ = ["FramePose", "InitConfig", "InitResult", "Initializer", "NewMap"]
