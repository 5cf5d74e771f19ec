"""The per-frame diagnostics stage: ``FrameDiagnostics(config).process(...) -> FrameHealth``.

One call per frame, in time order. The stage keeps only what it needs between frames: the
previous image and its KLT tracks (for the exposure fit on corresponding pixels and for parallax
against the parallax reference frame), the gyro rotation since that reference, a short IMU
buffer (for the exposure-window smear and the excitation window) and the blur reference.

Blur: ``blur.var_lap`` is the seed's Var(Delta I) of the raw image. The scene-normalised
``blur.ratio`` divides the contrast-normalised :func:`~amrvio.diagnostics.blur.blur_score` (the
VO's), Var(Delta I) / Var(I), by the median of recent sharp frames: an exposure step scales both
variances by a^2, so it does not read as blur. ``blur.flag`` is set when that ratio is low or
when the predicted smear (rotation from the gyro, plus translation when the caller passes a
:class:`~amrvio.diagnostics.smear.CameraMotion`) exceeds ``smear_flag_px``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.blur import BlurScorer, BlurScorerConfig, blur_score, var_laplacian
from amrvio.diagnostics.excitation import Excitation, ExcitationConfig, compute_excitation
from amrvio.diagnostics.exposure import (
    ExposureChange,
    ExposureConfig,
    ExposureFrame,
    fit_exposure_same_pixel,
    fit_exposure_tracked,
    prepare_exposure_frame,
    saturated_fraction,
)
from amrvio.diagnostics.health import (
    EXCITATION_COLUMNS,
    HEALTH_COLUMNS,
    BlurHealth,
    ExposureHealth,
    FrameHealth,
    ParallaxHealth,
    health_rows,
)
from amrvio.diagnostics.imu_vo_velocity import imu_velocity
from amrvio.diagnostics.parallax import (
    ParallaxReference,
    ParallaxReferenceConfig,
    RotationSource,
    low_parallax,
    parallax_reference_due,
)
from amrvio.diagnostics.smear import (
    CameraMotion,
    SmearPrediction,
    integrate_gyro,
    max_exposure_for_smear,
    predict_smear,
    predict_smear_from_rates,
)
from amrvio.diagnostics.tracks import (
    TrackFrame,
    TrackingConfig,
    detection_mask,
    diagnostics_tracker,
    prepare_track_frame,
    track_between,
    tracker_mask,
)
from amrvio.diagnostics.vo_motion import MotionHistory, motion_at_pose
from amrvio.errors import ShapeError
from amrvio.tracking.detect import detect_corners
from amrvio.tracking.lk import LkTracker
from amrvio.types.camera import CameraModel, PinholeCamera
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


def _tracking() -> TrackingConfig:
    # wide images are tracked on the first pyramid level narrower than 1000 px (speed, large
    # motions); the exposure fit still samples the full-resolution frames
    t = TrackingConfig()
    return replace(t, lk=replace(t.lk, max_width_px=1000))


@dataclass(frozen=True, slots=True)
class DiagnosticsConfig:
    """Settings of :class:`FrameDiagnostics`.

    ``tracking``: feature detection and LK (wide images tracked on a reduced pyramid level).
    ``reference``: when the parallax reference frame is renewed and low parallax flagged.
    ``smear_bound_px``: the exposure advice keeps the predicted max smear under it.
    ``smear_flag_px``: a predicted max smear above it sets the blur flag.
    ``assumed_exposure_s``: used for the smear when a frame carries no exposure time (None: no
    prediction then). ``excitation_window_s``: IMU window of the excitation record.
    """

    blur: BlurScorerConfig = field(default_factory=BlurScorerConfig)
    exposure: ExposureConfig = field(default_factory=ExposureConfig)
    tracking: TrackingConfig = field(default_factory=_tracking)
    reference: ParallaxReferenceConfig = field(default_factory=ParallaxReferenceConfig)
    excitation: ExcitationConfig = field(default_factory=ExcitationConfig)
    smear_bound_px: float = 2.0
    smear_flag_px: float = 4.0
    assumed_exposure_s: float | None = None
    excitation_window_s: float = 2.0


@dataclass(frozen=True, slots=True, eq=False)
class _Previous:
    """What the stage keeps of the previous frame."""

    image: U8
    track: TrackFrame
    exposure: ExposureFrame
    t_ns: int


class _ImuBuffer:
    """Recent IMU samples (deduplicated by stamp), trimmed to a time span."""

    def __init__(self, span_ns: int) -> None:
        self.span_ns = span_ns
        self.t = np.zeros(0, np.int64)
        self.g = np.zeros((0, 3))
        self.a = np.zeros((0, 3))

    def add(self, imu: ImuData) -> None:
        if len(imu) == 0:
            return
        t_new = np.asarray(imu.stamps_ns, np.int64)
        last = self.t[-1] if self.t.size else np.iinfo(np.int64).min
        keep = t_new > last
        self.t = np.concatenate([self.t, t_new[keep]])
        self.g = np.concatenate([self.g, np.asarray(imu.gyro_rad_s)[keep]])
        self.a = np.concatenate([self.a, np.asarray(imu.accel_m_s2)[keep]])
        cut = int(np.searchsorted(self.t, self.t[-1] - self.span_ns, side="left"))
        if cut > 0:
            self.t, self.g, self.a = self.t[cut:], self.g[cut:], self.a[cut:]

    def window(self, t0_ns: int, t1_ns: int) -> ImuData:
        lo = int(np.searchsorted(self.t, t0_ns, side="left"))
        hi = int(np.searchsorted(self.t, t1_ns, side="right"))
        return ImuData(self.t[lo:hi], self.g[lo:hi], self.a[lo:hi])


class FrameDiagnostics:
    """Per-frame health stage. Collaborators in the constructor, one call: :meth:`process`.

    ``camera``: for the smear field and parallax (without it a pinhole with f = image width is
    assumed for parallax, and no smear is predicted). ``T_body_cam``: camera pose in the IMU frame
    (its rotation maps gyro rates into the camera). ``inverse_response``: (256,) DSO G^-1; the
    exposure fit then runs on linearised intensities so that EV is the true exposure ratio.
    ``gyro_bias_rad_s``: subtracted from the gyro.
    """

    def __init__(
        self,
        config: DiagnosticsConfig | None = None,
        camera: CameraModel | None = None,
        T_body_cam: SE3 | None = None,
        inverse_response: NDArray[np.floating] | None = None,
        gyro_bias_rad_s: F64 | None = None,
    ) -> None:
        self.config = config or DiagnosticsConfig()
        self.camera = camera
        self.T_body_cam = T_body_cam
        self.inverse_response = inverse_response
        self.gyro_bias = gyro_bias_rad_s
        self._blur = BlurScorer(self.config.blur)
        span = max(self.config.excitation_window_s, 1.0)
        self._imu = _ImuBuffer(int(span * 1e9))
        self._trackers: dict[int, LkTracker] = {}  # by image width
        self._poses = MotionHistory()  # the VO's poses, for the translational smear
        self._prev: _Previous | None = None
        self._ref = ParallaxReference()
        self._index = 0

    @property
    def R_cam_body(self) -> F64 | None:
        """The rotation of body (IMU) vectors into the camera frame (None without an extrinsic)."""
        return None if self.T_body_cam is None else np.asarray(self.T_body_cam.rot.matrix().T)

    # ------------------------------------------------------------------------------------------
    def _lk(self, width: int) -> LkTracker:
        if width not in self._trackers:
            self._trackers[width] = diagnostics_tracker(self.config.tracking, width)
        return self._trackers[width]

    def _camera_for(self, shape: tuple[int, int]) -> CameraModel:
        if self.camera is not None:
            return self.camera
        h, w = shape
        return PinholeCamera(w, h, float(w), float(w), (w - 1) / 2.0, (h - 1) / 2.0)

    def _smear(self, t_ns: int, exposure_s: float | None, motion: CameraMotion | None,
               ) -> tuple[SmearPrediction | None, float | None]:
        T = exposure_s if exposure_s is not None else self.config.assumed_exposure_s
        if self.camera is None or T is None:
            return None, None
        imu_t = self._imu.t
        covered = (imu_t.size >= 2 and t_ns - int(T * 0.5e9) >= imu_t[0]
                   and t_ns + int(T * 0.5e9) <= imu_t[-1] + 20_000_000)
        if covered:
            pred = predict_smear(self.camera, imu_t, self._imu.g, t_ns, T, self.R_cam_body,
                                 self.gyro_bias, motion=motion)
        elif motion is not None and motion.omega_cam_rad_s is not None:
            pred = predict_smear_from_rates(self.camera, motion, T)
        else:
            return None, None
        advice = None
        if pred.max_px > self.config.smear_bound_px:
            advice = max_exposure_for_smear(self.camera, pred.omega_cam_rad_s,
                                            self.config.smear_bound_px, motion=motion)
        return pred, advice

    def observe_pose(self, t_ns: int, key: int | None, segment: int | None) -> None:
        """The frame at ``t_ns`` was tracked in map ``segment`` (``key``: the caller's handle on
        its pose, see :meth:`with_vo_motion`; None: it has no pose)."""
        self._poses.observe(t_ns, key, segment)

    def with_vo_motion(self, health: FrameHealth, pose_of: Callable[[int], F64 | None],
                       points_world: F64) -> FrameHealth:
        """``health`` with the smear's translational part, from the frames given to
        :meth:`observe_pose` (up to this frame's; ``pose_of(key)``: a frame's ``T_cam_world``
        as the map now has it) and the (N, 3) map points of the live tracks (see
        :mod:`~amrvio.diagnostics.vo_motion`); unchanged without a camera or a motion."""
        if self.camera is None:
            return health
        T_bc = self.T_body_cam
        velocity = None if T_bc is None else imu_velocity(
            ImuData(self._imu.t, self._imu.g, self._imu.a), self.R_cam_body, T_bc.t, self.gyro_bias)
        motion = self._poses.camera_motion(health.t_ns, pose_of, points_world, self.camera, velocity)
        return health if motion is None else self.with_motion(health, motion)

    def with_pose_motion(self, health: FrameHealth, T_cam_world: F64, v_cam: F64,
                         points_world: F64) -> FrameHealth:
        """``health`` with the smear's translational part from a camera at ``T_cam_world``
        moving at ``v_cam`` (camera frame) among the (N, 3) ``points_world``, all in one
        world's units (the VIO's prediction, in metres); unchanged without a camera or when too
        few of the points are in view."""
        if self.camera is None:
            return health
        motion = motion_at_pose(np.asarray(T_cam_world, dtype=np.float64), points_world,
                                self.camera, np.asarray(v_cam, dtype=np.float64), None)
        return health if motion is None else self.with_motion(health, motion)

    def with_motion(self, health: FrameHealth, motion: CameraMotion) -> FrameHealth:
        """``health`` of a frame already processed, its smear predicted again with the camera's
        translation (``motion``, known once the frame was tracked) added to the rotation. The
        IMU samples of the frame must still be held (call before the next frame)."""
        smear, advice = self._smear(health.t_ns, health.exposure.exposure_s, motion)
        if smear is None:
            return health
        b = health.blur
        blurred = b.ratio < self.config.blur.blur_ratio  # BlurScorer's own rule
        blur = replace(
            b, flag=bool(blurred or smear.max_px > self.config.smear_flag_px),
            smear_px_pred=smear.max_px, smear_px_mean=smear.mean_px,
            smear_px_rotation=smear.rotation_max_px, smear_px_translation=smear.translation_max_px,
            max_exposure_s=advice)
        return replace(health, blur=blur)

    def _new_reference(self, track: TrackFrame, expo_frame: ExposureFrame) -> None:
        t = track.image
        mask = tracker_mask(detection_mask(expo_frame.bad), t.lk.shape, t.levels)
        pts = detect_corners(t.lk, self.config.tracking.detector, mask=mask)
        self._ref.restart(np.asarray(pts * t.scale, dtype=np.float32))

    def _gyro_rotation(self, prev_t: int, t_ns: int) -> F64 | None:
        """Gyro rotation prev -> cur (camera frame), None when the reference lost it or the IMU
        does not cover the interval."""
        imu_t = self._imu.t
        if not (self._ref.gyro_ok and imu_t.size >= 2 and imu_t[0] <= prev_t
                and imu_t[-1] >= t_ns - 20_000_000):
            return None
        return integrate_gyro(imu_t, self._imu.g, prev_t, t_ns, self.R_cam_body, self.gyro_bias)

    def _track(self, prev: _Previous, track: TrackFrame, img: U8, expo_frame: ExposureFrame,
               t_ns: int) -> tuple[ExposureChange, float, RotationSource, bool]:
        """Track from the previous frame: the exposure change, the parallax (px) and its
        rotation source, and whether this frame became the parallax reference."""
        cfg, ref = self.config, self._ref
        ref.rotate(self._gyro_rotation(prev.t_ns, t_ns))
        tracker = self._lk(img.shape[1])
        res = track_between(tracker, prev.track, track, ref.pts)
        ok = res.ok
        pts1 = np.asarray(res.pts, dtype=np.float32)
        n_ok = int(ok.sum())
        expo = fit_exposure_tracked(tracker, (prev.track, track), (prev.exposure, expo_frame),
                                    ref.pts[ok], pts1[ok], cfg.exposure, cfg.tracking.detector)
        if expo is None:
            expo = fit_exposure_same_pixel(prev.image, img, cfg.exposure, self.inverse_response)
        ref.advance(pts1, ok)
        par = ref.measure(self._camera_for(img.shape[:2]))
        due = parallax_reference_due(n_ok, ref.n_detected, par.median_px, cfg.reference)
        if due:
            self._new_reference(track, expo_frame)
        return expo, par.median_px, par.rotation_source, due

    def process(
        self,
        frame_image: NDArray[np.generic],
        t_ns: int,
        imu_window: ImuData | None = None,
        exposure_s: float | None = None,
        frame_index: int | None = None,
        motion: CameraMotion | None = None,
    ) -> FrameHealth:
        """Diagnose one (H, W) uint8 grey frame taken at ``t_ns`` (mid-exposure).

        ``imu_window``: IMU samples since the previous call, reaching at least to the end of this
        frame's exposure (overlaps are ignored). ``exposure_s``: the frame's exposure time if known.
        ``motion``: the camera's velocity and the depths of tracked points when the caller knows
        them (VIO, VO with scale, or a wheel odometer); the predicted smear then includes the
        translational part, else it is the rotational part alone.
        """
        img = np.asarray(frame_image)
        if img.ndim != 2 or img.dtype != np.uint8:
            raise ShapeError(f"frame_image must be (H,W) uint8 grey, got {img.shape} {img.dtype}")
        if img.shape[0] < 16 or img.shape[1] < 16:
            raise ShapeError(f"frame_image too small: {img.shape}")
        prev = self._prev
        if prev is not None and t_ns <= prev.t_ns:
            raise ShapeError(f"frames must come in increasing time: {t_ns} after {prev.t_ns}")
        cfg = self.config
        idx = self._index if frame_index is None else frame_index
        self._index += 1
        if imu_window is not None:
            self._imu.add(imu_window)

        track = prepare_track_frame(self._lk(img.shape[1]), img)
        expo_frame = prepare_exposure_frame(img, cfg.exposure, self.inverse_response)
        expo: ExposureChange | None = None
        parallax = float("nan")
        rot_source = RotationSource.NONE
        if prev is None or prev.image.shape != img.shape:
            self._new_reference(track, expo_frame)
            new_ref = True
        else:
            expo, parallax, rot_source, new_ref = self._track(prev, track, img, expo_frame, t_ns)
        # Blur (seed section 5) on the contrast-normalised score. An exposure step changes
        # saturation and noise, so the sharp reference restarts there.
        if expo is not None and expo.flag:
            self._blur.reset()
        var_lap = var_laplacian(img, step=2)
        score = blur_score(img, var_lap)
        blur = self._blur.update(score)
        smear, advice = self._smear(t_ns, exposure_s, motion)
        smear_flag = smear is not None and smear.max_px > cfg.smear_flag_px
        ex: Excitation | None = None
        if self._imu.t.size:
            win = self._imu.window(t_ns - int(cfg.excitation_window_s * 1e9), t_ns)
            ex = compute_excitation(win, config=cfg.excitation, gyro_bias_rad_s=self.gyro_bias)
        self._prev = _Previous(img, track, expo_frame, int(t_ns))
        return FrameHealth(
            t_ns=int(t_ns),
            frame=idx,
            blur=BlurHealth(
                var_lap=var_lap,
                score=score,
                ratio=blur.ratio,
                flag=bool(blur.is_blurred or smear_flag),
                smear_px_pred=None if smear is None else smear.max_px,
                smear_px_mean=None if smear is None else smear.mean_px,
                smear_px_rotation=None if smear is None else smear.rotation_max_px,
                smear_px_translation=None if smear is None else smear.translation_max_px,
                max_exposure_s=advice,
            ),
            exposure=ExposureHealth(
                exposure_s=exposure_s,
                gain_a=1.0 if expo is None else expo.a,
                offset_b=0.0 if expo is None else expo.b,
                ev=0.0 if expo is None else expo.ev,
                flag=False if expo is None else expo.flag,
                method="" if expo is None else expo.method,
                saturated_frac=saturated_fraction(img),
                underexposed_frac=float(np.count_nonzero(img <= 5)) / img.size,
            ),
            parallax=ParallaxHealth(
                px=parallax,
                low_flag=low_parallax(self._ref.frames_since, parallax, cfg.reference),
                n_tracks=int(self._ref.pts.shape[0]),
                rotation_source=rot_source.value,
                new_reference=new_ref,
            ),
            excitation=ex,
        )


__all__ = [
    "EXCITATION_COLUMNS",
    "HEALTH_COLUMNS",
    "DiagnosticsConfig",
    "FrameDiagnostics",
    "FrameHealth",
    "health_rows",
]
