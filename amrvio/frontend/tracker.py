"""Tracker stage: follows the track set from image to image and poses the camera against the map.

Per frame: a motion-model prediction (direct alignment after a gap), KLT with the prediction as
the initial flow, PnP RANSAC + Huber against the map, and, when PnP fails, the scaled relative
pose (the tracks' essential matrix, its length from the map points), the direct-alignment
fallback or a rotation-only update. The tracker owns the :class:`TrackSet`, the last good image
and the constant velocity model; it reads the map it is given and never changes it.

Poses inside are 4x4 ``T_cam_world`` arrays of the current map segment.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from amrvio.frontend.direct import DirectConfig, align_direct
from amrvio.frontend.klt import KltConfig, KltResult, KltTracker, detect_bucketed, predict_tracks, retrack_projected
from amrvio.frontend.tracking_types import Landmarks, MotionModel, Observations, TrackingReport, TrackOutcome, TrackStep
from amrvio.frontend.tracks import UNANCHORED, TrackSet
from amrvio.geometry.pnp import PnPResult, solve_pnp
from amrvio.geometry.projection import normalized_to_bearings, pixels_to_normalized, project
from amrvio.geometry.scaled_relative import ScaledRelativeConfig, ScaledRelativeResult, scaled_relative_pose
from amrvio.geometry.two_view import robust_rotation
from amrvio.types.lie import se3_matrix_inverse

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class TrackingConfig:
    """KLT front-end, PnP gates (pixels), the direct-alignment prior/fallback switches, and the
    rotation-only update: when PnP fails, a frame whose tracks one rotation explains (median
    residual under ``rotation_max_px``) is posed by that rotation about the last position;
    ``retry_unpredicted``: when PnP fails, KLT is run again from the previous positions (no
    motion prediction, deep pyramid) before the fallbacks. A blurred frame is posed against the
    last good image and normally not tracked from; one whose PnP inliers reach
    ``blurred_reference_ratio`` times those of the last good image tracks as well as a sharp
    frame and becomes the reference (None: never), so that a long blurred stretch is not
    tracked across an ever wider baseline; while a VIO bridges blurred frames with the IMU it is
    never (``bridged`` of :meth:`Tracker.track`)."""

    klt: KltConfig = field(default_factory=KltConfig)
    direct: DirectConfig = field(default_factory=DirectConfig)
    direct_prior: bool = True
    direct_fallback: bool = True
    min_pnp_inliers: int = 25
    pnp_thresh_px: float = 1.0
    huber_px: float = 2.0
    rotation_only: bool = True
    rotation_max_px: float = 1.0
    retry_unpredicted: bool = True
    blurred_reference_ratio: float | None = 0.5
    scaled_relative: ScaledRelativeConfig = field(default_factory=ScaledRelativeConfig)


class Tracker:
    """Construct with the pinhole ``K`` (3x3) of undistorted pixels. ``timings`` accumulates
    seconds per step."""

    def __init__(self, K: F64, config: TrackingConfig, seed: int) -> None:
        self.cfg = config
        self.K = K
        self.seed = seed
        self.klt = KltTracker(config.klt, seed)
        self.tracks = TrackSet()
        self.motion = MotionModel()
        self.prev_img: U8 | None = None
        self.gap = 0  # frames since the last good (committed) image
        self.gap_posed = False  # the last frame of that gap was posed by PnP
        self.ref_inliers: int | None = None  # PnP inliers of that image (None: not posed by PnP)
        self.mapped = False  # tracking against a map (else towards an initialisation reference)
        self.timings: dict[str, float] = {}

    def _toc(self, stage: str, t0: float) -> None:
        self.timings[stage] = self.timings.get(stage, 0.0) + time.perf_counter() - t0

    @property
    def started(self) -> bool:
        return self.prev_img is not None

    def stale(self, max_gap: int) -> bool:
        """At least ``max_gap`` frames since the last good image, the last of them not posed by
        PnP: the motion model no longer says where the camera is. Blurred frames that PnP poses
        from the last good image keep it fresh (a view with less texture than the recent ones can
        look blurred: the simulated corridor, without blur, had 10 such frames after a turn)."""
        return self.gap >= max_gap and not self.gap_posed

    def detect(self, img: U8, kf_id: int = UNANCHORED) -> None:
        """Top the track set up with new corners when it fell below 90 % of the target."""
        t0 = time.perf_counter()
        want = self.cfg.klt.max_features - len(self.tracks)
        if want > 0.1 * self.cfg.klt.max_features:
            self.tracks.add(detect_bucketed(img, self.tracks.pts, want, self.cfg.klt), kf_id)
        self._toc("detect", t0)

    def restart(self, img: U8, keep_tracks: bool) -> None:
        """Make ``img`` the new reference image (for a new initialisation attempt)."""
        self._new_reference(img)
        if not keep_tracks:
            self.tracks.clear()
        self.detect(img)
        self.mapped = False

    def resume(self, img: U8, T_cam_world: F64) -> None:
        """Tracking resumes at ``img`` with pose ``T_cam_world`` (relocalised); the velocity of
        before the loss is kept as the motion prior."""
        self._new_reference(img)
        self.motion.T_last = T_cam_world.copy()
        self.mapped = True

    def adopt_map_pose(self, T_cam_world: F64, velocity: F64) -> None:
        """A new map fixed the pose of the current image and the velocity."""
        self.motion.velocity = velocity
        self.motion.T_last = T_cam_world.copy()
        self.mapped = True
        self.ref_inliers = None

    def _report(self, outcome: TrackOutcome, res: KltResult | None, n_inl: int = 0,
                prior: bool = False, pnp: str | None = None) -> TrackingReport:
        a = res.brightness.a if res is not None else 1.0
        b = res.brightness.b if res is not None else 0.0
        return TrackingReport(outcome, len(self.tracks), n_inl, a, b, prior, pnp)

    def started_report(self) -> TrackingReport:
        return self._report(TrackOutcome.STARTED, None)

    def repeated_report(self) -> TrackingReport:
        return self._report(TrackOutcome.REPEATED, None)

    def track_to_reference(self, img: U8, blurred: bool) -> TrackingReport:
        """Before the map exists: KLT from the last good image; commit unless ``blurred``."""
        if self.prev_img is None:
            raise RuntimeError("Tracker: track_to_reference before restart()")
        t0 = time.perf_counter()
        res = self.klt.track(self.prev_img, img, self.tracks.pts, wide=self.gap > 0, K=self.K)
        self._toc("klt", t0)
        if blurred:
            self.gap += 1
            self.gap_posed = False
            return self._report(TrackOutcome.SKIPPED_BLURRED, res)
        self.tracks.keep(res.ok)
        self.tracks.move(res.pts[res.ok])
        self._new_reference(img)
        return self._report(TrackOutcome.INIT_TRACKED, res)

    def track(self, img: U8, blurred: bool, m: Landmarks, segment_scale: float,
              R_cur_ref: F64 | None = None, stale: bool = False, bridged: bool = False) -> TrackStep:
        """Pose ``img`` against the map ``m`` (segment units; ``segment_scale`` global units per
        segment unit, for the speed record). ``R_cur_ref``: the camera's rotation since the
        reference image by the gyro, which replaces the motion model's in the KLT prediction.
        ``stale``: the motion model is stale (:meth:`stale`, and the map search failed): no
        direct-alignment fallback, which would start from it (a robot that turned 28 degrees
        during a black-out was posed 27 degrees off, and the map grew in that frame).
        ``bridged``: a VIO bridges blurred frames with the IMU, so a blurred ``img`` never becomes
        the reference: tracks carried on from blurred images took the smoother's median scale
        error on EuRoC MH_01 over 4 IMU seeds from 0.45 % to 4.7 %. Before the VIO runs nothing
        bridges them, and the VO's rule (``blurred_reference_ratio``) holds."""
        T_last = self.motion.T_last
        if self.prev_img is None or T_last is None:
            raise RuntimeError("Tracker: track() without a previous frame")
        cfg, mot, tr = self.cfg, self.motion, self.tracks
        steps = self.gap + 1
        V = np.linalg.matrix_power(mot.velocity, steps)
        if R_cur_ref is not None:
            V = V.copy()
            V[:3, :3] = R_cur_ref
        prior = False
        if self.gap > 0 and cfg.direct_prior:
            # resuming after blur: direct alignment to the last good image gives the prior
            d = self._direct(img, V, m)
            if d is not None:
                V, prior = d, True
        T_pred = V @ T_last
        t0 = time.perf_counter()
        has = m.points_of(tr.ids)
        xyz = np.zeros((len(tr.ids), 3))
        xyz[has] = m.xyz[tr.ids[has]]
        pred = predict_tracks(self.K, T_pred, V[:3, :3], tr.pts, xyz, has, img.shape)
        self._toc("predict", t0)
        res, use, pnp = self._klt_pnp(img, pred, self.gap > 0, has, m, T_pred)
        if not pnp.ok and not blurred and cfg.retry_unpredicted:
            # the motion model can be wrong (a jerky hand, a repeated or dropped frame): track
            # again from where the points were, with the deep pyramid
            res2, use2, pnp2 = self._klt_pnp(img, None, True, has, m, T_last)
            if pnp2.ok:
                res, use, pnp = res2, use2, pnp2
        if not pnp.ok:
            if blurred:
                self.gap += 1
                self.gap_posed = False
                return TrackStep(self._report(TrackOutcome.PREDICTED, res, 0, prior,
                                              pnp.status.value), T_pred, None)
            rel = self._scaled_relative(res, has, m, T_last) if cfg.scaled_relative.enabled else None
            if rel is not None and rel.ok:
                return self._relative_step(img, rel, res, prior, pnp.status.value, steps,
                                           segment_scale)
            # features scarce: direct alignment to the last good image as the fallback
            d = self._direct(img, V, m) if cfg.direct_fallback and not stale else None
            if d is not None:
                return self._direct_fallback(img, d, m, res, prior)
            R = self._rotation(res) if cfg.rotation_only else None
            if R is not None:
                return self._rotation_step(img, R, res, prior, pnp.status.value)
            mot.T_last = T_pred
            return TrackStep(self._report(TrackOutcome.LOST, res, 0, prior, pnp.status.value),
                             T_pred, None)
        T_cw = pnp.T_cam_world
        n_inl = int(pnp.inliers.sum())
        obs = Observations(tr.ids[use][pnp.inliers].copy(), res.pts[use][pnp.inliers].copy())
        ratio, ref = None if bridged else cfg.blurred_reference_ratio, self.ref_inliers
        if blurred and (ratio is None or ref is None or n_inl < ratio * ref):
            # pose only; keep the last good image as the tracking reference
            self.gap += 1
            self.gap_posed = True
            return TrackStep(self._report(TrackOutcome.TRACKED_BLURRED, res, n_inl, prior,
                                          pnp.status.value), T_cw, obs)
        # commit the tracks: drop KLT failures and PnP outliers
        bad = np.zeros(len(tr.ids), dtype=bool)
        bad[np.flatnonzero(use)[~pnp.inliers]] = True
        self._commit(img, res, res.ok & ~bad, T_cw, steps, segment_scale, n_inl)
        outcome = TrackOutcome.BLURRED_REFERENCE if blurred else TrackOutcome.TRACKED
        return TrackStep(self._report(outcome, res, n_inl, prior, pnp.status.value), T_cw, obs)

    def _commit(self, img: U8, res: KltResult, keep: NDArray[np.bool_], T_cw: F64, steps: int,
                segment_scale: float, n_pnp: int | None) -> None:
        """Move the tracks into ``img`` and keep ``keep``; ``T_cw`` becomes the last pose
        (``steps`` frames after the previous one) and updates the motion model; ``n_pnp``: the
        PnP inliers of ``img`` (None: posed otherwise)."""
        mot, tr = self.motion, self.tracks
        if mot.T_last is None:
            raise RuntimeError("Tracker: commit without a previous pose")
        tr.move(res.pts)
        tr.keep(keep)
        dT = T_cw @ se3_matrix_inverse(mot.T_last)
        if steps == 1:
            mot.velocity = dT
        mot.speeds.append(segment_scale * float(np.linalg.norm(dT[:3, 3])) / steps)
        mot.T_last = T_cw
        self._new_reference(img, n_pnp)

    def _new_reference(self, img: U8, n_pnp: int | None = None) -> None:
        """``img`` becomes the image the next frame is tracked from (no gap since); ``n_pnp``:
        its PnP inliers (None: not posed by PnP), which a blurred frame must approach to take
        its place."""
        self.prev_img = img
        self.gap, self.gap_posed = 0, False
        self.ref_inliers = n_pnp

    def _scaled_relative(self, res: KltResult, has: NDArray[np.bool_], m: Landmarks,
                         T_last: F64) -> ScaledRelativeResult:
        """The step from the last committed image by the tracks' essential matrix, its length
        from the map points (segment units)."""
        tr = self.tracks
        ok = res.ok
        xyz = np.zeros((int(ok.sum()), 3))
        has_ok = has[ok]
        X = m.xyz[tr.ids[ok][has_ok]]
        xyz[has_ok] = X @ T_last[:3, :3].T + T_last[:3, 3]
        focal = 0.5 * (self.K[0, 0] + self.K[1, 1])
        t0 = time.perf_counter()
        rel = scaled_relative_pose(pixels_to_normalized(tr.pts[ok], self.K),
                                   pixels_to_normalized(res.pts[ok], self.K), has_ok, xyz, focal,
                                   replace(self.cfg.scaled_relative, seed=self.seed))
        self._toc("scaled_relative", t0)
        # back to all tracks
        inl = np.zeros(len(ok), dtype=bool)
        inl[ok] = rel.track_inliers
        pts = np.zeros(len(ok), dtype=bool)
        pts[ok] = rel.point_inliers
        return replace(rel, track_inliers=inl, point_inliers=pts)

    def _relative_step(self, img: U8, rel: ScaledRelativeResult, res: KltResult, prior: bool,
                       pnp: str, steps: int, segment_scale: float) -> TrackStep:
        """Pose from :meth:`_scaled_relative`; the essential matrix's inliers are committed."""
        T_last = self.motion.T_last
        if T_last is None:
            raise RuntimeError("Tracker: relative step without a previous pose")
        T_cw = rel.T_cur_prev @ T_last
        tr = self.tracks
        obs = Observations(tr.ids[rel.point_inliers].copy(), res.pts[rel.point_inliers].copy())
        self._commit(img, res, res.ok & rel.track_inliers, T_cw, steps, segment_scale, None)
        n = int(rel.point_inliers.sum())
        return TrackStep(self._report(TrackOutcome.SCALED_RELATIVE, res, n, prior, pnp), T_cw,
                         obs)

    def _klt_pnp(self, img: U8, pred: F64 | None, wide: bool, has: NDArray[np.bool_],
                 m: Landmarks, T_guess: F64) -> tuple[KltResult, NDArray[np.bool_], PnPResult]:
        """KLT of the tracks into ``img`` (from ``pred``, or from where they were) and PnP of
        those with a map point."""
        if self.prev_img is None:
            raise RuntimeError("Tracker: KLT without a previous image")
        tr, t0 = self.tracks, time.perf_counter()
        res = self.klt.track(self.prev_img, img, tr.pts, pts_pred=pred, wide=wide, K=self.K)
        self._toc("klt", t0)
        use, lost = res.ok & has, has & ~res.ok
        pnp = self._pnp(m, res, use, T_guess)
        if pnp.ok and self.cfg.klt.guided_retrack and int(lost.sum()) > int(pnp.inliers.sum()):
            t0 = time.perf_counter()
            res2 = retrack_projected(self.klt, self.prev_img, img, res, lost, m.xyz[tr.ids[lost]], self.K,
                                     pnp.T_cam_world, tr.pts)
            self._toc("klt", t0)
            pnp2 = self._pnp(m, res2, res2.ok & has, pnp.T_cam_world)
            if pnp2.ok and int(pnp2.inliers.sum()) > int(pnp.inliers.sum()):
                return res2, res2.ok & has, pnp2
        return res, use, pnp

    def _pnp(self, m: Landmarks, res: KltResult, use: NDArray[np.bool_], T_guess: F64) -> PnPResult:
        cfg, t0 = self.cfg, time.perf_counter()
        pnp = solve_pnp(m.xyz[self.tracks.ids[use]], res.pts[use], self.K, T_guess=T_guess,
                        ransac_thresh_px=cfg.pnp_thresh_px, min_inliers=cfg.min_pnp_inliers,
                        huber_px=cfg.huber_px, seed=self.seed)
        self._toc("pnp", t0)
        return pnp

    def is_repeat(self, img: U8) -> bool:
        """True when ``img`` repeats the last tracked image exactly (a recorder that duplicates
        frames): it carries no new view."""
        prev = self.prev_img
        return prev is not None and prev.shape == img.shape and \
            bool(np.array_equal(prev[::4, ::4], img[::4, ::4])) and bool(np.array_equal(prev, img))

    def _rotation(self, res: KltResult) -> F64 | None:
        """R_cur_prev when one rotation explains the tracked flow, else None."""
        ok = res.ok
        if int(ok.sum()) < self.cfg.min_pnp_inliers:
            return None
        b0 = normalized_to_bearings(pixels_to_normalized(self.tracks.pts[ok], self.K))
        b1 = normalized_to_bearings(pixels_to_normalized(res.pts[ok], self.K))
        R, resid_deg = robust_rotation(b0, b1)
        focal = 0.5 * (self.K[0, 0] + self.K[1, 1])
        if float(np.median(np.radians(resid_deg))) * focal > self.cfg.rotation_max_px:
            return None
        return R

    def _rotation_step(self, img: U8, R: F64, res: KltResult, prior: bool,
                       pnp: str) -> TrackStep:
        """Pose by rotation about the last camera centre; tracks committed."""
        T_last = self.motion.T_last
        if T_last is None:
            raise RuntimeError("Tracker: rotation update without a previous pose")
        dT = np.eye(4)
        dT[:3, :3] = R
        T_cw = dT @ T_last
        tr = self.tracks
        tr.move(res.pts)
        tr.keep(res.ok)
        self.motion.velocity = dT
        self.motion.T_last = T_cw
        self._new_reference(img)
        return TrackStep(self._report(TrackOutcome.ROTATION, res, 0, prior, pnp), T_cw, None)

    def _direct(self, img: U8, V: F64, m: Landmarks) -> F64 | None:
        """T_cur_prev from sparse direct alignment (SE(3) + affine brightness) of ``img`` to the
        last good image, with the tracked map points as depth; None on failure."""
        if self.prev_img is None or self.motion.T_last is None:
            raise RuntimeError("Tracker: direct alignment without a previous frame")
        tr = self.tracks
        has = m.points_of(tr.ids)
        if int(has.sum()) < self.cfg.direct.min_pixels:
            return None
        t0, T_last = time.perf_counter(), self.motion.T_last
        depth = m.xyz[tr.ids[has]] @ T_last[2, :3] + T_last[2, 3]
        res = align_direct(self.prev_img, img, tr.pts[has], depth, self.K, T_init=V,
                           config=self.cfg.direct)
        self._toc("direct", t0)
        return res.T_cur_ref if res.ok else None

    def _direct_fallback(self, img: U8, V: F64, m: Landmarks, res: KltResult,
                         prior: bool) -> TrackStep:
        """Pose from direct alignment; the map points' tracks are re-seeded by projecting them,
        and the tracks without a point keep what KLT found for them (they would be the next
        keyframe's new points: dropping them, the phone lost its map after 2-5 such frames)."""
        if self.motion.T_last is None:
            raise RuntimeError("Tracker: direct fallback without a previous pose")
        tr = self.tracks
        T_cw = V @ self.motion.T_last
        m.ensure_capacity(tr.next_id)
        has = m.points_of(tr.ids)
        uv, z = project(self.K, T_cw, m.xyz[tr.ids])
        h, w = img.shape
        inside = has & (z > 0) & (uv[:, 0] >= 8) & (uv[:, 0] < w - 8) & (uv[:, 1] >= 8) & \
            (uv[:, 1] < h - 8)
        free = ~has & res.ok
        tr.move(np.where(inside[:, None], uv, np.where(free[:, None], res.pts, tr.pts)))
        tr.keep(inside | free)
        self.motion.velocity = V if self.gap == 0 else self.motion.velocity
        self.motion.T_last = T_cw
        self._new_reference(img)
        return TrackStep(self._report(TrackOutcome.DIRECT, res, 0, prior), T_cw, None)


__all__ = ["Tracker", "TrackingConfig"]
