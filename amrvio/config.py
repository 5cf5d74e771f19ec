"""The pipeline's configuration: a tree of frozen dataclasses, each stage owning its defaults.

YAML files use exactly the field names, nested as the tree is (``tracking: {klt: {max_features:
1200}}``). An unknown key or a value of the wrong type is a :class:`ConfigError` naming the key.
There is one seed, at the top: stages that draw random numbers get it at construction, so the
stage configs' own ``seed`` fields are not settable from a file.
"""

from __future__ import annotations

import dataclasses
import enum
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from amrvio.diagnostics.frame import DiagnosticsConfig
from amrvio.errors import ConfigError
from amrvio.estimator.initializer import InitConfig
from amrvio.estimator.local_mapping import MappingConfig
from amrvio.estimator.scale_sources import ScaleConfig
from amrvio.frontend.tracker import TrackingConfig
from amrvio.pipeline.recovery import RecoveryConfig
from amrvio.pipeline.vio_report import VioStageConfig
from amrvio.tracking.lk import reduction_levels

#: nested fields that the top-level ``seed`` replaces
_SEED = "seed"


@dataclass(frozen=True, slots=True)
class OutputConfig:
    """``final_refine``: refine non-keyframe poses against the final map (motion-only, Huber)."""

    final_refine: bool = True


@dataclass(frozen=True, slots=True)
class PipelineConfig:
    """The whole per-frame pipeline."""

    seed: int = 0
    track: bool = True
    diagnose: bool = True
    blur_gating: bool = True
    diagnostics: DiagnosticsConfig = field(default_factory=DiagnosticsConfig)
    tracking: TrackingConfig = field(default_factory=TrackingConfig)
    init: InitConfig = field(default_factory=InitConfig)
    mapping: MappingConfig = field(default_factory=MappingConfig)
    recovery: RecoveryConfig = field(default_factory=RecoveryConfig)
    scale: ScaleConfig = field(default_factory=ScaleConfig)
    output: OutputConfig = field(default_factory=OutputConfig)
    vio: VioStageConfig = field(default_factory=VioStageConfig)


#: the gates that bound a tracking or reprojection error, in pixels of the image the tracker works
#: on (``in_tracked_pixels``); gates on the size of a motion (flow, parallax, search radius) stay
#: in image pixels: a motion of N image pixels is the same angle at any tracking level
NOISE_GATES_PX: tuple[str, ...] = (
    "tracking.klt.fb_thresh_px", "tracking.klt.ransac_thresh_px", "tracking.pnp_thresh_px",
    "tracking.huber_px", "tracking.rotation_max_px", "tracking.scaled_relative.thresh_px",
    "tracking.scaled_relative.point_thresh_px", "init.two_view.ransac_thresh_px",
    "init.two_view.max_reproj_px", "init.pnp_thresh_px", "recovery.reloc.pnp_thresh_px",
    "mapping.anchor.max_shift_px", "mapping.mapper.huber_px", "mapping.mapper.cull_px",
    "mapping.mapper.tri_max_reproj_px",
)


def in_tracked_pixels(cfg: PipelineConfig, image_width: int | None) -> PipelineConfig:
    """``cfg`` as the stages use it on images ``image_width`` pixels wide: every gate of
    :data:`NOISE_GATES_PX` multiplied by the image pixels per pixel of the pyramid level the KLT
    tracks on (``tracking.klt.max_width_px``: 2 for a 1920-pixel-wide phone video, 1 up to 1280
    wide). A track is as precise as a fraction of a pixel of the image it was tracked in; with
    the gates in image pixels, the 1080p phone's forward-backward check, PnP and triangulation
    gates were half as wide, relative to that precision, as on KITTI or EuRoC. ``cfg`` itself
    when the images are tracked at full resolution (or ``image_width`` is None: unknown)."""
    px_scale = 1 if image_width is None else 2 ** reduction_levels(image_width, cfg.tracking.klt.max_width_px)
    if px_scale == 1:
        return cfg

    def scaled(node: Any, path: list[str]) -> Any:
        head, rest = path[0], path[1:]
        value = getattr(node, head)
        return dataclasses.replace(node, **{head: value * px_scale if not rest else scaled(value, rest)})

    out = cfg
    for dotted in NOISE_GATES_PX:
        out = scaled(out, dotted.split("."))
    return out


