"""The diagnostics stage set up for a dataset (``pipeline.run.diagnose`` is the pipeline with
tracking off).

``amrvio run`` and ``amrvio diagnose`` build the same :class:`FrameDiagnostics` here, so the
health record of a run and of a diagnosis are computed by the same code in the same pass.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.frame import DiagnosticsConfig, FrameDiagnostics
from amrvio.imu.static import initial_standstill
from amrvio.io.base import Dataset

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True)
class DiagnosticsSetup:
    """The stage and the notes on how it was set up (assumed exposure, gyro bias)."""

    stage: FrameDiagnostics
    config: DiagnosticsConfig
    notes: tuple[str, ...]


def assumed_exposure_s(dataset: Dataset, assumed_ms: float | None) -> float | None:
    """Exposure used for the smear prediction when frames carry none: ``assumed_ms``, else half
    the frame period, at most 10 ms. None when the dataset has no IMU (no prediction)."""
    if dataset.imu is None or all(f.exposure_s is not None for f in dataset.frames):
        return None
    if assumed_ms is not None:
        return assumed_ms * 1e-3
    t = np.array([f.t_ns for f in dataset.frames], dtype=np.float64) * 1e-9
    period = float(np.median(np.diff(t))) if t.size > 1 else 0.05
    return min(0.010, 0.5 * period)


def setup_diagnostics(dataset: Dataset, config: DiagnosticsConfig,
                      gyro_bias: str | F64 = "auto",
                      assumed_ms: float | None = None) -> DiagnosticsSetup:
    """FrameDiagnostics for ``dataset``. ``gyro_bias``: "auto" (the mean gyro of a still first
    second, when it is still), "none", or a (3,) bias in rad/s."""
    notes: list[str] = []
    expo = assumed_exposure_s(dataset, assumed_ms)
    if expo is not None:
        notes.append(f"note: the dataset records no exposure times; the smear is predicted for an "
                     f"assumed {expo * 1e3:.1f} ms exposure (set --assumed-exposure-ms)")
        config = dataclasses.replace(config, assumed_exposure_s=expo)
    bias: F64 | None = None
    if isinstance(gyro_bias, np.ndarray):
        bias = gyro_bias
    elif gyro_bias == "auto" and dataset.imu is not None:
        bias = initial_standstill(dataset.imu).gyro_bias_rad_s
    if bias is not None:
        notes.append("note: gyro bias " + " ".join(f"{v:.5f}" for v in bias)
                     + " rad/s subtracted (from a still start, or --gyro-bias)")
    stage = FrameDiagnostics(config, dataset.camera, dataset.T_body_cam, dataset.inverse_response,
                             bias)
    return DiagnosticsSetup(stage, config, tuple(notes))


__all__ = ["DiagnosticsSetup", "assumed_exposure_s", "setup_diagnostics"]
