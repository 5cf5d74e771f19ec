"""The per-frame health record of :class:`~amrvio.diagnostics.frame.FrameDiagnostics`, in parts
(blur, exposure, parallax, excitation), and its flat CSV form (``health.csv``)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from amrvio.diagnostics.excitation import Excitation


@dataclass(frozen=True, slots=True)
class BlurHealth:
    """``var_lap``: the seed's Var(Delta I) of the raw image; ``score``: the contrast-normalised
    :func:`~amrvio.diagnostics.blur.blur_score`; ``ratio``: the scene-normalised
    :func:`~amrvio.diagnostics.blur.blur_score` over recent sharp frames; ``flag``: ratio low or
    predicted smear above the flag level. ``smear_px_pred``/``smear_px_mean``: predicted smear
    (max / mean over the image), rotation from the gyro plus translation when the camera's motion
    was given; ``smear_px_rotation``/``smear_px_translation``: the max of each part alone
    (translation None when the motion was not given); ``max_exposure_s``: the longest exposure
    keeping the predicted smear under the bound at the current motion (only when the bound is
    exceeded)."""

    var_lap: float
    score: float
    ratio: float
    flag: bool
    smear_px_pred: float | None = None
    smear_px_mean: float | None = None
    max_exposure_s: float | None = None
    smear_px_rotation: float | None = None
    smear_px_translation: float | None = None


@dataclass(frozen=True, slots=True)
class ExposureHealth:
    """``exposure_s``: the frame's exposure time if known; ``gain_a``/``offset_b``/``ev``: the
    brightness change from the previous frame; ``flag``: an exposure step; ``method``: "klt"
    (tracked patches), "same_pixel" or "" (first frame); clipped pixel fractions."""

    exposure_s: float | None
    gain_a: float
    offset_b: float
    ev: float
    flag: bool
    method: str
    saturated_frac: float
    underexposed_frac: float


@dataclass(frozen=True, slots=True)
class ParallaxHealth:
    """``px``: rotation-compensated parallax against the parallax reference frame; ``low_flag``;
    ``n_tracks`` surviving since the reference; ``rotation_source``; ``new_reference``: this
    frame became the reference."""

    px: float
    low_flag: bool
    n_tracks: int
    rotation_source: str
    new_reference: bool


@dataclass(frozen=True, slots=True)
class FrameHealth:
    """Health record of one frame. Optional values are None when they cannot be computed
    (no IMU, no exposure time, first frame)."""

    t_ns: int
    frame: int
    blur: BlurHealth
    exposure: ExposureHealth
    parallax: ParallaxHealth
    excitation: Excitation | None = None

    @property
    def t_s(self) -> float:
        return self.t_ns * 1e-9

    def as_row(self) -> dict[str, str]:
        """Flat CSV row (strings; empty for None / NaN), keys :data:`HEALTH_COLUMNS` (and
        :data:`EXCITATION_COLUMNS` with an excitation record)."""

        def f(v: float | None, nd: int = 6) -> str:
            if v is None or not math.isfinite(v):
                return ""
            return f"{v:.{nd}g}"

        b, e, p = self.blur, self.exposure, self.parallax
        row: dict[str, str] = {
            "t_s": f"{self.t_s:.9f}",
            "frame": str(self.frame),
            "blur_var_lap": f(b.var_lap),
            "blur_ratio": f(b.ratio, 4),
            "smear_px_pred": f(b.smear_px_pred, 4),
            "smear_px_mean": f(b.smear_px_mean, 4),
            "smear_px_rot": f(b.smear_px_rotation, 4),
            "smear_px_trans": f(b.smear_px_translation, 4),
            "blur_flag": str(int(b.flag)),
            "exposure_s": f(e.exposure_s),
            "max_exposure_s": f(b.max_exposure_s, 4),
            "gain_a": f(e.gain_a),
            "offset_b": f(e.offset_b),
            "exposure_ev": f(e.ev, 4),
            "exposure_flag": str(int(e.flag)),
            "exposure_method": e.method,
            "saturated_frac": f(e.saturated_frac, 4),
            "underexposed_frac": f(e.underexposed_frac, 4),
            "parallax_px": f(p.px, 4),
            "low_parallax_flag": str(int(p.low_flag)),
            "n_tracks": str(p.n_tracks),
            "rotation_source": p.rotation_source,
            "keyframe": str(int(p.new_reference)),
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
    "t_s", "frame", "blur_var_lap", "blur_ratio", "smear_px_pred", "smear_px_mean", "smear_px_rot",
    "smear_px_trans", "blur_flag",
    "exposure_s", "max_exposure_s", "gain_a", "offset_b", "exposure_ev", "exposure_flag",
    "exposure_method", "saturated_frac", "underexposed_frac", "parallax_px", "low_parallax_flag",
    "n_tracks", "rotation_source", "keyframe",
)
EXCITATION_COLUMNS: tuple[str, ...] = (
    "accel_std_m_s2", "accel_dir_change_deg", "gyro_mean_rad_s", "gyro_max_rad_s",
    "excitation_degenerate",
)


def health_columns(excitation: bool) -> list[str]:
    """The health columns: :data:`HEALTH_COLUMNS`, then :data:`EXCITATION_COLUMNS` when the
    records have an excitation part."""
    return [*HEALTH_COLUMNS, *(EXCITATION_COLUMNS if excitation else ())]


def health_rows(records: Sequence[FrameHealth]) -> tuple[list[str], list[Mapping[str, str]]]:
    """Column names (excitation columns only when any record has them) and CSV rows."""
    return health_columns(any(r.excitation is not None for r in records)), [r.as_row() for r in records]


__all__ = [
    "EXCITATION_COLUMNS",
    "HEALTH_COLUMNS",
    "BlurHealth",
    "ExposureHealth",
    "FrameHealth",
    "ParallaxHealth",
    "health_columns",
    "health_rows",
]
