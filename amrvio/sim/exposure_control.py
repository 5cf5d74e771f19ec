"""Per-frame exposure times: fixed, scripted EV steps, or an auto-exposure P-controller.

EV is the log2 ratio of exposure times: +1 EV doubles the exposure. Every exposure is clamped to
[min_exposure_s, max_fraction * frame period] so that it fits in the frame period.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from amrvio.errors import ConfigError

F64 = NDArray[np.float64]


def parse_ev_steps(spec: str) -> tuple[tuple[float, float], ...]:
    """Parse ``"t1:+1,t2:-0.5"`` -> ((t1, +1.0), (t2, -0.5)), sorted by time. Raises ConfigError."""
    out: list[tuple[float, float]] = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        parts = item.split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            t, ev = float(parts[0]), float(parts[1])
        except ValueError:
            raise ConfigError(f"--ev-steps item {item!r} is not 't_s:ev' (e.g. '2.0:+1')") from None
        if not (math.isfinite(t) and math.isfinite(ev)) or t < 0:
            raise ConfigError(f"--ev-steps item {item!r}: need a finite time >= 0 and a finite EV")
        out.append((t, ev))
    return tuple(sorted(out))


@dataclass(frozen=True, slots=True)
class ExposureLimits:
    frame_period_s: float
    min_exposure_s: float = 50e-6
    max_fraction: float = 0.9  # leave readout time inside the frame period

    @property
    def max_exposure_s(self) -> float:
        return self.max_fraction * self.frame_period_s

    def clamp(self, exposure_s: float) -> float:
        return float(min(max(exposure_s, self.min_exposure_s), self.max_exposure_s))


def scripted_exposures(
    frame_times_s: ArrayLike, base_exposure_s: float, ev_steps: tuple[tuple[float, float], ...],
    limits: ExposureLimits,
) -> F64:
    """Exposure of each frame: base * 2^(sum of the EV steps at or before the frame time)."""
    t = np.asarray(frame_times_s, dtype=np.float64)
    ev = np.zeros_like(t)
    for t_step, d_ev in ev_steps:
        ev += np.where(t >= t_step, d_ev, 0.0)
    return np.array([limits.clamp(base_exposure_s * 2.0**e) for e in ev])


@dataclass(frozen=True, slots=True)
class AutoExposure:
    """P-control of the mean image intensity (in DN) towards ``target_dn`` in log-exposure.

    next = exposure * (target / mean)^gain, the change limited to +-max_ev_per_frame EV.
    """

    target_dn: float = 110.0
    gain: float = 0.5
    max_ev_per_frame: float = 0.25

    def __post_init__(self) -> None:
        if not (0 < self.target_dn < 255) or not (0 < self.gain <= 1) or self.max_ev_per_frame <= 0:
            raise ConfigError(
                "auto-exposure needs 0 < target_dn < 255, 0 < gain <= 1, max_ev_per_frame > 0"
            )

    def next_exposure(self, exposure_s: float, mean_dn: float, limits: ExposureLimits) -> float:
        d_ev = self.gain * (math.log2(self.target_dn) - math.log2(max(mean_dn, 0.5)))
        d_ev = max(-self.max_ev_per_frame, min(self.max_ev_per_frame, d_ev))
        return limits.clamp(exposure_s * 2.0**d_ev)
