"""Monocular VO as a per-frame loop of stages: ``process(image, t_ns) -> FrameResult``.

Stages and where they live:
- blur check (``diagnostics.blur``);
- KLT front-end with photometric compensation, FB check and essential-matrix rejection,
  motion prior ``predict_tracks`` (``frontend.klt``);
- two-view initialiser (``geometry.two_view``) | PnP tracker (``geometry.pnp``), with the
  direct-alignment prior and fallback (``frontend.direct``);
- keyframe policy (``frontend.keyframe_policy``) and anchor re-tracking (``frontend.anchor``);
- mapping: triangulation, local BA, culling, on the one map it owns (``estimator.mapper``);
- camera-height scale readings (``estimator.camera_height``).
This module keeps the track set and the segment bookkeeping, and wires the stages; ``finish()``
composes the final trajectory from the BA-refined keyframes.
"""

from __future__ import annotations

import logging
import time
from collections import defaultdict, deque
from dataclasses import dataclass, field
from enum import Enum

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.blur import BlurScorer, BlurScorerConfig, var_laplacian
from amrvio.estimator.camera_height import HeightEstimate, height_at_keyframe, smooth_scales
from amrvio.estimator.mapper import Mapper, MapperConfig
from amrvio.estimator.vo_map import VoMap
from amrvio.frontend.anchor import AnchorConfig, AnchorImage, retrack_from_anchors
from amrvio.frontend.direct import DirectConfig, align_direct
from amrvio.frontend.keyframe_policy import (
    KeyframePolicyConfig,
    KeyframeReason,
    keyframe_decision,
)
from amrvio.frontend.klt import KltConfig, KltTracker, detect_bucketed, predict_tracks
from amrvio.geometry._common import invert_T, project, se3_exp
from amrvio.geometry.pnp import refine_pose_huber, solve_pnp
from amrvio.geometry.two_view import (
    TwoViewConfig,
    TwoViewResult,
    TwoViewStatus,
    two_view_init,
)
from amrvio.types.lie import SE3

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]
log = logging.getLogger(__name__)


class PoseStatus(Enum):
    """How an output pose was obtained."""

    TRACKED = "tracked"
    INTERPOLATED = "interpolated"
    LOST = "lost"


@dataclass(frozen=True, slots=True)
class VoConfig:
    """All VO settings (flat, so that ablations replace one field). ``ba_backend``: "gtsam"
    (LM with SEQUENTIAL_CHOLESKY, chosen on measured speed: bench_ba_solvers) or "scipy"."""

    klt: KltConfig = field(default_factory=KltConfig)
    two_view: TwoViewConfig = field(default_factory=lambda: TwoViewConfig(min_parallax_deg=3.0))
    min_pnp_inliers: int = 25
    pnp_thresh_px: float = 1.0
    kf_max_gap: int = 6
    kf_min_track_ratio: float = 0.8
    kf_parallax_px: float = 25.0
    ba_window: int = 8
    ba_fixed: int = 2  # 3 before: KITTI sweep median ATE 1.00 -> 0.81 m (bench_vo)
    ba_backend: str = "gtsam"
    ba_iterations: int = 8
    huber_px: float = 2.0
    cull_px: float = 2.5
    tri_min_parallax_deg: float = 1.0
    tri_max_reproj_px: float = 1.0
    init_max_frames: int = 20
    static_flow_px: float = 0.5
    anchor_refine: bool = True
    direct: DirectConfig = field(default_factory=DirectConfig)
    direct_prior: bool = True
    direct_fallback: bool = True
    final_refine: bool = True
    anchor_max_shift_px: float = 2.0
    blur_gating: bool = True
    camera_height_m: float | None = None
    scale_half_window: int = 10
    seed: int = 0

    def mapper(self) -> MapperConfig:
        return MapperConfig(self.ba_window, self.ba_fixed, self.ba_backend, self.ba_iterations,
                            self.huber_px, self.cull_px, self.tri_min_parallax_deg,
                            self.tri_max_reproj_px)

    def keyframe_policy(self) -> KeyframePolicyConfig:
        return KeyframePolicyConfig(self.kf_max_gap, self.kf_min_track_ratio,
                                    self.kf_parallax_px)

    def anchor(self) -> AnchorConfig:
        return AnchorConfig(self.klt.win_size, self.anchor_max_shift_px, self.klt.photometric)