#: one line of help per field, by dotted path; `amrvio config --dump` prints them as comments
HELP: dict[str, str] = {
    "seed": "seed of every random choice (RANSAC, sampling): same input and seed, same output",
    "track": "run tracking (false: diagnostics only, as `amrvio diagnose`)",
    "blur_gating": "blurred frames give a pose but make no keyframe and no track update",
    "diagnose": "compute the per-frame health record (blur, smear, exposure, parallax, excitation)",
    "diagnostics": "the health record; its blur scorer also gates blurred frames for tracking",
    "diagnostics.blur": "blur score normalised by recent sharp frames",
    "diagnostics.blur.window": "recent sharp scores in the running median",
    "diagnostics.blur.blur_ratio": "a frame whose score / median is below this is blurred",
    "diagnostics.blur.sharp_ratio": "frames at or above this ratio join the sharp reference",
    "diagnostics.blur.reset_after": "consecutive non-sharp frames after which the reference restarts",
    "diagnostics.exposure": "gain/offset and EV between frames",
    "diagnostics.exposure.ev_step": "|EV| that flags an exposure step",
    "diagnostics.exposure.patch_radius": "radius of the patches sampled around tracks (px)",
    "diagnostics.exposure.curvature_dn": "intensity curvature scale of the patch weights (grey levels)",
    "diagnostics.exposure.smooth_px": "box filter applied before the patches are sampled (px)",
    "diagnostics.exposure.max_abs_ev": "largest |EV| accepted as a measurement",
    "diagnostics.exposure.grid_step": "pixel step of the same-pixel fallback",
    "diagnostics.exposure.min_tracks": "tracks needed for the tracked-patch fit",
    "diagnostics.exposure.huber_k": "Huber constant of the robust fit (in robust sigmas)",
    "diagnostics.exposure.tukey_k": "Tukey biweight constant of the robust fit (in robust sigmas)",
    "diagnostics.exposure.min_patches": "fewer used samples than this many patches: refit with more corners",
    "diagnostics.exposure.extra_corners": "corners added where neither frame clips when the fit is starved",
    "diagnostics.tracking": "the diagnostics' own sparse tracks",
    "diagnostics.tracking.detector": "corner detection",
    "diagnostics.tracking.detector.max_corners": "corners tracked",
    "diagnostics.tracking.detector.quality_level": "Shi-Tomasi quality level relative to the best corner",
    "diagnostics.tracking.detector.min_distance_px": "minimum distance between corners (px)",
    "diagnostics.tracking.detector.block_size": "corner measure window (px)",
    "diagnostics.tracking.detector.border_px": "image border without corners (px)",
    "diagnostics.tracking.detector.grid_rows": "detection buckets, rows (0: no bucketing)",
    "diagnostics.tracking.detector.grid_cols": "detection buckets, columns (0: no bucketing)",
    "diagnostics.tracking.lk": "pyramidal LK",
    "diagnostics.tracking.lk.invariance": "brightness invariance: affine, normalise or none",
    "diagnostics.tracking.lk.win_size": "LK window (px)",
    "diagnostics.tracking.lk.pyr_levels": "pyramid levels",
    "diagnostics.tracking.lk.max_iterations": "LK iterations per level",
    "diagnostics.tracking.lk.epsilon": "LK convergence threshold (px)",
    "diagnostics.tracking.lk.fb_thresh_px": "forward-backward check threshold (px); null: off",
    "diagnostics.tracking.lk.max_error": "largest LK residual accepted; null: no bound",
    "diagnostics.tracking.lk.border_px": "tracks closer to the border are dropped (px)",
    "diagnostics.tracking.lk.epipolar": "epipolar outlier check; null: off",
    "diagnostics.tracking.lk.max_width_px": "wider images are tracked on a coarser pyramid level (px)",
    "diagnostics.tracking.lk.reduce_by_area": "that level by 2x2 averaging (true) or Gaussian pyrDown",
    "diagnostics.tracking.lk.fb_pyr_levels": "pyramid levels of the backward check; null: as pyr_levels",
    "diagnostics.reference": "parallax reference frame",
    "diagnostics.reference.min_tracks": "tracks below which the reference is renewed",
    "diagnostics.reference.min_track_frac": "share of the reference's tracks below which it is renewed",
    "diagnostics.reference.max_parallax_px": "parallax above which the reference is renewed (px)",
    "diagnostics.reference.low_parallax_px": "parallax below which frames count as low parallax (px)",
    "diagnostics.reference.min_frames_low_parallax": "frames of low parallax before the flag is raised",
    "diagnostics.excitation": "IMU excitation (scale observability)",
    "diagnostics.excitation.min_accel_std_m_s2": "acceleration spread below which a window is degenerate (m/s^2)",
    "diagnostics.excitation.min_accel_m_s2": "mean acceleration that counts in the direction change (m/s^2)",
    "diagnostics.excitation.min_samples": "IMU samples needed",
    "diagnostics.excitation.lowpass_s": "averaging bin that removes vibration (s); 0: off",
    "diagnostics.smear_bound_px": "the exposure advice keeps the predicted smear under this (px)",
    "diagnostics.smear_flag_px": "predicted smear above this sets the blur flag (px)",
    "diagnostics.assumed_exposure_s": "exposure for the smear prediction when frames carry none (s); null: derived",
    "diagnostics.excitation_window_s": "IMU window of the excitation record (s)",
    "tracking": "KLT front-end, PnP, direct alignment",
    "tracking.klt": "corner detection and pyramidal KLT",
    "tracking.klt.detector": "bucketed Shi-Tomasi corners",
    "tracking.klt.detector.max_corners": "tracks kept alive (topped up at keyframes)",
    "tracking.klt.detector.quality_level": "Shi-Tomasi quality level relative to the best corner",
    "tracking.klt.detector.min_distance_px": "minimum distance between corners (px)",
    "tracking.klt.detector.block_size": "corner measure window (px)",
    "tracking.klt.detector.border_px": "image border without corners (px)",
    "tracking.klt.detector.grid_rows": "detection buckets, rows (0: no bucketing)",
    "tracking.klt.detector.grid_cols": "detection buckets, columns (0: no bucketing)",
    "tracking.klt.win_size": "KLT window (px)",
    "tracking.klt.pyr_levels": "pyramid levels between consecutive frames",
    "tracking.klt.wide_pyr_levels": "pyramid levels after a gap (blur)",
    "tracking.klt.fb_thresh_px": "forward-backward check threshold (px)",
    "tracking.klt.photometric": "affine brightness compensation before KLT",
    "tracking.klt.ransac_thresh_px": "essential-matrix outlier threshold (px)",
    "tracking.klt.max_iterations": "KLT iterations per level",
    "tracking.klt.max_width_px": "wider images are tracked on a coarser pyramid level (px; null: full)",
    "tracking.klt.guided_retrack": "when KLT lost more map-point tracks than PnP kept, track them again "
                                   "from their projections at the PnP pose",
    "tracking.klt.fb_pyr_levels": "pyramid levels of the backward check; null: as the forward pass",
    "tracking.direct": "sparse direct alignment, SE(3) + affine brightness",
    "tracking.direct.levels": "pyramid levels",
    "tracking.direct.iterations": "Gauss-Newton iterations per level",
    "tracking.direct.huber": "Huber threshold (grey levels)",
    "tracking.direct.min_pixels": "fewest map points to try it",
    "tracking.direct.max_rms": "largest accepted photometric RMS (grey levels)",
    "tracking.direct.estimate_affine": "estimate gain/offset (false: brightness constancy)",
    "tracking.direct_prior": "direct alignment gives the motion prior after blurred frames",
    "tracking.direct_fallback": "direct alignment poses the frame when PnP fails",
    "tracking.min_pnp_inliers": "PnP inliers needed to accept a pose",
    "tracking.pnp_thresh_px": "PnP RANSAC threshold (px)",
    "tracking.huber_px": "Huber threshold of pose refinement and BA (px)",
    "tracking.rotation_only": "pose by rotation alone when PnP fails and one rotation explains the flow",
    "tracking.rotation_max_px": "median residual under which one rotation explains the flow (px)",
    "tracking.retry_unpredicted": "when PnP fails, track again without the motion prediction",
    "tracking.blurred_reference_ratio": "VO without IMU: blurred frames with this share of the last good one's "
                                       "PnP inliers are tracked from (null: never)",
    "tracking.scaled_relative": "when PnP fails: the tracks' essential matrix, its length from the map points",
    "tracking.scaled_relative.enabled": "try it before the direct-alignment fallback",
    "tracking.scaled_relative.min_tracks": "essential-matrix inliers needed",
    "tracking.scaled_relative.min_points": "map points that must agree on the step length",
    "tracking.scaled_relative.thresh_px": "essential-matrix RANSAC threshold (px)",
    "tracking.scaled_relative.point_thresh_px": "reprojection error of an agreeing map point (px)",
    "tracking.scaled_relative.min_flow_px": "rotation-compensated median flow needed (px)",
    "init": "two-view initialisation",
    "init.two_view": "gates of the two-view geometry",
    "init.two_view.min_points": "tracks shared with the reference needed to try",
    "init.two_view.min_inliers": "inliers of the chosen model (homography or essential) needed",
    "init.two_view.min_flow_px": "median flow under which a non-rotating pair is low-parallax (px)",
    "init.two_view.min_parallax_deg": "parallax the min_triangulated-th best point needs (deg)",
    "init.two_view.min_point_parallax_deg": "parallax a triangulated point needs (deg)",
    "init.two_view.ransac_thresh_px": "essential-matrix RANSAC threshold (px; homography: twice)",
    "init.two_view.homography_ratio": "S_H / (S_H + S_F) above which the homography is used",
    "init.two_view.min_good_ratio": "share of the model's inliers that must agree with the motion",
    "init.two_view.max_reproj_px": "largest reprojection error of a triangulated point (px)",
    "init.two_view.min_triangulated": "triangulated points needed",
    "init.min_shared_ratio": "share of the reference's tracks under which it is replaced",
    "init.max_history": "frames since the reference kept for posing by PnP",
    "init.static_flow_mrad": "median flow under which the camera counts as at rest (mrad: px / focal length)",
    "init.min_pnp_inliers": "PnP inliers to pose a frame between the two views",
    "init.pnp_thresh_px": "PnP RANSAC threshold for those frames (px)",
    "recovery": "relocalisation in the lost map (ORB keyframe retrieval + PnP) after a loss",
    "recovery.enabled": "try relocalisation before starting a new map",
    "recovery.max_features": "ORB descriptors kept per keyframe",
    "recovery.max_keyframes": "keyframes of the current map kept for relocalisation, the newest (bounds the memory)",
    "recovery.max_bridge_frames": "unusable frames after which the map is searched first (without an IMU; with one "
                                  "the gyro predicts the tracks, and the map is searched if they fail)",
    "recovery.reloc": "relocalisation gates (ORB-SLAM's)",
    "vio": "visual-inertial odometry, when the recording has an IMU",
    "vio.enabled": "run VIO when the recording has an IMU (false, or --no-imu: the VO alone)",
    "vio.imu_noise_scale": "factor on the IMU's noise densities and random walks",
    "vio.window_keyframes": "keyframes in the fixed-lag smoother",
    "vio.static_init_s": "still this long from the start: static initialisation (s; 0: never)",
    "vio.dynamic_init": "the dynamic visual-inertial initialisation from VO keyframes",
    "vio.dynamic_init.min_keyframes": "VO keyframes the dynamic initialisation needs",
    "vio.dynamic_init.max_window_s": "longest span of VO keyframes the dynamic initialisation uses (s)",
    "vio.min_tracks": "fewer tracks than this and the IMU bridges the frame",
    "vio.reinit_on_check_failure": "re-initialise the smoother when a consistency check fails",
    "vio.reinit_after_s": "a scale or bias-drift check must fail this long before it re-initialises (s; 0: at once)",
    "vio.dynamic_init.max_scale_rel_std": "scale std / scale the dynamic initialisation must reach",
    "vio.dynamic_init.max_gravity_std_deg": "gravity-direction std the dynamic initialisation must reach (deg)",
    "vio.dynamic_init.max_scale_drift": "largest change of the VO's scale across the initialisation window "
                                        "(0.1: 10 %; a drifting window is cut to its newer half)",
    "vio.max_smear_px": "predicted smear (px, rotation + translation) above which the IMU bridges a frame "
                        "(after tracking, without exposure times: unless PnP posed it)",
    "vio.track_smear_px": "while the VIO runs, a frame the blur score calls blurred is tracked if its predicted "
                          "smear is at most this (px)",
    "vio.zero_velocity": "zero-velocity update while the tracks and the IMU both say the platform stands",
    "vio.zero_velocity.window_s": "seconds over which tracks and IMU must both say standstill",
    "vio.zero_velocity.max_flow_mrad": "median track displacement over the window below which the image says still "
                                       "(mrad: px / focal length)",
    "vio.zero_velocity.min_tracks": "tracks shared across the window needed to judge standstill",
    "vio.zero_velocity.sigma_m_s": "std (m/s) of the zero-velocity update at standstill (0: off)",
    "vio.wheel_sigma_m_s": "std of the wheel-odometry body velocity (m/s; 0: wheels not used; --wheels: 0.05)",
    "recovery.link": "placing a new map by the 3-D points it shares with the previous one",
    "recovery.link.min_common": "shared points needed",
    "recovery.link.min_inlier_ratio": "share of them the similarity must explain",
    "recovery.link.rel_thresh": "inlier gate, relative to the points' median spread",
    "recovery.link.iterations": "RANSAC draws",
    "recovery.reloc.n_corners": "corners of the tracker's detector described in the lost frame",
    "recovery.reloc.n_features": "multi-scale ORB features added to them",
    "recovery.reloc.ratio": "Lowe's ratio test of descriptor matches",
    "recovery.reloc.max_hamming": "largest Hamming distance of an appearance match (of 256 bits)",
    "recovery.reloc.min_matches": "matches a keyframe needs to be tried",
    "recovery.reloc.max_candidates": "keyframes tried, best bag-of-words score first",
    "recovery.reloc.recent_candidates": "the newest keyframes, tried as well",
    "recovery.reloc.pnp_thresh_px": "PnP inlier gate (px)",
    "recovery.reloc.min_inliers": "inliers the final pose needs",
    "recovery.reloc.search_radius_px": "radius of the search by projection (px)",
    "recovery.reloc.guided_max_hamming": "largest Hamming distance in the search by projection",
    "mapping": "keyframes, triangulation and local bundle adjustment",
    "mapping.keyframes": "keyframe policy",
    "mapping.keyframes.max_gap": "frames at most between keyframes",
    "mapping.keyframes.min_track_ratio": "share of the last keyframe's points still tracked",
    "mapping.keyframes.parallax_px": "median parallax of the common tracks that makes a keyframe (px)",
    "mapping.keyframes.min_common": "fewest tracks shared with the last keyframe",
    "mapping.anchor_refine": "re-track keyframe points from the image where they started",
    "mapping.anchor": "anchor re-tracking",
    "mapping.anchor.win_size": "LK window (px)",
    "mapping.anchor.max_shift_px": "largest accepted disagreement with the frame-to-frame track (px)",
    "mapping.anchor.photometric": "compensate the brightness change first",
    "mapping.anchor.pyr_levels": "pyramid levels of the re-tracking LK",
    "mapping.mapper": "triangulation and local BA",
    "mapping.mapper.ba_window": "keyframes optimised by the local BA",
    "mapping.mapper.ba_fixed": "older keyframes held fixed (gauge)",
    "mapping.mapper.ba_backend": "gtsam (LM, SEQUENTIAL_CHOLESKY), schur (the same LM in NumPy) or scipy",
    "mapping.mapper.ba_iterations": "LM iterations",
    "mapping.mapper.huber_px": "Huber threshold of the BA (px)",
    "mapping.mapper.cull_px": "points with a larger residual are removed after BA (px)",
    "mapping.mapper.tri_min_parallax_deg": "parallax a new point needs (deg)",
    "mapping.mapper.tri_max_reproj_px": "largest reprojection error of a new point (px)",
    "scale": "metric scale sources",
    "scale.camera_height_m": "camera height above a flat floor (m); null when unknown",
    "scale.half_window": "keyframes on each side of the running median of scale readings",
    "scale.wheel": "scale from wheel odometry (replaces the camera height when the recording has it)",
    "scale.wheel.enabled": "use the recording's wheel odometry for the scale (a ground robot)",
    "scale.wheel.min_distance_m": "wheel distance between keyframes below which a pair gives no reading (m)",
    "scale.wheel.max_turn_deg": "keyframe pairs that turned more give no reading (deg)",
    "scale.wheel.half_window": "keyframe readings on each side of the running median",
    "scale.wheel.factor": "metres the wheels read per metre driven (a calibration: summary.json "
                          "wheel_calibration.factor of a run without --wheels); wheel readings are divided by it "
                          "(--wheel-factor)",
    "output": "what is written",
    "output.final_refine": "refine non-keyframe poses against the final map",
}


