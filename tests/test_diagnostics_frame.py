"""The FrameDiagnostics stage, the advice text and the `amrvio diagnose` command."""

from __future__ import annotations

import csv
from pathlib import Path

import cv2
import numpy as np
import pytest

from amrvio.diagnostics.advice import make_advice
from amrvio.diagnostics.frame import HEALTH_COLUMNS, FrameDiagnostics, health_rows
from amrvio.errors import ShapeError
from amrvio.sim.simulate import SimConfig, simulate
from amrvio.types.camera import PinholeCamera


def _texture(shape: tuple[int, int] = (240, 320), seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    base = np.zeros(shape, np.float32)
    for s in (2, 4, 8, 16):
        n = rng.normal(size=(shape[0] // s + 2, shape[1] // s + 2)).astype(np.float32)
        base += cv2.resize(n, (shape[1] + 2 * s, shape[0] + 2 * s))[: shape[0], : shape[1]]
    base = (base - base.min()) / (base.max() - base.min())
    return np.asarray(30 + 170 * base, np.float32)


def _sequence(n: int = 12, step_at: int = 6, ev: float = 1.0) -> list[np.ndarray]:
    tex = _texture((260, 360))
    frames = []
    for i in range(n):
        crop = tex[10 + i // 2 : 250 + i // 2, 10 + i : 330 + i]
        gain = 2.0**ev if i >= step_at else 1.0
        frames.append(np.clip(np.round(crop * gain * 0.7), 0, 255).astype(np.uint8))
    return frames


def test_stage_flags_exposure_step_only_there_and_reports_rows() -> None:
    stage = FrameDiagnostics(camera=PinholeCamera(320, 240, 300.0, 300.0, 159.5, 119.5))
    recs = [stage.process(f, (i + 1) * 50_000_000) for i, f in enumerate(_sequence())]
    flags = [r.exposure.flag for r in recs]
    assert flags == [i == 6 for i in range(12)]
    assert recs[6].exposure.ev == pytest.approx(1.0, abs=0.1)
    assert recs[0].parallax.new_reference and recs[0].exposure.method == ""
    assert all(r.exposure.method == "klt" for r in recs[1:])
    assert not any(r.blur.flag for r in recs)
    assert all(r.blur.smear_px_pred is None and r.excitation is None for r in recs)
    cols, rows = health_rows(recs)
    assert cols == list(HEALTH_COLUMNS)
    assert rows[3]["smear_px_pred"] == "" and rows[6]["exposure_flag"] == "1"
    advice = make_advice(recs)
    assert any("exposure step +1.0" in a for a in advice)


def test_stage_flags_blurred_frame() -> None:
    frames = _sequence(12, step_at=100)
    frames[8] = cv2.blur(frames[8], (9, 1))
    stage = FrameDiagnostics()
    recs = [stage.process(f, (i + 1) * 50_000_000) for i, f in enumerate(frames)]
    assert [r.blur.flag for r in recs] == [i == 8 for i in range(12)]
    assert any(a.startswith("frames 8-8: motion blur") for a in make_advice(recs))


def test_stage_bad_input() -> None:
    stage = FrameDiagnostics()
    with pytest.raises(ShapeError):
        stage.process(np.zeros((240, 320), np.float32), 1)
    with pytest.raises(ShapeError):
        stage.process(np.zeros((4, 4), np.uint8), 1)
    stage.process(np.zeros((64, 64), np.uint8), 10)  # an empty (black) frame is data, not an error
    with pytest.raises(ShapeError):
        stage.process(np.zeros((64, 64), np.uint8), 5)  # time going backwards


def test_cli_diagnose_on_simulated_sequence(tmp_path: Path) -> None:
    from amrvio.cli.main import main

    seq = tmp_path / "seq"
    simulate(SimConfig(
        scene="corridor", motion="forward-stop-turn", seconds=3.0, fps=10, width=320, height=240,
        ev_steps="2.0:+1", blur_bursts="1.0:0.6:6.0", exposure_ms=10.0), seq)
    out = tmp_path / "out"
    assert main(["diagnose", str(seq), "--out", str(out), "--estimate-photometric", "15"]) == 0
    rows = list(csv.DictReader(open(out / "health.csv", encoding="utf-8")))
    assert len(rows) == 30
    assert set(HEALTH_COLUMNS) <= set(rows[0]) and "accel_std_m_s2" in rows[0]
    smear = np.array([float(r["smear_px_pred"]) for r in rows])
    assert smear[11:14].min() > 5.0 and smear[:9].max() < 1.0  # the yaw burst at 1.0-1.6 s
    assert [r["exposure_flag"] for r in rows].count("1") == 1 and rows[20]["exposure_flag"] == "1"
    advice = (out / "advice.txt").read_text(encoding="utf-8")
    assert "predicted smear" in advice and "cap exposure at" in advice
    assert "exposure step +0.9" in advice
    assert (out / "health.png").stat().st_size > 10_000
    report = (out / "photometric_estimate" / "report.txt").read_text(encoding="utf-8")
    assert "exposures known" in report and "vs the dataset's pcalib.txt" in report
    assert (out / "photometric_estimate" / "pcalib.txt").is_file()


def test_cli_diagnose_missing_dataset_is_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from amrvio.cli.main import main

    rc = main(["diagnose", str(tmp_path / "nope"), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert rc == 1 and err.count("\n") == 1 and "diagnose" in err


def test_stage_is_deterministic() -> None:
    frames = _sequence(8)

    def rows() -> list[dict[str, str]]:
        stage = FrameDiagnostics(camera=PinholeCamera(320, 240, 300.0, 300.0, 159.5, 119.5))
        return [stage.process(f, (i + 1) * 50_000_000).as_row() for i, f in enumerate(frames)]

    assert rows() == rows()


def test_cli_diagnose_bad_option_is_one_line_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    from amrvio.cli.main import main

    rc = main(["diagnose", str(tmp_path), "--out", str(tmp_path / "o"), "--ev-step", "0"])
    err = capsys.readouterr().err
    assert rc == 1 and "--ev-step" in err and err.count("\n") == 1
