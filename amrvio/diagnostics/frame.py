"""The per-frame diagnostics stage: ``FrameDiagnostics(config).process(...) -> FrameHealth``.

One call per frame, in time order. The stage keeps only what it needs between frames: the
previous image and its KLT tracks (for the exposure fit on corresponding pixels and for parallax
against the last keyframe), the gyro rotation since the keyframe, a short IMU buffer (for the
exposure-window smear and the excitation window) and the blur reference.

Blur: ``blur_var_lap`` is the seed's Var(Delta I) of the raw image. The scene-normalised
``blur_ratio`` divides a *contrast-normalised* score, Var(Delta I) / Var(I), by the median of recent
sharp frames: an exposure step scales both variances by a^2, so it does not read as blur.
``blur_flag`` is set when that ratio is low or when the gyro-predicted smear exceeds
``smear_flag_px``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.blur import BlurScorer, BlurScorerConfig, var_laplacian
from amrvio.diagnostics.excitation import Excitation, ExcitationConfig, compute_excitation
from amrvio.diagnostics.exposure import (
    ExposureChange,
    ExposureConfig,
    ExposureFrame,
    TrackerConfig,
    detect_features,
    detection_mask,
    fit_exposure_frames,
    fit_exposure_same_pixel,
    normalise_for_tracking,
    prepare_exposure_frame,
    saturated_fraction,
    track_features,
)
from amrvio.diagnostics.parallax import RotationSource, rotation_compensated_parallax
from amrvio.diagnostics.smear import (
    SmearPrediction,
    integrate_gyro,
    max_exposure_for_smear,
    predict_smear,
)
from amrvio.errors import ShapeError
from amrvio.types.camera import CameraModel, PinholeCamera
from amrvio.types.lie import SE3
from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class DiagnosticsConfig:
    """Settings of :class:`FrameDiagnostics`.

    ``blur_step``: stride of the Laplacian subset used for the score (1 = every pixel).
    ``smear_bound_px``: the exposure advice keeps the predicted max smear under it.
    ``smear_flag_px``: a predicted max smear above it sets ``blur_flag``.
    ``assumed_exposure_s``: used for the smear when a frame carries no exposure time (None: no
    prediction then). ``low_parallax_px``: parallax below it, ``min_frames_low_parallax`` frames
    after the keyframe, sets ``low_parallax_flag``. ``keyframe_parallax_px``: a new keyframe starts
    above it (or when fewer than ``keyframe_track_frac`` of its tracks remain).
    ``excitation_window_s``: IMU window of the excitation record. ``max_track_width``: wider
    images are tracked on the first pyramid level narrower than this (speed, large motions);
    the exposure fit still samples the full-resolution frames.
    """

    blur: BlurScorerConfig = field(default_factory=BlurScorerConfig)
    exposure: ExposureConfig = field(default_factory=ExposureConfig)
    tracker: TrackerConfig = field(default_factory=TrackerConfig)
    excitation: ExcitationConfig = field(default_factory=ExcitationConfig)
    blur_step: int = 2
    smear_bound_px: float = 2.0
    smear_flag_px: float = 4.0
    assumed_exposure_s: float | None = None
    low_parallax_px: float = 5.0
    min_frames_low_parallax: int = 10
    keyframe_parallax_px: float = 30.0
    keyframe_track_frac: float = 0.5
    excitation_window_s: float = 2.0
    max_track_width: int = 1000


@dataclass(frozen=True, slots=True)
class FrameHealth:
    """Health record of one frame. Optional values are None when they cannot be computed
    (no IMU, no exposure time, first frame). Reused by the VO pipeline: ``blur_flag`` to skip
    updates, ``gain_a``/``offset_b`` as the photometric prior of direct alignment.

    ``exposure_method``: "klt" (tracked patches), "same_pixel" or "" (first frame).
    ``max_exposure_s``: the longest exposure keeping the predicted smear under the bound at the
    current angular rate (only when the predicted smear exceeds the bound).
    """

    t_ns: int
    frame: int
    blur_var_lap: float
    blur_ratio: float
    blur_flag: bool
    smear_px_pred: float | None
    smear_px_mean: float | None
    exposure_s: float | None
    max_exposure_s: float | None
    gain_a: float
    offset_b: float
    exposure_ev: float
    exposure_flag: bool
    exposure_method: str
    saturated_frac: float
    underexposed_frac: float
    parallax_px: float
    low_parallax_flag: bool
    n_tracks: int
    rotation_source: str
    keyframe: bool
    excitation: Excitation | None = None

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9

    def as_row(self) -> dict[str, str]:
        """Flat CSV row (strings; empty for None / NaN)."""

        def f(v: float | None, nd: int = 6) -> str:
            if v is None or not math.isfinite(v):
                return ""
            return f"{v:.{nd}g}"

        row: dict[str, str] = {
            "t_s": f"{self.t_s:.9f}",
            "frame": str(self.frame),
            "blur_var_lap": f(self.blur_var_lap),
            "blur_ratio": f(self.blur_ratio, 4),
            "smear_px_pred": f(self.smear_px_pred, 4),
            "smear_px_mean": f(self.smear_px_mean, 4),
            "blur_flag": str(int(self.blur_flag)),
            "exposure_s": f(self.exposure_s),
            "max_exposure_s": f(self.max_exposure_s, 4),
            "gain_a": f(self.gain_a),
            "offset_b": f(self.offset_b),
            "exposure_ev": f(self.exposure_ev, 4),
            "exposure_flag": str(int(self.exposure_flag)),
            "exposure_method": self.exposure_method,
            "saturated_frac": f(self.saturated_frac, 4),
            "underexposed_frac": f(self.underexposed_frac, 4),
            "parallax_px": f(self.parallax_px, 4),
            "low_parallax_flag": str(int(self.low_parallax_flag)),
            "n_tracks": str(self.n_tracks),
            "rotation_source": self.rotation_source,
            "keyframe": str(int(self.keyframe)),
        }
        ex = self.excitation
        if ex is not None:
            row["accel_std_m_s2"] = f(ex.accel_std_m_s2, 4)
            row["accel_dir_change_deg"] = f(math.degrees(ex.accel_dir_change_rad), 4)
            row["gyro_mean_rad_s"] = f(ex.gyro_mean_rad_s, 4)
            row["gyro_max_rad_s"] = f(ex.gyro_max_rad_s, 4)
            row["excitation_degenerate"] = str(int(ex.degenerate))
        return row


HEALTH_COLUMNS: tuple[str, ...] = (
    "t_s", "frame", "blur_var_lap", "blur_ratio", "smear_px_pred", "smear_px_mean", "blur_flag",
    "exposure_s", "max_exposure_s", "gain_a", "offset_b", "exposure_ev", "exposure_flag",
    "exposure_method", "saturated_frac", "underexposed_frac", "parallax_px", "low_parallax_flag",
    "n_tracks", "rotation_source", "keyframe",
)
EXCITATION_COLUMNS: tuple[str, ...] = (
    "accel_std_m_s2", "accel_dir_change_deg", "gyro_mean_rad_s", "gyro_max_rad_s",
    "excitation_degenerate",
)


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
        self.R_cam_body: F64 | None = (
            None if T_body_cam is None else np.asarray(T_body_cam.rot.matrix().T)
        )
        self.inverse_response = inverse_response
        self.gyro_bias = gyro_bias_rad_s
        self._blur = BlurScorer(self.config.blur)
        span = max(self.config.excitation_window_s, 1.0)
        self._imu = _ImuBuffer(int(span * 1e9))
        self._prev_img: U8 | None = None
        self._prev_norm: U8 | None = None
        self._down = 0
        self._prev_expo: ExposureFrame | None = None
        self._prev_t: int | None = None
        self._pts = np.zeros((0, 2), np.float32)
        self._pts_kf = np.zeros((0, 2), np.float32)
        self._kf_count = 0
        self._R_kf_cur = np.eye(3)
        self._gyro_ok = False
        self._frames_since_kf = 0
        self._index = 0

    # ------------------------------------------------------------------------------------------
    def _camera_for(self, shape: tuple[int, int]) -> CameraModel:
        if self.camera is not None:
            return self.camera
        h, w = shape
        return PinholeCamera(w, h, float(w), float(w), (w - 1) / 2.0, (h - 1) / 2.0)

    def _smear(self, t_ns: int, exposure_s: float | None) -> tuple[SmearPrediction | None, float | None]:
        T = exposure_s if exposure_s is not None else self.config.assumed_exposure_s
        if self.camera is None or T is None or self._imu.t.size < 2:
            return None, None
        if t_ns - int(T * 0.5e9) < self._imu.t[0] or t_ns + int(T * 0.5e9) > self._imu.t[-1] + 20_000_000:
            return None, None
        pred = predict_smear(
            self.camera, self._imu.t, self._imu.g, t_ns, T, self.R_cam_body, self.gyro_bias
        )
        advice = None
        if pred.max_px > self.config.smear_bound_px:
            advice = max_exposure_for_smear(
                self.camera, pred.omega_cam_rad_s, self.config.smear_bound_px
            )
        return pred, advice

    def _new_keyframe(self, norm: U8, expo_frame: ExposureFrame) -> None:
        mask = detection_mask(expo_frame)
        f = 2**self._down
        for _ in range(self._down):
            mask = None if mask is None else np.asarray(mask[::2, ::2])
        if mask is not None and mask.shape != norm.shape:
            mask = np.ascontiguousarray(mask[: norm.shape[0], : norm.shape[1]])
            if mask.shape != norm.shape:
                mask = None
        pts = detect_features(norm, self.config.tracker, mask=mask) * np.float32(f)
        self._pts = pts
        self._pts_kf = pts.copy()
        self._kf_count = int(pts.shape[0])
        self._R_kf_cur = np.eye(3)
        self._gyro_ok = True
        self._frames_since_kf = 0

    def process(
        self,
        frame_image: NDArray[np.generic],
        t_ns: int,
        imu_window: ImuData | None = None,
        exposure_s: float | None = None,
        frame_index: int | None = None,
    ) -> FrameHealth:
        """Diagnose one (H, W) uint8 grey frame taken at ``t_ns`` (mid-exposure).

        ``imu_window``: IMU samples since the previous call, reaching at least to the end of this
        frame's exposure (overlaps are ignored). ``exposure_s``: the frame's exposure time if known.
        """
        img = np.asarray(frame_image)
        if img.ndim != 2 or img.dtype != np.uint8:
            raise ShapeError(f"frame_image must be (H,W) uint8 grey, got {img.shape} {img.dtype}")
        if img.shape[0] < 16 or img.shape[1] < 16:
            raise ShapeError(f"frame_image too small: {img.shape}")
        if self._prev_t is not None and t_ns <= self._prev_t:
            raise ShapeError(f"frames must come in increasing time: {t_ns} after {self._prev_t}")
        cfg = self.config
        idx = self._index if frame_index is None else frame_index
        self._index += 1
        if imu_window is not None:
            self._imu.add(imu_window)

        if self._prev_img is None or self._prev_img.shape != img.shape:
            self._down = 0
            while (img.shape[1] >> self._down) > cfg.max_track_width:
                self._down += 1
        norm = normalise_for_tracking(img)
        for _ in range(self._down):  # track big images on a pyramid level (speed, large motion)
            norm = cv2.pyrDown(norm)
        expo_frame = prepare_exposure_frame(img, cfg.exposure, self.inverse_response)
        sat = saturated_fraction(img)
        under = float(np.count_nonzero(img <= 5)) / img.size
        expo: ExposureChange | None = None
        parallax = float("nan")
        rot_source = RotationSource.NONE
        keyframe = False
        if self._prev_img is None or self._prev_norm is None or self._prev_img.shape != img.shape:
            self._new_keyframe(norm, expo_frame)
            keyframe = True
        else:
            # Gyro rotation prev -> cur (camera frame) accumulated since the keyframe.
            if self._gyro_ok and self._prev_t is not None and self._imu.t.size >= 2 and (
                self._imu.t[0] <= self._prev_t and self._imu.t[-1] >= t_ns - 20_000_000
            ):
                R_prev_cur = integrate_gyro(
                    self._imu.t, self._imu.g, self._prev_t, t_ns, self.R_cam_body, self.gyro_bias
                )
                self._R_kf_cur = self._R_kf_cur @ R_prev_cur
            else:
                self._gyro_ok = False
            f = np.float32(2**self._down)
            pts1, ok = track_features(self._prev_norm, norm, self._pts / f, cfg.tracker)
            pts1 = pts1 * f
            n_ok = int(ok.sum())
            if n_ok >= cfg.exposure.min_tracks and self._prev_expo is not None:
                expo = fit_exposure_frames(
                    self._prev_expo, expo_frame, self._pts[ok], pts1[ok], cfg.exposure
                )
            else:
                expo = fit_exposure_same_pixel(
                    self._prev_img, img, cfg.exposure, self.inverse_response
                )
            self._pts, self._pts_kf = pts1[ok], self._pts_kf[ok]
            self._frames_since_kf += 1
            R_cur_kf = self._R_kf_cur.T if self._gyro_ok else None
            par = rotation_compensated_parallax(
                self._camera_for(img.shape[:2]), self._pts_kf, self._pts, R_cur_kf
            )
            parallax, rot_source = par.median_px, par.rotation_source
            if (
                n_ok < cfg.tracker.min_tracks
                or n_ok < cfg.keyframe_track_frac * self._kf_count
                or (math.isfinite(parallax) and parallax > cfg.keyframe_parallax_px)
            ):
                self._new_keyframe(norm, expo_frame)
                keyframe = True
        # Blur (seed section 5) on raw and on contrast-normalised scores. An exposure step changes
        # saturation and noise, so the sharp reference restarts there.
        score = var_laplacian(img, step=cfg.blur_step)
        _, std = cv2.meanStdDev(img)
        contrast = max(float(std[0, 0]) ** 2, 1e-6)
        if expo is not None and expo.flag:
            self._blur.reset()
        blur = self._blur.update(score / contrast)
        smear, advice = self._smear(t_ns, exposure_s)
        smear_flag = smear is not None and smear.max_px > cfg.smear_flag_px
        low_par = bool(
            self._frames_since_kf >= cfg.min_frames_low_parallax
            and math.isfinite(parallax)
            and parallax < cfg.low_parallax_px
        )
        ex: Excitation | None = None
        if self._imu.t.size:
            win = self._imu.window(t_ns - int(cfg.excitation_window_s * 1e9), t_ns)
            ex = compute_excitation(win, config=cfg.excitation, gyro_bias_rad_s=self.gyro_bias)
        self._prev_img, self._prev_norm, self._prev_t = img, norm, int(t_ns)
        self._prev_expo = expo_frame
        return FrameHealth(
            t_ns=int(t_ns),
            frame=idx,
            blur_var_lap=score,
            blur_ratio=blur.ratio,
            blur_flag=bool(blur.is_blurred or smear_flag),
            smear_px_pred=None if smear is None else smear.max_px,
            smear_px_mean=None if smear is None else smear.mean_px,
            exposure_s=exposure_s,
            max_exposure_s=advice,
            gain_a=1.0 if expo is None else expo.a,
            offset_b=0.0 if expo is None else expo.b,
            exposure_ev=0.0 if expo is None else expo.ev,
            exposure_flag=False if expo is None else expo.flag,
            exposure_method="" if expo is None else expo.method,
            saturated_frac=sat,
            underexposed_frac=under,
            parallax_px=parallax,
            low_parallax_flag=low_par,
            n_tracks=int(self._pts.shape[0]),
            rotation_source=rot_source.value,
            keyframe=keyframe,
            excitation=ex,
        )


def health_rows(records: list[FrameHealth]) -> tuple[list[str], list[Mapping[str, str]]]:
    """Column names (excitation columns only when any record has them) and CSV rows."""
    cols = list(HEALTH_COLUMNS)
    if any(r.excitation is not None for r in records):
        cols += list(EXCITATION_COLUMNS)
    return cols, [r.as_row() for r in records]
