"""Lens black-outs: time ranges during which the lens is covered (no light reaches the sensor).

A frame collects light only while its exposure window is uncovered
(amrvio.sim.image_formation.render_frame, ``lens_covered``): a frame exposed entirely inside a
black-out is the sensor's response at zero irradiance (read noise only, a near-black image); a
frame whose exposure straddles an edge collects the light of its uncovered part. The motion, the IMU
and the wheel odometry go on. ``--blackout T0:DUR`` covers [T0, T0 + DUR) seconds of motion time
(frame k is exposed around (k + 1/2) / fps).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from amrvio.errors import ConfigError


@dataclass(frozen=True, slots=True)
class Blackout:
    """The lens is covered over [t0_s, t0_s + dur_s) (motion time, seconds)."""

    t0_s: float
    dur_s: float

    @property
    def t1_s(self) -> float:
        return self.t0_s + self.dur_s


def parse_blackouts(spec: str, seconds: float | None = None) -> tuple[Blackout, ...]:
    """Parse ``"t0:dur,..."`` (seconds) into black-outs sorted by start. Raises ConfigError (one line)
    for a malformed item, a negative or non-finite start, a duration <= 0, a range that ends after
    ``seconds`` (the sequence length, when given) and overlapping ranges."""
    out: list[tuple[str, Blackout]] = []
    for item in (s.strip() for s in spec.split(",")):
        if not item:
            continue
        parts = item.split(":")
        try:
            if len(parts) != 2:
                raise ValueError
            t0, dur = (float(p) for p in parts)
        except ValueError:
            raise ConfigError(f"--blackout item {item!r} is not 'T0:DUR' in seconds (e.g. '4.0:1.0')") from None
        if not (math.isfinite(t0) and math.isfinite(dur)) or t0 < 0.0 or dur <= 0.0:
            raise ConfigError(f"--blackout item {item!r}: need finite T0 >= 0 and DUR > 0 (seconds)")
        if seconds is not None and t0 + dur > seconds + 1e-9:
            raise ConfigError(f"--blackout item {item!r}: the range [{t0:g}, {t0 + dur:g}) s ends after "
                              f"the {seconds:g} s sequence")
        out.append((item, Blackout(t0, dur)))
    out.sort(key=lambda ib: ib[1].t0_s)
    for (ia, a), (ib, b) in zip(out, out[1:], strict=False):
        if b.t0_s < a.t1_s:
            raise ConfigError(f"--blackout items {ia!r} and {ib!r} overlap; give one range")
    return tuple(b for _, b in out)


def open_pieces(t_start_s: float, exposure_s: float,
                covered: Sequence[tuple[float, float]]) -> list[tuple[float, float]]:
    """The parts (start, duration) of the exposure [t_start_s, t_start_s + exposure_s] outside every
    covered interval [a, b); in time order, pieces shorter than 1 ns dropped. An exposure that no
    interval touches is returned as is: ``[(t_start_s, exposure_s)]``."""
    end = t_start_s + exposure_s
    touching = sorted((a, b) for a, b in covered if a < end and b > t_start_s)
    if not touching:
        return [(t_start_s, exposure_s)]
    pieces: list[tuple[float, float]] = []
    t = t_start_s
    for a, b in touching:
        if a - t > 1e-9:
            pieces.append((t, a - t))
        t = max(t, b)
        if t >= end:
            break
    if end - t > 1e-9:
        pieces.append((t, end - t))
    return pieces


@dataclass(frozen=True, slots=True)
class BlackoutFrames:
    """The frames a black-out touches: ``dark`` frames were exposed entirely inside it (indices
    into the sequence, consecutive), ``partial`` ones straddle one of its edges."""

    blackout: Blackout
    dark: tuple[int, ...]
    partial: tuple[int, ...]


def frames_touched(blackout: Blackout, t_starts_s: Sequence[float],
                   exposures_s: Sequence[float]) -> BlackoutFrames:
    """Which frames (exposure k over [t_starts_s[k], t_starts_s[k] + exposures_s[k]]) ``blackout``
    darkens entirely or in part."""
    dark: list[int] = []
    partial: list[int] = []
    for k, (s, e) in enumerate(zip(t_starts_s, exposures_s, strict=True)):
        if s >= blackout.t0_s and s + e <= blackout.t1_s:
            dark.append(k)
        elif s < blackout.t1_s and s + e > blackout.t0_s:
            partial.append(k)
    return BlackoutFrames(blackout, tuple(dark), tuple(partial))
