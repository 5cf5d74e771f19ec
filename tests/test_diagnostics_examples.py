"""The seed's three demos in examples/ run and their numbers match the truth they generate."""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def _load(name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    assert spec is not None and spec.loader is not None
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_scale_ambiguity_demo() -> None:
    r = _load("scale_ambiguity").run(seed=0)
    assert r["status_ok"] == 1.0
    assert r["t_unit_norm"] == pytest.approx(1.0, abs=1e-9)  # scale is a convention
    assert r["direction_error_deg"] < 5.0
    assert r["scale_hat"] == pytest.approx(r["true_norm_m"], rel=0.08)  # IMU fixes it
    assert r["median_depth_rel_error"] < 0.08


def test_affine_brightness_demo() -> None:
    r = _load("affine_brightness").run(seed=0)
    assert r["saturated_frac"] > 0.01
    assert r["a_robust"] == pytest.approx(r["a_true"], rel=0.005)
    assert r["b_robust"] == pytest.approx(r["b_true"], abs=0.2)
    assert abs(r["a_closed"] - r["a_true"]) > 0.05  # the plain closed form is biased by clipping
    assert r["ev_robust"] == pytest.approx(np.log2(r["a_true"]), abs=0.01)


def test_blur_score_demo() -> None:
    r = _load("blur_score").run()
    scores = r["scores"]
    assert all(a > b for a, b in zip(scores, scores[1:], strict=False))
    assert r["flags"][0] is False and all(r["flags"][2:])
    assert r["smear_center_px"] == pytest.approx(500 * np.tan(2 * 0.008), rel=1e-6)  # ~8 px
    assert r["smear_max_px"] > r["smear_center_px"]
    assert r["max_exposure_ms"] * 1e-3 * 2.0 * 500 < 2.0 + 1e-6


@pytest.mark.parametrize("name", ["scale_ambiguity", "affine_brightness", "blur_score"])
def test_examples_run_as_scripts(name: str) -> None:
    out = subprocess.run([sys.executable, str(EXAMPLES / f"{name}.py")], capture_output=True,
                         text=True, timeout=60, check=True)
    assert "---" in out.stdout