def _fields(cls: type) -> dict[str, Any]:
    """name -> resolved type of a config dataclass's fields, the nested seeds left out."""
    hints = typing.get_type_hints(cls)
    return {f.name: hints[f.name] for f in dataclasses.fields(cls)
            if f.name != _SEED or cls is PipelineConfig}


def _is_config(tp: Any) -> bool:
    return isinstance(tp, type) and dataclasses.is_dataclass(tp)


# Ranges of the keys whose meaning fixes one (the command-line options state the same ranges);
# every other number is held to +-MAX_ABS_NUMBER: a larger one is a typo, and it would overflow.
KEY_BOUNDS: dict[str, tuple[float, float]] = {
    "seed": (0, 2**32 - 1),
    "scale.camera_height_m": (0.01, 100.0),
    "scale.wheel.min_distance_m": (0.0, 100.0),
    "scale.wheel.max_turn_deg": (0.0, 180.0),
    "scale.wheel.half_window": (0, 10_000),
    "scale.wheel.factor": (0.5, 2.0),
    "tracking.blurred_reference_ratio": (0.0, 1000.0),
    "tracking.scaled_relative.min_tracks": (8, 1_000_000),
    "tracking.scaled_relative.min_points": (2, 1_000_000),
    "tracking.scaled_relative.thresh_px": (1e-3, 1000.0),
    "tracking.scaled_relative.point_thresh_px": (1e-3, 1000.0),
    "tracking.scaled_relative.min_flow_px": (0.0, 10_000.0),
    "recovery.max_keyframes": (1, 1_000_000),
    "recovery.max_features": (1, 65_535),  # a keyframe's word counts are kept as uint16
}
MAX_ABS_NUMBER = 1e9