@dataclass(frozen=True, slots=True)
class FrameResult:
    """Online result of one frame (pose may still be refined by ``finish``)."""

    index: int
    t_ns: int
    status: PoseStatus
    T_world_cam: F64
    segment: int
    n_tracks: int
    n_inliers: int
    is_keyframe: bool
    blurred: bool
    blur_score: float
    brightness_a: float
    brightness_b: float
    event: str


@dataclass(frozen=True, slots=True)
class VoOutput:
    """Final results: per-frame poses (N, 4, 4) T_world_cam, statuses, keyframe indices,
    map points (P, 3), the per-keyframe height/scale record, timings per stage (s)."""

    stamps_ns: NDArray[np.int64]
    T_world_cam: F64
    frames: list[FrameResult]
    keyframe_indices: NDArray[np.int64]
    map_points: F64
    height_record: list[HeightEstimate]
    frame_scale: F64
    events: list[tuple[int, str]]
    timings_s: dict[str, float]


@dataclass(slots=True)
class _FrameRec:
    status: PoseStatus
    segment: int
    ref_kf: int  # keyframe id in its segment, -1 if none
    T_cam_ref: F64  # pose relative to ref keyframe, or absolute T_cam_world when ref_kf < 0
    obs_ids: I64 | None = None  # PnP inlier tracks, for the final motion-only refinement
    same_as: int = -1  # static camera: this frame has the pose of frame ``same_as``
    obs_uv: F64 | None = None


@dataclass(slots=True)
class _Segment:
    mapper: Mapper
    # Sim3 from segment world to global world: p_g = s R p + t
    R: F64
    t: F64
    s: float

    @property
    def map(self) -> VoMap:
        return self.mapper.map


