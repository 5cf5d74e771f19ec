"""Scale sources: readings that make the up-to-scale map metric: the known camera height
(a ground-plane fit at each keyframe, ``estimator.camera_height``) or wheel odometry
(``estimator.wheel_scale``); the VIO stage brings its own metric scale. Each source reads
keyframes as they are made and gives a per-frame scale at the end."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from amrvio.estimator.camera_height import HeightEstimate, height_at_keyframe, smooth_scales
from amrvio.estimator.local_mapping import Segment
from amrvio.estimator.wheel_scale import WheelScale, WheelScaleConfig
from amrvio.types.sensors import WheelData

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class ScaleConfig:
    """``camera_height_m``: the camera's height above a flat floor (m), None when unknown;
    ``half_window``: keyframes on each side of the running median of the scale readings;
    ``wheel``: the wheel-odometry source, used instead when the recording has wheel odometry."""

    camera_height_m: float | None = None
    half_window: int = 10
    wheel: WheelScaleConfig = field(default_factory=WheelScaleConfig)


class CameraHeightScale:
    """Scale from the known camera height: one ground-plane reading per keyframe."""

    def __init__(self, config: ScaleConfig, seed: int) -> None:
        self.cfg = config
        self.seed = seed
        self.readings: list[HeightEstimate] = []
        self.timings: dict[str, float] = {}

    @property
    def active(self) -> bool:
        return self.cfg.camera_height_m is not None

    def observe_keyframe(self, segment: Segment, kf_id: int) -> HeightEstimate | None:
        """Read the camera height at keyframe ``kf_id`` of ``segment`` (None when inactive)."""
        if self.cfg.camera_height_m is None:
            return None
        t0 = time.perf_counter()
        m = segment.mapper.map
        kf = m.keyframes[kf_id]
        has = m.points_of(kf.track_ids)
        est = height_at_keyframe(kf.frame_index, kf.T_cam_world, m.xyz[kf.track_ids[has]],
                                 self.cfg.camera_height_m, segment_scale=segment.world_from_segment.s,
                                 seed=self.seed)
        self.readings.append(est)
        self.timings["scale"] = self.timings.get("scale", 0.0) + time.perf_counter() - t0
        return est

    def frame_scales(self, n_frames: int, stamps_ns: NDArray[np.int64] | None = None) -> F64:
        """(n_frames,) metric scale per frame (ones when inactive or without a valid reading);
        ``stamps_ns`` is not needed here (the wheel source's signature)."""
        if self.cfg.camera_height_m is None:
            return np.ones(n_frames)
        return smooth_scales(self.readings, n_frames, self.cfg.half_window)


def make_scale_source(config: ScaleConfig, seed: int, wheel: WheelData | None = None
                      ) -> CameraHeightScale | WheelScale:
    """The wheel-odometry source when the recording has wheel odometry and it is enabled, else
    the camera height (inactive when no height is configured)."""
    if wheel is not None and config.wheel.enabled:
        return WheelScale(wheel, config.wheel)
    return CameraHeightScale(config, seed)


__all__ = ["CameraHeightScale", "ScaleConfig", "make_scale_source"]