def _in_bounds(key: str, value: float, where: str) -> float:
    lo, hi = KEY_BOUNDS.get(key, (-MAX_ABS_NUMBER, MAX_ABS_NUMBER))
    if not lo <= value <= hi:
        rng = ", ".join(str(int(b)) if float(b).is_integer() else f"{b:g}" for b in (lo, hi))
        raise ConfigError(f"{where}: key '{key}' must be in [{rng}], got {value!r}")
    return value


def _check_value(key: str, tp: Any, value: Any, where: str) -> Any:
    """``value`` converted to ``tp`` or a ConfigError naming the key."""
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        args = typing.get_args(tp)
        if value is None and type(None) in args:
            return None
        inner = [a for a in args if a is not type(None)]
        if len(inner) == 1:
            return _check_value(key, inner[0], value, where)
    if isinstance(tp, type) and issubclass(tp, enum.Enum):
        try:
            return tp(value)
        except ValueError:
            allowed = ", ".join(str(m.value) for m in tp)
            raise ConfigError(f"{where}: key '{key}' must be one of {allowed}, got {value!r}") from None
    if tp is bool:
        if not isinstance(value, bool):
            raise ConfigError(f"{where}: key '{key}' must be true or false, got {value!r}")
        return value
    if tp is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise ConfigError(f"{where}: key '{key}' must be an integer, got {value!r}")
        return _in_bounds(key, value, where)
    if tp is float:
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise ConfigError(f"{where}: key '{key}' must be a number, got {value!r}")
        if value != value or value in (float("inf"), float("-inf")):
            raise ConfigError(f"{where}: key '{key}' must be finite, got {value!r}")
        return float(_in_bounds(key, value, where))
    if tp is str:
        if not isinstance(value, str):
            raise ConfigError(f"{where}: key '{key}' must be a string, got {value!r}")
        return value
    raise ConfigError(f"{where}: key '{key}' has a type ({tp}) that files cannot set")