class VoPipeline:
    """Monocular VO. Construct with the pinhole ``K`` (3x3) of undistorted pixel coordinates."""

    def __init__(self, K: F64, config: VoConfig | None = None) -> None:
        self.cfg = config or VoConfig()
        self.K = np.asarray(K, dtype=np.float64)
        self.klt = KltTracker(self.cfg.klt)
        # a short reference: sustained motion blur becomes the new normal after 10 frames,
        # sudden bursts are flagged
        self.blur = BlurScorer(BlurScorerConfig(window=10, reset_after=10))
        self.timings: dict[str, float] = defaultdict(float)
        self.frames: list[FrameResult] = []
        self.recs: list[_FrameRec] = []
        self.stamps: list[int] = []
        self.events: list[tuple[int, str]] = []
        self.heights: list[HeightEstimate] = []
        self.segments: list[_Segment] = []
        self._next_id = 0
        # tracks in the last good image
        self.prev_img: U8 | None = None
        self.ids: I64 = np.zeros(0, dtype=np.int64)
        self.pts: F64 = np.zeros((0, 2))
        self.first_kf: I64 = np.zeros(0, dtype=np.int64)
        self.first_uv: F64 = np.zeros((0, 2))
        self.gap = 0  # frames since the last good (tracked) image
        self._reset_init()
        self.T_last: F64 | None = None  # T_cam_world of last good frame (segment world)
        self.T_before: F64 | None = None
        self.last_good_index = -1
        self.velocity: F64 = np.eye(4)  # per-frame motion T_k_k-1
        self.last_kf_frame = -1
        self.kf_images: dict[int, AnchorImage] = {}  # of the current segment, by kf id
        self.speed_hist: deque[float] = deque(maxlen=50)  # global units per frame

    # ------------------------------------------------------------------ helpers
    def _reset_init(self) -> None:
        self.initialised = False
        self.init_ref_index = -1
        self.init_ref_pts: F64 = np.zeros((0, 2))
        self.init_history: list[tuple[int, I64, F64]] = []

    def _new_ids(self, n: int) -> I64:
        ids = np.arange(self._next_id, self._next_id + n, dtype=np.int64)
        self._next_id += n
        return ids

    def _tic(self) -> float:
        return time.perf_counter()

    def _toc(self, stage: str, t0: float) -> None:
        self.timings[stage] += time.perf_counter() - t0

    @property
    def seg(self) -> _Segment:
        return self.segments[-1]

    def _detect(self, img: U8, kf_id: int) -> None:
        t0 = self._tic()
        want = self.cfg.klt.max_features - len(self.ids)
        if want > 0.1 * self.cfg.klt.max_features:
            new = detect_bucketed(img, self.pts, want, self.cfg.klt)
            if len(new):
                self.ids = np.concatenate([self.ids, self._new_ids(len(new))])
                self.pts = np.vstack([self.pts, new])
                self.first_kf = np.concatenate([self.first_kf, np.full(len(new), kf_id)])
                self.first_uv = np.vstack([self.first_uv, new])
        self._toc("detect", t0)

    def _keep(self, mask: NDArray[np.bool_]) -> None:
        self.ids, self.pts = self.ids[mask], self.pts[mask]
        self.first_kf, self.first_uv = self.first_kf[mask], self.first_uv[mask]

    def _record(self, index: int, t_ns: int, status: PoseStatus, T_cw: F64, ref_kf: int,
                n_inl: int, is_kf: bool, blurred: bool, bscore: float, a: float, b: float,
                event: str = "", obs: tuple[I64, F64] | None = None) -> FrameResult:
        seg_id = len(self.segments) - 1
        if ref_kf >= 0:
            T_rel = T_cw @ invert_T(self.seg.map.keyframes[ref_kf].T_cam_world)
        else:
            T_rel = T_cw.copy()
        rec = _FrameRec(status, seg_id, ref_kf, T_rel)
        if obs is not None and not is_kf:
            rec.obs_ids, rec.obs_uv = obs
        self.recs.append(rec)
        self.stamps.append(t_ns)
        if event:
            self.events.append((index, event))
        T_wc = invert_T(T_cw)
        if self.segments:
            sg = self.seg
            T_wc = T_wc.copy()
            T_wc[:3, 3] = sg.s * sg.R @ T_wc[:3, 3] + sg.t
            T_wc[:3, :3] = sg.R @ T_wc[:3, :3]
        fr = FrameResult(index, t_ns, status, T_wc, seg_id, len(self.ids), n_inl, is_kf,
                         blurred, bscore, a, b, event)
        self.frames.append(fr)
        return fr

    # ------------------------------------------------------------------ main entry
    def process(self, img: U8, t_ns: int) -> FrameResult:
        """Consume the next grey image (H, W) uint8 taken at ``t_ns``."""
        index = len(self.frames)
        t0 = self._tic()
        # var(Laplacian) / var(I): invariant to an affine brightness (exposure) change
        sub = img[::2, ::2]
        bscore = var_laplacian(img, step=2) / max(float(np.var(sub)), 1.0)
        br = self.blur.update(bscore)
        blurred = bool(br.is_blurred) and self.cfg.blur_gating
        self._toc("blur", t0)
        if self.prev_img is None:
            return self._start(img, t_ns, index, bscore, blurred)
        if not self.initialised:
            return self._init_step(img, t_ns, index, bscore, blurred)
        return self._track_step(img, t_ns, index, bscore, blurred)

    # ------------------------------------------------------------------ start / init
    def _start(self, img: U8, t_ns: int, index: int, bscore: float,
               blurred: bool, event: str = "start", keep_tracks: bool = False) -> FrameResult:
        """Begin an initialisation attempt with this frame as the reference. ``keep_tracks``
        (a retry in the same place) keeps the tracks and the history, so that the frames of
        the failed attempts still get a pose by PnP once a map exists."""
        self.prev_img = img
        history = self.init_history[-self.cfg.init_max_frames * 3:] if keep_tracks else []
        if not keep_tracks:
            self.ids = np.zeros(0, dtype=np.int64)
            self.pts = np.zeros((0, 2))
            self.first_kf = np.zeros(0, dtype=np.int64)
            self.first_uv = np.zeros((0, 2))
        self._detect(img, -1)
        self._reset_init()
        self.init_ref_index = index
        self.init_ref_img = img
        self.init_ref_ids = self.ids.copy()
        self.init_ref_pts = self.pts.copy()
        if history and history[-1][0] == index:
            history = history[:-1]
        self.init_history = [*history, (index, self.ids.copy(), self.pts.copy())]
        self.gap = 0
        T_guess = np.eye(4) if self.T_last is None else self.velocity @ self.T_last
        status = PoseStatus.LOST
        return self._record(index, t_ns, status, T_guess, -1, 0, False, blurred, bscore,
                            1.0, 0.0, event)

    def _init_step(self, img: U8, t_ns: int, index: int, bscore: float,
                   blurred: bool) -> FrameResult:
        if self.prev_img is None:
            raise RuntimeError("VoPipeline: init step without a previous image")
        t0 = self._tic()
        res = self.klt.track(self.prev_img, img, self.pts, wide=self.gap > 0, K=self.K)
        self._toc("klt", t0)
        T_hold = self.recs[-1].T_cam_ref if self.recs else np.eye(4)
        if blurred:
            self.gap += 1
            return self._record(index, t_ns, PoseStatus.LOST, T_hold, -1, 0, False, blurred,
                                bscore, res.brightness.a, res.brightness.b)
        self.gap = 0
        self._keep(res.ok)
        self.pts = res.pts[res.ok]
        self.prev_img = img
        self.init_history.append((index, self.ids.copy(), self.pts.copy()))
        ref_mask = np.isin(self.init_ref_ids, self.ids)
        ref_pts = self.init_ref_pts[ref_mask]
        cur_mask = np.isin(self.ids, self.init_ref_ids)
        # both arrays are sorted by id (ids only ever get filtered), so they align
        t1 = self._tic()
        tv = two_view_init(ref_pts, self.pts[cur_mask], self.K, self.cfg.two_view)
        self._toc("init", t1)
        if tv.ok:
            return self._make_map(tv, img, t_ns, index, bscore, res.brightness.a,
                                  res.brightness.b, ref_pts)
        static = (tv.status is TwoViewStatus.LOW_PARALLAX
                  and tv.median_flow_px < self.cfg.static_flow_px)
        too_old = index - self.init_ref_index >= self.cfg.init_max_frames
        if too_old or len(self.ids) < self.cfg.two_view.min_points:
            self.prev_img = None
            old_ref = self.init_ref_index
            fr = self._start(img, t_ns, index, bscore, blurred, event=f"init_failed:"
                             f"{tv.status.value}", keep_tracks=too_old)
            if static:  # the camera did not move: the old reference shares this pose
                self.recs[old_ref].same_as = index
            return fr
        fr = self._record(index, t_ns, PoseStatus.LOST, T_hold, -1, 0, False, blurred,
                          bscore, res.brightness.a, res.brightness.b)
        if static:
            self.recs[-1].same_as = self.init_ref_index
        return fr

    def _make_map(self, tv: TwoViewResult, img: U8, t_ns: int, index: int, bscore: float,
                  a: float, b: float, ref_pts: F64) -> FrameResult:
        # new segment; link it to the global frame through the last known pose
        R_g, t_g, s_g = np.eye(3), np.zeros(3), 1.0
        if self.segments:
            ref_rec = self.recs[self.init_ref_index]
            T_wc_ref = invert_T(ref_rec.T_cam_ref if ref_rec.ref_kf < 0 else
                                ref_rec.T_cam_ref @ self.seg.map.keyframes[
                                    ref_rec.ref_kf].T_cam_world)
            sg = self.seg
            R_g = sg.R @ T_wc_ref[:3, :3]
            t_g = sg.s * sg.R @ T_wc_ref[:3, 3] + sg.t
            # keep the previous segment's typical speed (median over its recent moving
            # frames): |t| = 1 map unit spans (index - ref) frames. A guess, logged as such;
            # --camera-height corrects it from the ground plane.
            moving = [v for v in self.speed_hist if v > 0]
            speed = float(np.median(moving)) if moving else 1.0
            s_g = max(speed * (index - self.init_ref_index), 1e-6)
            self.events.append((index, f"segment_scale_guess:{s_g:.4g}"))
        self.segments.append(_Segment(Mapper(self.K, self.cfg.mapper()), R_g, t_g, s_g))
        self.kf_images = {}
        m = self.seg.map
        ref_mask = np.isin(self.init_ref_ids, self.ids)
        ref_ids = self.init_ref_ids[ref_mask]
        cur_mask = np.isin(self.ids, self.init_ref_ids)
        T0 = np.eye(4)
        T1 = tv.T_c2_c1
        kf0 = m.add_keyframe(self.init_ref_index, T0, ref_ids, ref_pts)
        m.ensure_capacity(self._next_id)
        good = tv.point_valid
        m.set_points(ref_ids[good], tv.points_c1[good])
        # the current tracks: those from ref keep first_kf = 0
        self.first_kf = np.where(cur_mask, kf0.kf_id, -1)
        fu = np.zeros_like(self.pts)
        fu[cur_mask] = ref_pts
        self.first_uv = fu
        # keep only tracks that were seen in the reference
        self._keep(cur_mask)
        kf1 = m.add_keyframe(index, T1, self.ids, self.pts)
        self.seg.mapper.local_ba()
        T1 = m.keyframes[kf1.kf_id].T_cam_world
        self.initialised = True
        # poses of the frames between ref and now: PnP on their stored tracks
        for fi, ids_f, pts_f in self.init_history:
            if fi in (self.init_ref_index, index):
                continue
            has = m.points_of(ids_f)
            rec = self.recs[fi]
            if int(has.sum()) >= self.cfg.min_pnp_inliers:
                r = solve_pnp(m.xyz[ids_f[has]], pts_f[has], self.K, T_guess=T0,
                              ransac_thresh_px=self.cfg.pnp_thresh_px, seed=self.cfg.seed)
                if r.ok:
                    rec.status = PoseStatus.TRACKED
                    rec.same_as = -1
                    rec.ref_kf = 0
                    rec.segment = len(self.segments) - 1
                    rec.T_cam_ref = r.T_cam_world.copy()
                    rec.obs_ids, rec.obs_uv = ids_f[has][r.inliers], pts_f[has][r.inliers]
                    continue
            rec.status = PoseStatus.INTERPOLATED
            rec.same_as = -1
            rec.ref_kf = -2  # to interpolate in finish()
            rec.segment = len(self.segments) - 1
        ref_rec = self.recs[self.init_ref_index]
        ref_rec.status = PoseStatus.TRACKED
        ref_rec.ref_kf = 0
        ref_rec.segment = len(self.segments) - 1
        ref_rec.T_cam_ref = np.eye(4)
        n_frames = max(index - self.init_ref_index, 1)
        # per-frame velocity from the init baseline (geometric mean of the motion)
        xi = SE3.from_matrix(T1).log() / n_frames
        self.velocity = se3_exp(np.asarray(xi, dtype=np.float64))
        self.T_last = T1.copy()
        self.last_kf_frame = index
        self._detect(img, kf1.kf_id)
        self._height_reading(kf1.kf_id)
        self._init_kf_obs_fix(kf1.kf_id)
        self.kf_images[kf0.kf_id] = AnchorImage.of(self.init_ref_img)
        self._store_kf_image(kf1.kf_id, img)
        return self._record(index, t_ns, PoseStatus.TRACKED, T1, kf1.kf_id,
                            int(good.sum()), True, False, bscore, a, b,
                            f"init_ok:ref={self.init_ref_index}")

    def _init_kf_obs_fix(self, kf_id: int) -> None:
        """Re-record the keyframe observations after detection added tracks."""
        kf = self.seg.map.keyframes[kf_id]
        kf.track_ids = self.ids.copy()
        kf.uv = self.pts.copy()

    # ------------------------------------------------------------------ tracking
    def _track_step(self, img: U8, t_ns: int, index: int, bscore: float,
                    blurred: bool) -> FrameResult:
        if self.prev_img is None or self.T_last is None:
            raise RuntimeError("VoPipeline: tracking step without a previous frame")
        cfg = self.cfg
        m = self.seg.map
        steps = self.gap + 1
        V = np.linalg.matrix_power(self.velocity, steps)
        if self.gap > 0 and cfg.direct_prior:
            # resuming after blur: direct alignment to the last good image gives the prior
            d = self._direct(img, V)
            if d is not None:
                V = d
                self.events.append((index, "direct_prior"))
        T_pred = V @ self.T_last
        # motion prior for KLT: project map points; rotation-only homography for the rest
        t0 = self._tic()
        has = m.points_of(self.ids)
        xyz = np.zeros((len(self.ids), 3))
        xyz[has] = m.xyz[self.ids[has]]
        pred = predict_tracks(self.K, T_pred, V[:3, :3], self.pts, xyz, has, img.shape)
        self._toc("predict", t0)
        t0 = self._tic()
        res = self.klt.track(self.prev_img, img, self.pts, pts_pred=pred, wide=self.gap > 0,
                             K=self.K)
        self._toc("klt", t0)
        ok = res.ok
        use = ok & has
        t0 = self._tic()
        pnp = solve_pnp(m.xyz[self.ids[use]], res.pts[use], self.K, T_guess=T_pred,
                        ransac_thresh_px=cfg.pnp_thresh_px, min_inliers=cfg.min_pnp_inliers,
                        huber_px=cfg.huber_px, seed=cfg.seed)
        self._toc("pnp", t0)
        a, b = res.brightness.a, res.brightness.b
        if not pnp.ok:
            if blurred:
                self.gap += 1
                return self._record(index, t_ns, PoseStatus.INTERPOLATED, T_pred, -1, 0,
                                    False, True, bscore, a, b)
            # features scarce: direct alignment to the last good image as the fallback
            d = self._direct(img, V) if cfg.direct_fallback else None
            if d is not None:
                return self._direct_fallback(img, t_ns, index, bscore, d, a, b)
            # lost: start a new segment from this frame
            self.T_last = T_pred
            self.prev_img = None
            return self._start(img, t_ns, index, bscore, blurred,
                               event=f"lost:{pnp.status.value}")
        T_cw = pnp.T_cam_world
        n_inl = int(pnp.inliers.sum())
        obs = (self.ids[use][pnp.inliers].copy(), res.pts[use][pnp.inliers].copy())
        kf_ref = len(m.keyframes) - 1
        if blurred:
            # blurred frame: pose only; keep the last good image as the tracking reference
            self.gap += 1
            return self._record(index, t_ns, PoseStatus.TRACKED, T_cw, kf_ref, n_inl, False,
                                True, bscore, a, b, obs=obs)
        # commit the tracks: drop KLT failures and PnP outliers
        bad = np.zeros(len(self.ids), dtype=bool)
        bad[np.flatnonzero(use)[~pnp.inliers]] = True
        keep = ok & ~bad
        self.pts = res.pts
        self._keep(keep)
        self.prev_img = img
        # velocity over the frames since the last good one
        dT = T_cw @ invert_T(self.T_last)
        if steps == 1:
            self.velocity = dT
        self.speed_hist.append(self.seg.s * float(np.linalg.norm(dT[:3, 3])) / steps)
        self.T_last = T_cw
        self.gap = 0
        self.last_good_index = index
        is_kf = self._need_keyframe(index, n_inl)
        if is_kf:
            T_cw = self._make_keyframe(index, T_cw, img)
            kf_ref = len(m.keyframes) - 1
        return self._record(index, t_ns, PoseStatus.TRACKED, T_cw, kf_ref, n_inl, is_kf,
                            False, bscore, a, b, obs=obs)

    def _direct(self, img: U8, V: F64) -> F64 | None:
        """T_cur_prev from sparse direct alignment (SE(3) + affine brightness) of ``img`` to
        the last good image, using the tracked map points as the depth; None on failure."""
        if self.prev_img is None or self.T_last is None:
            raise RuntimeError("VoPipeline: tracking step without a previous frame")
        m = self.seg.map
        has = m.points_of(self.ids)
        if int(has.sum()) < self.cfg.direct.min_pixels:
            return None
        t0 = self._tic()
        X = m.xyz[self.ids[has]]
        depth = X @ self.T_last[2, :3] + self.T_last[2, 3]
        res = align_direct(self.prev_img, img, self.pts[has], depth, self.K, T_init=V,
                           config=self.cfg.direct)
        self._toc("direct", t0)
        return res.T_cur_ref if res.ok else None

    def _direct_fallback(self, img: U8, t_ns: int, index: int, bscore: float, V: F64,
                         a: float, b: float) -> FrameResult:
        """Pose from direct alignment; re-seed the tracks by projecting the map points."""
        if self.T_last is None:
            raise RuntimeError("VoPipeline: direct fallback without a previous pose")
        m = self.seg.map
        T_cw = V @ self.T_last
        m.ensure_capacity(self._next_id)
        has = m.points_of(self.ids)
        uv, z = project(self.K, T_cw, m.xyz[self.ids])
        h, w = img.shape
        inside = has & (z > 0) & (uv[:, 0] >= 8) & (uv[:, 0] < w - 8) & (uv[:, 1] >= 8) & \
            (uv[:, 1] < h - 8)
        self.pts = np.where(inside[:, None], uv, self.pts)
        self._keep(inside)
        self.prev_img = img
        self.velocity = V if self.gap == 0 else self.velocity
        self.T_last = T_cw
        self.gap = 0
        kf_ref = len(m.keyframes) - 1
        return self._record(index, t_ns, PoseStatus.TRACKED, T_cw, kf_ref, 0, False, False,
                            bscore, a, b, event="direct_fallback")

    def _need_keyframe(self, index: int, n_inl: int) -> bool:
        m = self.seg.map
        kf = m.keyframes[-1]
        reason = keyframe_decision(self.cfg.keyframe_policy(), index - kf.frame_index, n_inl,
                                   int(m.points_of(kf.track_ids).sum()), kf.track_ids, kf.uv,
                                   self.ids, self.pts)
        return reason is not KeyframeReason.NONE

    def _make_keyframe(self, index: int, T_cw: F64, img: U8) -> F64:
        mapper = self.seg.mapper
        m = mapper.map
        if self.cfg.anchor_refine:
            t0 = self._tic()
            self.pts, drop = retrack_from_anchors(img, self.pts, self.first_kf, self.first_uv,
                                                  self.kf_images, self.cfg.anchor())
            self._keep(~drop)
            self._toc("anchor", t0)
        kf = m.add_keyframe(index, T_cw, self.ids, self.pts)
        # triangulate tracks seen in an earlier keyframe and without a point yet
        mapper.triangulate_new(kf.kf_id, self.ids, self.first_kf, self.first_uv, self.pts,
                               self._next_id)
        mapper.local_ba()
        T_cw = m.keyframes[kf.kf_id].T_cam_world.copy()
        self.T_last = T_cw
        # tracks without a first keyframe start here
        fresh = self.first_kf < 0
        self.first_kf[fresh] = kf.kf_id
        self.first_uv[fresh] = self.pts[fresh]
        self._detect(img, kf.kf_id)
        self._init_kf_obs_fix(kf.kf_id)
        self._height_reading(kf.kf_id)
        self.last_kf_frame = index
        self._store_kf_image(kf.kf_id, img)
        return T_cw

    def _store_kf_image(self, kf_id: int, img: U8) -> None:
        """Keep the keyframe images that some current track is anchored in."""
        self.kf_images[kf_id] = AnchorImage.of(img)
        used = {int(k) for k in np.unique(self.first_kf)}
        for key in list(self.kf_images):
            if key not in used:
                del self.kf_images[key]

    def _height_reading(self, kf_id: int) -> None:
        if self.cfg.camera_height_m is None:
            return
        t0 = self._tic()
        m = self.seg.map
        kf = m.keyframes[kf_id]
        has = m.points_of(kf.track_ids)
        self.heights.append(height_at_keyframe(
            kf.frame_index, kf.T_cam_world, m.xyz[kf.track_ids[has]], self.cfg.camera_height_m,
            segment_scale=self.seg.s, seed=self.cfg.seed))
        self._toc("scale", t0)

    # ------------------------------------------------------------------ output
    def _final_refine(self, m: VoMap, T_cw: F64, ids: I64, uv: F64) -> F64:
        """Motion-only Huber refinement of a non-keyframe pose against the final map."""
        has = m.points_of(ids)
        if int(has.sum()) < self.cfg.min_pnp_inliers:
            return T_cw
        X = m.xyz[ids[has]]
        T = refine_pose_huber(T_cw, X, uv[has], self.K, huber_px=self.cfg.huber_px,
                              iterations=5)
        proj, z = project(self.K, T, X)
        err = np.linalg.norm(proj - uv[has], axis=1)
        if not np.all(np.isfinite(T)) or float(np.median(err)) > self.cfg.pnp_thresh_px:
            return T_cw
        return T

    def _all_timings(self) -> dict[str, float]:
        out = dict(self.timings)
        for sg in self.segments:
            for k, v in sg.mapper.timings.items():
                out[k] = out.get(k, 0.0) + v
        return out

    def finish(self) -> VoOutput:
        """Compose final poses from the refined keyframes; fill interpolated/lost frames."""
        n = len(self.recs)
        T_wc = np.zeros((n, 4, 4))
        known = np.zeros(n, dtype=bool)
        for i, r in enumerate(self.recs):
            if r.ref_kf == -2:
                continue
            sg = self.segments[r.segment] if 0 <= r.segment < len(self.segments) else None
            if r.ref_kf >= 0 and sg is not None:
                T_cw = r.T_cam_ref @ sg.map.keyframes[r.ref_kf].T_cam_world
                if self.cfg.final_refine and r.obs_ids is not None and r.obs_uv is not None:
                    T_cw = self._final_refine(sg.map, T_cw, r.obs_ids, r.obs_uv)
            else:
                T_cw = r.T_cam_ref
            Twc = invert_T(T_cw)
            if sg is not None:
                Twc[:3, 3] = sg.s * sg.R @ Twc[:3, 3] + sg.t
                Twc[:3, :3] = sg.R @ Twc[:3, :3]
            T_wc[i] = Twc
            known[i] = r.status is PoseStatus.TRACKED or r.ref_kf >= 0
        statuses = [r.status for r in self.recs]
        # static frames before an initialisation take the pose of the frame they match
        for i, r in enumerate(self.recs):
            j, hops = r.same_as, 0
            while j >= 0 and self.recs[j].same_as >= 0 and hops < n:
                j, hops = self.recs[j].same_as, hops + 1
            if r.same_as >= 0 and j >= 0 and statuses[j] is PoseStatus.TRACKED:
                T_wc[i] = T_wc[j]
                statuses[i] = PoseStatus.TRACKED
        anchor = np.flatnonzero([s is PoseStatus.TRACKED for s in statuses])
        if len(anchor):
            T_wc = _fill_interpolated(T_wc, statuses, anchor)
        # metric scale from the camera height: scale each increment (smoothed per keyframe)
        frame_scale = np.ones(n)
        if self.cfg.camera_height_m is not None:
            frame_scale = smooth_scales(self.heights, n, self.cfg.scale_half_window)
            p = T_wc[:, :3, 3].copy()
            q = p.copy()
            q[0] = p[0] * frame_scale[0]
            for i in range(1, n):
                q[i] = q[i - 1] + 0.5 * (frame_scale[i] + frame_scale[i - 1]) * (p[i] - p[i - 1])
            T_wc[:, :3, 3] = q
        pts = []
        g_scale = float(np.median(frame_scale))
        for sg in self.segments:
            _, X = sg.map.all_points()
            pts.append(g_scale * (sg.s * X @ sg.R.T + sg.t))
        frames = list(self.frames)
        for i, fr in enumerate(frames):
            if fr.status is not statuses[i]:
                frames[i] = FrameResult(fr.index, fr.t_ns, statuses[i], T_wc[i], fr.segment,
                                        fr.n_tracks, fr.n_inliers, fr.is_keyframe, fr.blurred,
                                        fr.blur_score, fr.brightness_a, fr.brightness_b,
                                        fr.event)
        kf_idx = np.array([i for i, f in enumerate(frames) if f.is_keyframe], dtype=np.int64)
        return VoOutput(np.array(self.stamps, dtype=np.int64), T_wc, frames, kf_idx,
                        np.vstack(pts) if pts else np.zeros((0, 3)), list(self.heights),
                        frame_scale, list(self.events), self._all_timings())


