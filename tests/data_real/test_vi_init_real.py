"""The VI initialiser on the real EuRoC V1_01 flight (../shared/data), a subset of the windows of
bench/bench_vi_init.py (issue 10, "Done when"): ground-truth camera poses / 3.7 with seeded noise
(0.3 mm, 0.02 deg), 10 Hz keyframes, the recorded IMU.

What must hold on every window: a window called OK has its scale within 2 % and gravity within
1 deg; the reported standard deviations cover the errors; the rest at the start is
INSUFFICIENT_EXCITATION, and solved anyway it gives no usable scale. The control (the IMU
synthesised from the ground truth, with its biases and the datasheet's noise) makes a window that
the recorded IMU leaves uncertain OK."""

from __future__ import annotations

from pathlib import Path

import pytest
from threadpoolctl import threadpool_limits

from amrvio.estimator.vi_init import ViInitConfig, ViInitStatus
from bench.bench_vi_init import WindowOutcome, make_case, run_case
from bench.euroc_v101 import EurocFlight, accel_gain, accel_gain_bracket, load_flight, synthetic_flight
from tests.skip_policy import skip_shared_missing

pytestmark = pytest.mark.real_data

FLIGHT_STARTS_S = (20.0, 120.0)  # 8 s windows, in flight


@pytest.fixture(scope="module")
def flight(shared_data: Path) -> EurocFlight:
    root = shared_data / "euroc_V1_01_easy_first95"
    if not (root / "mav0" / "imu0" / "data.csv").is_file():
        skip_shared_missing(root / "mav0" / "imu0" / "data.csv")
    return load_flight(root)


@pytest.fixture(scope="module")
def outcomes(flight: EurocFlight) -> list[WindowOutcome]:
    with threadpool_limits(limits=1, user_api="blas"):  # small matrices: threads only cost
        return [run_case(flight, make_case(flight, s, 8.0)) for s in FLIGHT_STARTS_S]


def test_windows_called_ok_are_within_2_percent_and_1_degree(outcomes: list[WindowOutcome]) -> None:
    for o in outcomes:
        st = o.result.state
        assert st is not None and st.scale > 0, o.case.start_s
        if o.result.status is ViInitStatus.OK:
            assert abs(o.scale_err) < 0.02 and o.gravity_err_deg < 1.0, o.case.start_s
        else:  # in flight every failure is an uncertainty verdict, with advice
            assert o.result.status in (ViInitStatus.SCALE_UNCERTAIN, ViInitStatus.GRAVITY_UNCERTAIN), o.case.start_s
            assert o.result.advice


def test_reported_std_covers_the_error(outcomes: list[WindowOutcome]) -> None:
    for o in outcomes:
        st = o.result.state
        assert st is not None
        rel_std = st.scale_std / st.scale
        # the recorded IMU limits an 8 s window to about 1 % (measured 0.8 to 1.4 %)
        assert 0.002 < rel_std < 0.02, o.case.start_s
        assert abs(o.scale_err) < 3.0 * rel_std, o.case.start_s
        assert o.gravity_err_deg < max(3.0 * st.gravity_std_deg, 0.2), o.case.start_s
        fig = o.result.figures
        assert fig is not None and fig.vo_position_sigma_m == pytest.approx(0.0003, rel=0.5)  # the noise added


def test_rest_at_the_start_is_insufficient_excitation(flight: EurocFlight) -> None:
    with threadpool_limits(limits=1, user_api="blas"):
        # the MAV sits on the floor for its first 5.2 s; from 2 s on its rotors shake the IMU
        spun = run_case(flight, make_case(flight, 2.0, 3.0), ViInitConfig())
        res = run_case(flight, make_case(flight, 0.0, 3.0), ViInitConfig())
    ex = spun.result.excitation
    assert spun.result.status is ViInitStatus.INSUFFICIENT_EXCITATION
    assert ex is not None and ex.accel_std_m_s2 > 0.25 and ex.translation_snr < 10.0  # measured 0.68, 3.7
    assert "does not translate" in spun.result.advice
    assert res.result.status is ViInitStatus.INSUFFICIENT_EXCITATION
    ex = res.result.excitation
    assert ex is not None and ex.accel_std_m_s2 < 0.25 and ex.rotation_range_deg < 2.0
    assert "accelerate forward" in res.result.advice
    # solved anyway, it has no usable scale: none at all, or far off
    assert res.result.state is None or res.result.state.scale <= 0 or abs(res.scale_err) > 0.1


def test_with_an_imu_that_fits_its_model_the_window_is_ok(flight: EurocFlight) -> None:
    control = synthetic_flight(flight)
    with threadpool_limits(limits=1, user_api="blas"):
        recorded = run_case(flight, make_case(flight, 60.0, 8.0))
        synthetic = run_case(control, make_case(control, 60.0, 8.0))
    assert recorded.result.status is ViInitStatus.SCALE_UNCERTAIN  # measured 1.2 % std
    assert synthetic.result.status is ViInitStatus.OK
    assert abs(synthetic.scale_err) < 0.02 and synthetic.gravity_err_deg < 1.0  # measured -0.19 %, 0.39 deg
    fig_r, fig_s = recorded.result.figures, synthetic.result.figures
    assert fig_r is not None and fig_s is not None
    # the recorded accelerometer is several times noisier than its datasheet on the flying MAV (28.5 vs 2.0)
    assert fig_r.accel_noise_factor > 5.0 * fig_s.accel_noise_factor


def test_recorded_accelerometer_reads_short_of_the_ground_truth_and_the_control_does_not(flight: EurocFlight) -> None:
    # bench_vi_init's mean scale error of about -1 %: the recorded IMU reads 0.5-1.5 % short along
    # every world axis, with no time offset that explains it; the IMU synthesised from the ground
    # truth (another route: the replay spline's exact specific force) reads its acceleration to 0.3 %
    gain, per_axis = accel_gain(flight)
    assert 0.985 < gain < 0.995 and all(0.985 < g < 0.995 for g in per_axis)
    assert max(accel_gain(flight, s)[0] for s in (-0.02, -0.01, 0.01, 0.02)) < 0.995
    synthetic = synthetic_flight(flight)
    control, control_axes = accel_gain(synthetic)
    assert abs(control - 1.0) < 0.003 and all(abs(g - 1.0) < 0.003 for g in control_axes)
    # not noise in the differentiated ground truth (which lowers that slope alone): over 1 s
    # averages the bracket that holds the gain whatever noise either side carries lies below 1
    # (measured 0.9902-0.9928), and the control's holds it (1.0002-1.0002)
    low, high = accel_gain_bracket(flight, 1.0)
    assert low <= high < 0.996
    c_low, c_high = accel_gain_bracket(synthetic, 1.0)
    assert c_low <= c_high and abs(c_low - 1.0) < 0.002 and abs(c_high - 1.0) < 0.002