def _build(base: Any, data: dict[str, Any], where: str, prefix: str = "") -> Any:
    """``base`` (a config instance) with the keys of ``data`` replaced, recursively."""
    known = _fields(type(base))
    changes: dict[str, Any] = {}
    for k, v in data.items():
        key = f"{prefix}{k}"
        if not isinstance(k, str) or k not in known:
            hint = " (there is one seed, at the top level)" if k == _SEED else ""
            raise ConfigError(f"{where}: unknown key '{key}'{hint}")
        tp = known[k]
        if _is_config(tp):
            if not isinstance(v, dict):
                raise ConfigError(f"{where}: key '{key}' must be a mapping of its fields, got {v!r}")
            changes[k] = _build(getattr(base, k), v, where, key + ".")
        else:
            changes[k] = _check_value(key, tp, v, where)
    try:
        return dataclasses.replace(base, **changes)
    except (ValueError, TypeError) as err:
        raise ConfigError(f"{where}: {prefix.rstrip('.') or 'config'}: {err}") from None


def config_from_dict(data: dict[str, Any], where: str = "config") -> PipelineConfig:
    """A PipelineConfig from a (YAML-shaped) mapping; ``where`` names the source in errors."""
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: the file must hold a mapping of config keys")
    cfg = _build(PipelineConfig(), data, where)
    if not isinstance(cfg, PipelineConfig):
        raise ConfigError(f"{where}: not a pipeline configuration")
    return cfg


