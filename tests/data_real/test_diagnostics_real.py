"""Diagnostics on real frames: affine fit with saturation, blur monotonic in kernel length,
and the parametric response against the third-party EuRoC photometric estimate."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from amrvio.diagnostics.blur import var_laplacian
from amrvio.photometric.affine import fit_affine_robust
from amrvio.photometric.calibrate import fit_radial_vignette, fit_response_to_inverse_lut

pytestmark = pytest.mark.real_data


def _frames(shared: Path) -> dict[str, np.ndarray]:
    kitti = shared / "kitti00_0000-0199" / "image_0" / "000050.png"
    phone_dir = shared / "phone_handheld_blur_0450-0549" / "mav0" / "cam0" / "data"
    phone = sorted(phone_dir.glob("*.png"))[10]
    out = {}
    for name, p in (("kitti", kitti), ("phone", phone)):
        img = cv2.imread(str(p), cv2.IMREAD_GRAYSCALE)
        assert img is not None, p
        out[name] = img
    # downsample the 1080p phone frame for speed (keeps real content)
    out["phone"] = cv2.resize(out["phone"], (960, 540), interpolation=cv2.INTER_AREA)
    return out


@pytest.mark.parametrize("name", ["kitti", "phone"])
def test_affine_fit_recovers_gain_offset_with_10pct_saturation(shared_data: Path, name: str) -> None:
    img = _frames(shared_data)[name]
    b = 10.0
    a = (250.0 - b) / float(np.percentile(img, 90))  # 10 % of pixels end at >= 250
    cur = np.clip(np.round(a * img.astype(np.float64) + b), 0, 255).astype(np.uint8)
    sat = float(np.mean(cur >= 250))
    assert 0.08 <= sat <= 0.15
    fit = fit_affine_robust(img, cur)
    assert fit.a == pytest.approx(a, rel=0.01)
    assert fit.b == pytest.approx(b, rel=0.01)


@pytest.mark.parametrize("name", ["kitti", "phone"])
def test_blur_score_falls_monotonically_with_kernel_length(shared_data: Path, name: str) -> None:
    img = _frames(shared_data)[name]
    scores = []
    for length in (1, 3, 5, 7, 11, 15, 21, 31):
        k = np.zeros((length, length), np.float32)
        k[length // 2, :] = 1.0 / length  # horizontal linear motion kernel
        k = cv2.warpAffine(k, cv2.getRotationMatrix2D(((length - 1) / 2, (length - 1) / 2), 30, 1.0),
                           (length, length))
        k /= k.sum()
        scores.append(var_laplacian(cv2.filter2D(img, -1, k, borderType=cv2.BORDER_REFLECT)))
    assert all(s0 > s1 for s0, s1 in zip(scores, scores[1:], strict=False)), scores


def test_parametric_response_fits_euroc_third_party_estimate(shared_data: Path) -> None:
    from amrvio.io.calib import read_pcalib

    lut = read_pcalib(
        shared_data / "euroc_V1_01_easy_first95" / "photometric_calib_estimated_dsso" / "pcalib.txt"
    )
    resp, rms = fit_response_to_inverse_lut(lut)
    # the family represents that (estimated, not true) curve to better than 1 % of full scale
    assert rms < 0.01
    inv = resp.inverse_lut()
    assert np.all(np.diff(inv) >= 0)


def test_radial_vignette_fits_euroc_third_party_estimate(shared_data: Path) -> None:
    from amrvio.io.calib import read_vignette

    vig = read_vignette(
        shared_data / "euroc_V1_01_easy_first95" / "photometric_calib_estimated_dsso" / "vignette.png"
    )
    model, rms = fit_radial_vignette(vig)
    assert vig.shape == (480, 752)
    assert rms < 0.03  # the estimate is close to radial
    assert model.at_radius(np.array([1.0]))[0] < 0.9  # and falls off towards the corners


@pytest.mark.parametrize("name", ["kitti", "phone"])
def test_exposure_change_on_tracked_patches_under_known_motion(shared_data: Path, name: str) -> None:
    from amrvio.diagnostics.exposure import estimate_exposure_change

    img = _frames(shared_data)[name]
    h, w = img.shape
    M = np.array([[1.0, 0.0, 5.3], [0.0, 1.0, -2.6]], dtype=np.float32)
    moved = cv2.warpAffine(img, M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    for ev in (-0.5, 0.4):
        cur = np.clip(np.round(2.0**ev * moved.astype(np.float64)), 0, 255).astype(np.uint8)
        ch = estimate_exposure_change(img, cur)
        assert ch.method == "klt" and ch.valid
        assert ch.ev == pytest.approx(ev, abs=0.08)
        assert ch.flag
