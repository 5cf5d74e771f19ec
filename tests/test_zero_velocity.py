"""The zero-velocity detector (:mod:`amrvio.pipeline.zero_velocity`) on synthetic tracks and IMU
samples with known motion: standstill is flagged once the window is full, a slow translation
(closed-form flow) or a rotation is not, and too few tracks or a broken chain are not judged."""

from __future__ import annotations

import numpy as np
import pytest

from amrvio.errors import ConfigError
from amrvio.imu.static import StandstillStatus
from amrvio.pipeline.vio_report import VioPhase, VioReport
from amrvio.pipeline.zero_velocity import ZeroVelocity, ZeroVelocityConfig, ZeroVelocityDetector
from amrvio.types.sensors import ImuData

FPS, IMU_HZ, G = 20.0, 200.0, 9.81
F_PX = 229.36  # EuRoC's focal length at 376x240
HALF_PX_MRAD = 1e3 * 0.5 / F_PX  # a gate of 0.5 px at F_PX


def _imu(seconds: float, rate_rad_s: float = 0.0, seed: int = 0) -> ImuData:
    """Samples of a level IMU at rest (or turning about gravity at ``rate_rad_s``)."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, 1.0 / IMU_HZ)
    n = len(t)
    gyro = np.tile([0.0, 0.0, rate_rad_s], (n, 1)) + 1e-3 * rng.standard_normal((n, 3))
    accel = np.tile([0.0, 0.0, G], (n, 1)) + 0.02 * rng.standard_normal((n, 3))
    return ImuData((t * 1e9).astype(np.int64), gyro, accel)


def _run(det: ZeroVelocityDetector, imu: ImuData, n_frames: int, step_px: float = 0.0,
         n_tracks: int = 60, noise_px: float = 0.05, seed: int = 1) -> list[ZeroVelocity]:
    """Frames whose ``n_tracks`` tracks move by ``step_px`` along u each frame."""
    rng = np.random.default_rng(seed)
    uv0 = rng.uniform(20, 300, (n_tracks, 2))
    ids = np.arange(n_tracks, dtype=np.int64)
    out = []
    for k in range(n_frames):
        t_ns = int(round((k + 0.5) / FPS * 1e9))
        uv = uv0 + [k * step_px, 0.0] + noise_px * rng.standard_normal(uv0.shape)
        out.append(det.update(t_ns, ids, uv, imu))
    return out


def test_standstill_is_flagged_once_the_window_is_full() -> None:
    det = ZeroVelocityDetector(ZeroVelocityConfig(window_s=0.3), F_PX)
    res = _run(det, _imu(2.0), 20)
    # the 0.3 s window holds 6 frame periods at 20 Hz: frames 0-5 have no reference yet
    assert [r.judged for r in res[:6]] == [False] * 6
    assert all(r.still for r in res[6:])
    assert all(r.imu is StandstillStatus.STILL and r.n_tracks == 60 for r in res[6:])
    # the median of |noise difference| of two 0.05 px draws per axis: 0.05 sqrt(2 ln 4) = 0.083 px
    assert np.median([r.flow_px for r in res[6:]]) == pytest.approx(0.05 * np.sqrt(2 * np.log(4)), rel=0.2)
    assert det.last is res[-1]


def test_a_slow_translation_is_not_standstill() -> None:
    det = ZeroVelocityDetector(ZeroVelocityConfig(window_s=0.3, max_flow_mrad=HALF_PX_MRAD), F_PX)
    # 0.1 px a frame: 0.6 px over the window (above the gate); the IMU alone would call it still
    res = _run(det, _imu(2.0), 20, step_px=0.1, noise_px=0.0)
    assert all(r.judged and not r.still for r in res[6:])
    assert all(r.flow_px == pytest.approx(0.6, abs=1e-9) for r in res[6:])
    assert all(r.imu is StandstillStatus.STILL for r in res[6:])
    # 0.05 px a frame (0.3 px over the window) is below it
    res = _run(ZeroVelocityDetector(ZeroVelocityConfig(window_s=0.3, max_flow_mrad=HALF_PX_MRAD), F_PX), _imu(2.0), 20,
               step_px=0.05, noise_px=0.0)
    assert all(r.still for r in res[6:])


def test_the_gate_is_an_angle_the_same_standstill_at_twice_the_resolution_is_still() -> None:
    # 0.1 px a frame at f = 229 px (0.6 px, 2.6 mrad over the window) moves; the same angle at
    # twice the resolution (0.2 px a frame at f = 459 px) too, and 0.1 px a frame there
    # (1.3 mrad: half the angle) is still, where a gate in pixels would call it moving
    cfg = ZeroVelocityConfig(window_s=0.3)
    assert ZeroVelocityDetector(cfg, 2 * F_PX).max_flow_px == pytest.approx(2 * ZeroVelocityDetector(cfg, F_PX).max_flow_px)
    assert not any(r.still for r in _run(ZeroVelocityDetector(cfg, F_PX), _imu(2.0), 20, step_px=0.1, noise_px=0.0))
    assert not any(r.still for r in _run(ZeroVelocityDetector(cfg, 2 * F_PX), _imu(2.0), 20, step_px=0.2,
                                         noise_px=0.0))
    assert all(r.still for r in _run(ZeroVelocityDetector(cfg, 2 * F_PX), _imu(2.0), 20, step_px=0.1,
                                     noise_px=0.0)[6:])
    with pytest.raises(ConfigError, match="focal length"):
        ZeroVelocityDetector(cfg, 0.0)


def test_a_rotating_imu_is_not_standstill_even_with_still_tracks() -> None:
    det = ZeroVelocityDetector(ZeroVelocityConfig(), F_PX)
    res = _run(det, _imu(2.0, rate_rad_s=0.3), 20)
    assert all(r.judged and not r.still and r.imu is StandstillStatus.ROTATING for r in res[6:])


def test_too_few_shared_tracks_or_a_reset_leave_the_frame_unjudged() -> None:
    det = ZeroVelocityDetector(ZeroVelocityConfig(min_tracks=20), F_PX)
    res = _run(det, _imu(2.0), 20, n_tracks=19)
    assert all(not r.still and not r.judged and r.n_tracks == 19 for r in res[6:])
    det = ZeroVelocityDetector(ZeroVelocityConfig(), F_PX)
    assert _run(det, _imu(2.0), 10)[-1].still
    det.reset()
    assert not det.last.judged
    t_ns = int(round(10.5 / FPS * 1e9))
    assert not det.update(t_ns, np.arange(60), np.zeros((60, 2)), _imu(2.0)).judged


@pytest.mark.parametrize("field,value", [("window_s", 0.0), ("window_s", float("nan")), ("max_flow_mrad", -1.0),
                                         ("min_tracks", 0), ("sigma_m_s", -0.01), ("sigma_m_s", float("inf"))])
def test_bad_config_is_refused(field: str, value: float) -> None:
    with pytest.raises(ConfigError, match=f"zero_velocity.{field}"):
        ZeroVelocityConfig(**{field: value})  # type: ignore[arg-type]


def test_health_columns_say_whether_the_update_had_zero_velocity() -> None:
    still = ZeroVelocity(True, 0.123, 40, StandstillStatus.STILL)
    f = VioReport(VioPhase.VIO, zero_velocity=still).health_fields()
    assert f["vio_zero_velocity"] == "1" and f["vio_zero_velocity_flow_px"] == "0.123"
    moving = ZeroVelocity(False, 3.0, 40, StandstillStatus.STILL)
    assert VioReport(VioPhase.VIO, zero_velocity=moving).health_fields()["vio_zero_velocity"] == "0"
    unjudged = VioReport(VioPhase.VIO, zero_velocity=ZeroVelocity(False, float("nan"), 3, None)).health_fields()
    assert unjudged["vio_zero_velocity"] == "" and unjudged["vio_zero_velocity_flow_px"] == ""


def test_observe_logs_the_start_and_end_of_a_standstill_and_resets_on_an_untracked_frame() -> None:
    from amrvio.pipeline.imu_log import ImuLog

    log = ImuLog(10.0)
    log.add(_imu(3.0))
    det = ZeroVelocityDetector(ZeroVelocityConfig(window_s=0.3), F_PX)
    ids, uv = np.arange(40, dtype=np.int64), np.random.default_rng(0).uniform(20, 300, (40, 2))
    events: list[list[str]] = []
    for k in range(20):
        ev: list[str] = []
        t_ns = int(round((k + 0.5) / FPS * 1e9))
        det.observe(t_ns, None if k == 12 else ids, uv + (0.0 if k < 15 else 0.5 * (k - 14)), log, ev)
        events.append(ev)
    # still from frame 6 (a full window); frame 12 is untracked: the window starts again at 13,
    # full at 19, but the tracks move by (0.5, 0.5) px a frame from frame 15 on
    assert events[6] == ["vio_zero_velocity:start:flow_px=0.000"]
    assert events[12] == ["vio_zero_velocity:end"]
    assert all(not e for k, e in enumerate(events) if k not in (6, 12))
    assert not det.last.still and det.last.flow_px == pytest.approx(2.5 * np.sqrt(2.0))  # (2.5, 2.5) px