def load_config(path: Path) -> PipelineConfig:
    """Read a YAML config file (keys = field names; absent keys keep their defaults)."""
    import yaml

    try:
        text = path.read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the config file ({err.strerror})") from None
    except UnicodeDecodeError:
        raise ConfigError(f"{path}: not a UTF-8 text file (a YAML config is text)") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as err:
        mark = getattr(err, "problem_mark", None)
        line = f" line {mark.line + 1}" if mark is not None else ""
        raise ConfigError(f"{path}:{line} not valid YAML") from None
    return config_from_dict({} if data is None else data, str(path))


def config_to_dict(cfg: Any) -> dict[str, Any]:
    """The tree as plain values (enums by value), nested seeds left out."""
    out: dict[str, Any] = {}
    for name in _fields(type(cfg)):
        v = getattr(cfg, name)
        if _is_config(type(v)):
            out[name] = config_to_dict(v)
        elif isinstance(v, enum.Enum):
            out[name] = v.value
        else:
            out[name] = v
    return out


def dump_config(cfg: PipelineConfig | None = None) -> str:
    """YAML text of ``cfg`` (defaults when None) with a comment per field."""
    import yaml

    lines: list[str] = ["# amrvio pipeline configuration; keys are the field names"]

    def emit(obj: Any, prefix: str, indent: int) -> None:
        for name in _fields(type(obj)):
            key = f"{prefix}{name}"
            v = getattr(obj, name)
            pad = "  " * indent
            lines.append(f"{pad}# {HELP.get(key, '')}".rstrip())
            if _is_config(type(v)):
                lines.append(f"{pad}{name}:")
                emit(v, key + ".", indent + 1)
            else:
                val = v.value if isinstance(v, enum.Enum) else v
                text = yaml.safe_dump(val, default_flow_style=True).strip()
                text = text.removesuffix("...").strip()
                lines.append(f"{pad}{name}: {text}")

    emit(cfg or PipelineConfig(), "", 0)
    return "\n".join(lines) + "\n"


def all_keys(cls: type = PipelineConfig, prefix: str = "") -> list[str]:
    """Every settable dotted key of the tree."""
    keys: list[str] = []
    for name, tp in _fields(cls).items():
        keys.append(prefix + name)
        if _is_config(tp):
            keys += all_keys(tp, prefix + name + ".")
    return keys


def without_photometric(cfg: PipelineConfig) -> PipelineConfig:
    """The brightness-constancy ablation: no affine compensation in KLT, anchor re-tracking and
    direct alignment (three config fields)."""
    tr, mp = cfg.tracking, cfg.mapping
    return dataclasses.replace(
        cfg,
        tracking=dataclasses.replace(tr, klt=dataclasses.replace(tr.klt, photometric=False),
                                     direct=dataclasses.replace(tr.direct, estimate_affine=False)),
        mapping=dataclasses.replace(mp, anchor=dataclasses.replace(mp.anchor, photometric=False)))


__all__ = ["HELP", "NOISE_GATES_PX", "OutputConfig", "PipelineConfig", "all_keys", "config_from_dict",
           "config_to_dict", "dump_config", "in_tracked_pixels", "load_config", "without_photometric"]
