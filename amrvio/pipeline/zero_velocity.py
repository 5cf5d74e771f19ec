"""Zero-velocity detection for the VIO stage: standstill seen by both the camera and the IMU.

A platform that stands still has v = 0 exactly. The IMU alone cannot see this: its
preintegration drifts the velocity by the integrated accelerometer-bias error, a few cm/s per
second, and nothing in a window of views that all share one position can stop it (the landmarks
have no parallax, so they do not fix the positions either). Measured on the simulator replay of
EuRoC V1_01, whose MAV stands for 5 s before take-off: the smoothed speed reached 0.07-0.08 m/s
while standing. The zero-velocity update (ZUPT, as OpenVINS and most ground-robot VIO) adds the
measurement ``v_world = 0`` with ``sigma_m_s`` to a frame's velocity when, over the last
``window_s``:

- the image says so: the median displacement of the tracks this frame shares with the frame
  ``window_s`` earlier is at most ``max_flow_mrad`` as an angle (px / focal length; at least
  ``min_tracks`` of them). A slow translation ``v`` at depth ``Z`` moves them ``v window_s / Z``
  rad whatever the resolution, so 2.2 mrad over 0.3 s is at most 0.022 m/s at 3 m (0.5 px at
  f = 229 px, 1.0 px at f = 459 px): a moving platform with its scene within a few metres is not
  taken for still. A rotation moves every track, so turning on the spot is not still either (its
  velocity is zero, but nothing here needs that);
- the IMU says so: :func:`amrvio.imu.static.detect_standstill` on the same samples (steady
  gravity direction, specific force of norm g, small mean rate) rejects an accelerating
  platform whose scene is far away.

Both must hold. A scene that moves as a whole with the camera (a vehicle's cabin) or an IMU on a
platform at constant velocity with only distant texture would be taken for still; a recording
of those should set ``sigma_m_s = 0`` (off).
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ConfigError
from amrvio.estimator.initializer import STILL_MRAD, angle_px
from amrvio.imu.static import StandstillStatus, detect_standstill
from amrvio.pipeline.imu_log import ImuLog
from amrvio.types.sensors import ImuData

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]


@dataclass(frozen=True, slots=True)
class ZeroVelocityConfig:
    """See the module docstring. ``sigma_m_s``: standard deviation of the zero-velocity
    measurement per axis (0: detection still reported, no update made)."""

    window_s: float = 0.3
    max_flow_mrad: float = STILL_MRAD
    min_tracks: int = 20
    sigma_m_s: float = 0.02

    def __post_init__(self) -> None:
        if not (np.isfinite(self.window_s) and 0.0 < self.window_s <= 10.0):
            raise ConfigError(f"vio.zero_velocity.window_s must be in (0, 10] s, got {self.window_s}")
        if not (np.isfinite(self.max_flow_mrad) and self.max_flow_mrad > 0):
            raise ConfigError(f"vio.zero_velocity.max_flow_mrad must be > 0, got {self.max_flow_mrad}")
        if self.min_tracks < 1:
            raise ConfigError(f"vio.zero_velocity.min_tracks must be >= 1, got {self.min_tracks}")
        if not (np.isfinite(self.sigma_m_s) and self.sigma_m_s >= 0):
            raise ConfigError(f"vio.zero_velocity.sigma_m_s must be >= 0, got {self.sigma_m_s}")


@dataclass(frozen=True, slots=True)
class ZeroVelocity:
    """The verdict on one frame. ``still``: both the image and the IMU say standstill;
    ``flow_px``: median displacement of the shared tracks over the window (NaN when not judged);
    ``n_tracks``: how many tracks were shared; ``imu``: the IMU's verdict (None when the image
    was not judged: window not yet full, or too few shared tracks)."""

    still: bool
    flow_px: float
    n_tracks: int
    imu: StandstillStatus | None

    @property
    def judged(self) -> bool:
        return self.imu is not None


NOT_JUDGED = ZeroVelocity(False, float("nan"), 0, None)

TOL_NS = 1_000_000
"""A frame counts as ``window_s`` old when it is older than ``window_s`` less this (1 ms): frame
stamps are rounded, and the window must not flip between n and n + 1 frame periods."""


class ZeroVelocityDetector:
    """Keeps the tracks of the recent frames; :meth:`update` judges the newest (kept as
    :attr:`last`). ``focal_px``: the camera's focal length, which turns the angle gate into
    :attr:`max_flow_px`."""

    def __init__(self, config: ZeroVelocityConfig, focal_px: float) -> None:
        if not (np.isfinite(focal_px) and focal_px > 0):
            raise ConfigError(f"the zero-velocity detector needs a focal length > 0, got {focal_px}")
        self.cfg = config
        self.max_flow_px = angle_px(config.max_flow_mrad, float(focal_px))
        self._frames: deque[tuple[int, I64, F64]] = deque()
        self.last = NOT_JUDGED  # the newest verdict


    def reset(self) -> None:
        """Forget the frames (a frame whose tracks were not tracked into its image breaks the
        chain: the next verdict needs a full window again)."""
        self._frames.clear()
        self.last = NOT_JUDGED

    def observe(self, t_ns: int, ids: I64 | None, uv_px: F64, imu: ImuLog, events: list[str]) -> ZeroVelocity:
        """The frame loop's call: :meth:`update` with the samples of ``imu`` (the stage's log)
        over the window, or :meth:`reset` for a frame whose tracks were not moved into its image
        (``ids`` None). The start and end of a standstill are appended to ``events``
        (``vio_zero_velocity:start:flow_px=F`` / ``vio_zero_velocity:end``)."""
        was = self.last.still
        if ids is None:
            self.reset()
        else:
            self.update(t_ns, ids, uv_px, imu.span(t_ns - int(round(self.cfg.window_s * 1e9)) - TOL_NS, t_ns))
        if self.last.still != was:
            events.append("vio_zero_velocity:" + (f"start:flow_px={self.last.flow_px:.3f}" if self.last.still
                                                  else "end"))
        return self.last

    def update(self, t_ns: int, ids: I64, uv_px: F64, imu: ImuData) -> ZeroVelocity:
        """Judge the frame at ``t_ns`` with its tracks ``ids`` (N,) / ``uv_px`` (N, 2) and the IMU
        samples ``imu`` (the detector uses those within the window)."""
        self.last = self._judge(int(t_ns), ids, uv_px, imu)
        return self.last

    def _judge(self, t_ns: int, ids: I64, uv_px: F64, imu: ImuData) -> ZeroVelocity:
        cfg = self.cfg
        # the reference is the newest frame at least window_s old (TOL_NS: stamps in whole ns)
        win_ns = int(round(cfg.window_s * 1e9)) - TOL_NS
        frames = self._frames
        frames.append((t_ns, np.asarray(ids), np.asarray(uv_px, dtype=np.float64)))
        while len(frames) > 1 and frames[1][0] <= t_ns - win_ns:
            frames.popleft()
        t0, ids0, uv0 = frames[0]
        if t_ns - t0 < win_ns:  # no frame is window_s old yet
            return NOT_JUDGED
        _, i0, i1 = np.intersect1d(ids0, frames[-1][1], assume_unique=True, return_indices=True)
        if len(i0) < cfg.min_tracks:
            return ZeroVelocity(False, float("nan"), len(i0), None)
        flow = float(np.median(np.linalg.norm(frames[-1][2][i1] - uv0[i0], axis=1)))
        stand = detect_standstill(imu.window(t0, int(t_ns)))
        return ZeroVelocity(flow <= self.max_flow_px and stand.still, flow, len(i0), stand.status)


__all__ = ["NOT_JUDGED", "ZeroVelocity", "ZeroVelocityConfig", "ZeroVelocityDetector"]