def _fill_interpolated(T_wc: F64, statuses: list[PoseStatus], anchor: NDArray[np.intp]) -> F64:
    """Interpolate non-tracked frames between tracked neighbours (SLERP + linear); hold the
    nearest tracked pose at the ends (those frames keep their LOST status)."""
    from scipy.spatial.transform import Rotation, Slerp

    out = T_wc.copy()
    n = len(statuses)
    rots = Rotation.from_matrix(T_wc[anchor, :3, :3])
    slerp = Slerp(anchor.astype(float), rots) if len(anchor) >= 2 else None
    for i in range(n):
        if statuses[i] is PoseStatus.TRACKED:
            continue
        j = int(np.searchsorted(anchor, i))
        if 0 < j < len(anchor) and slerp is not None:
            i0, i1 = anchor[j - 1], anchor[j]
            al = (i - i0) / (i1 - i0)
            out[i] = np.eye(4)
            out[i, :3, :3] = slerp([float(i)]).as_matrix()[0]
            out[i, :3, 3] = (1 - al) * T_wc[i0, :3, 3] + al * T_wc[i1, :3, 3]
            statuses[i] = PoseStatus.INTERPOLATED
        elif statuses[i] is PoseStatus.INTERPOLATED or not np.all(np.isfinite(out[i])) or \
                abs(np.linalg.det(out[i, :3, :3]) - 1) > 1e-3:
            out[i] = T_wc[anchor[min(j, len(anchor) - 1)]]
            statuses[i] = PoseStatus.LOST
    return out


__all__ = ["FrameResult", "PoseStatus", "VoConfig", "VoOutput", "VoPipeline"]
