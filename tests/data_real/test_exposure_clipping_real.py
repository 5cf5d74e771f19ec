"""Exposure steps under clipping on real KITTI 00 frames, through the diagnostics stage.

1. The case of issue 13: frames 0-159 with frames 40-59 replaced by clip(round(1.5 I - 15)),
   diagnosed by ``pipeline.run.diagnose`` (what ``amrvio diagnose`` runs): the step up at 40 and
   the step down at 60 are flagged, and nothing else is. The true gain of a modified pair is
   1.5 (or 1/1.5) times that of the unmodified pair, which is not exactly 1: frames 59 -> 60
   brighten by 2-4 % (mean intensity +3.7 %). It is measured on the unmodified frames with 400
   corners, and ``a`` must be within 3 % of the product.
2. A sweep of steps of +-0.3 to +-1.5 EV with 0-40 % of the pixels clipped at both ends
   (the darker frame's darkest ``f/2`` black, the brighter frame's brightest ``f/2`` saturated):
   on a real frame and its warped copy (the truth is exact), and on consecutive real frames
   (whose own brightness change is measured on the unmodified pair and added to the truth).
"""

from __future__ import annotations

import itertools
import os
import shutil
from pathlib import Path

import cv2
import numpy as np
import pytest

from amrvio.diagnostics.frame import FrameDiagnostics
from tests.skip_policy import skip_shared_missing

pytestmark = pytest.mark.real_data

EVS = (0.3, 0.5, 0.8, 1.0, 1.5)
CLIPPED = (0.0, 0.1, 0.2, 0.3, 0.4)
A_TOL = 0.03  # relative, on the gain


def _kitti(shared: Path) -> Path:
    seq = shared / "kitti00_0000-0199"
    if not (seq / "image_0" / "000159.png").is_file():
        skip_shared_missing(seq / "image_0")
    return seq


def _read(seq: Path, i: int) -> np.ndarray:
    img = cv2.imread(str(seq / "image_0" / f"{i:06d}.png"), cv2.IMREAD_GRAYSCALE)
    if img is None:
        raise FileNotFoundError(seq / "image_0" / f"{i:06d}.png")
    return np.asarray(img)


def _link_or_copy(src: Path, dst: Path) -> None:
    try:
        os.symlink(src, dst)
    except OSError:
        shutil.copyfile(src, dst)


def test_kitti_clipped_exposure_steps_through_diagnose(shared_data: Path, tmp_path: Path) -> None:
    from amrvio.io.dataset import open_dataset
    from amrvio.pipeline.run import diagnose

    seq = _kitti(shared_data)
    n = 160
    root = tmp_path / "kitti_clipped"
    (root / "image_0").mkdir(parents=True)
    for name in ("calib.txt", "times.txt", "poses.txt"):
        lines = (seq / name).read_text().splitlines(keepends=True)
        (root / name).write_text("".join(lines if name == "calib.txt" else lines[:n]))
    sat = []
    for i in range(n):
        dst = root / "image_0" / f"{i:06d}.png"
        if 40 <= i < 60:
            img = _read(seq, i).astype(np.float64)
            out = np.clip(np.round(1.5 * img - 15.0), 0, 255).astype(np.uint8)
            sat.append(float(np.mean(out == 255)))
            cv2.imwrite(str(dst), out)
        else:
            _link_or_copy((seq / "image_0" / f"{i:06d}.png").resolve(), dst)
    assert np.mean(sat) > 0.15  # about a fifth of the pixels saturate, as in the issue
    recs, _ = diagnose(open_dataset(f"kitti:{root}"))
    health = [r.diagnostics for r in recs]
    assert len(health) == n and all(h is not None for h in health)
    flagged = [i for i, h in enumerate(health) if h is not None and h.exposure.flag]
    assert flagged == [40, 60]
    up, down = health[40], health[60]
    assert up is not None and down is not None
    r40, r60 = _pair_gain(seq, 40), _pair_gain(seq, 60)
    assert abs(r40 - 1.0) < 0.05 and abs(r60 - 1.0) < 0.05
    assert up.exposure.gain_a == pytest.approx(1.5 * r40, rel=A_TOL)
    assert down.exposure.gain_a == pytest.approx(r60 / 1.5, rel=A_TOL)
    assert up.exposure.ev == pytest.approx(np.log2(1.5 * r40), abs=np.log2(1 + A_TOL))
    assert down.exposure.ev == pytest.approx(np.log2(r60 / 1.5), abs=np.log2(1 + A_TOL))


def _pair_gain(seq: Path, k: int) -> float:
    """Gain of the unmodified pair k-1 -> k, from 400 corners over the whole frame."""
    from dataclasses import replace

    from amrvio.diagnostics.exposure import estimate_exposure_change
    from amrvio.diagnostics.tracks import TrackingConfig
    from amrvio.tracking.detect import DetectorConfig

    t = TrackingConfig()
    wide = TrackingConfig(detector=DetectorConfig(max_corners=400, quality_level=0.01,
                                                  min_distance_px=8, block_size=5),
                          lk=replace(t.lk, max_width_px=1000))
    change = estimate_exposure_change(_read(seq, k - 1), _read(seq, k), tracking=wide)
    assert change.valid and change.method == "klt"
    return change.a


def _expose(img: np.ndarray, scale: float, offset: float) -> np.ndarray:
    return np.clip(np.round(scale * img.astype(np.float64) + offset), 0, 255).astype(np.uint8)


def _stepped_pair(i0: np.ndarray, i1: np.ndarray, ev: float, f: float) -> tuple[
        np.ndarray, np.ndarray, float]:
    """(prev, cur, clipped fraction): an exposure step of ``ev`` from ``i0`` to ``i1`` with the
    brightest f/2 of the brighter frame saturated and the darkest f/2 of the darker one black
    (a black level ``o``: dark = s I + o, bright = g s I + o, so a = g and b = o (1 - g))."""
    g = 2.0 ** abs(ev)
    lo = float(np.quantile(i0, f / 2)) if f > 0 else float(i0.min())
    hi = float(np.quantile(i0, 1 - f / 2)) if f > 0 else float(i0.max())
    s = 255.0 / (g * hi - lo)
    o = -s * lo
    if ev > 0:
        prev, cur = _expose(i0, s, o), _expose(i1, s * g, o)
    else:
        prev, cur = _expose(i0, s * g, o), _expose(i1, s, o)
    clipped = float(np.mean((prev <= 5) | (prev >= 250) | (cur <= 5) | (cur >= 250)))
    return prev, cur, clipped


def _ev_between(prev: np.ndarray, cur: np.ndarray) -> tuple[float, bool]:
    stage = FrameDiagnostics()
    stage.process(prev, 1_000_000_000)
    e = stage.process(cur, 1_100_000_000).exposure
    return e.ev, e.flag


def _sweep(i0: np.ndarray, i1: np.ndarray) -> tuple[list[float], list[bool], float]:
    """Errors (estimated - true EV, the pair's own change added) and flags over the sweep, and
    the largest clipped fraction reached."""
    ev0, _ = _ev_between(i0, i1)
    errs, flags, most = [], [], 0.0
    for e, f in itertools.product(EVS, CLIPPED):
        for ev in (e, -e):
            prev, cur, clipped = _stepped_pair(i0, i1, ev, f)
            est, flag = _ev_between(prev, cur)
            errs.append(est - ev - ev0)
            flags.append(flag or abs(ev) < 0.5)
            most = max(most, clipped)
    return errs, flags, most


@pytest.mark.parametrize("k", [50, 150])
def test_exposure_sweep_on_a_warped_real_frame(shared_data: Path, k: int) -> None:
    i0 = _read(_kitti(shared_data), k)
    h, w = i0.shape
    M = cv2.getRotationMatrix2D((w / 2, h / 2), 0.5, 1.0)
    M[:, 2] += (3.3, -1.6)
    i1 = cv2.warpAffine(i0, M, (w, h), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT)
    errs, flags, most = _sweep(i0, i1)
    assert most > 0.4
    assert all(flags)  # every step of 0.5 EV or more
    assert np.max(np.abs(errs)) <= np.log2(1 + A_TOL)


def test_exposure_sweep_on_consecutive_real_frames(shared_data: Path) -> None:
    """Consecutive frames of a car at 10 Hz: perspective and occlusion change the patches, and
    the clipping changes which of them (darker or brighter) carry the fit, so the per-pair
    error is larger; its median stays small and no step of 0.5 EV or more is missed."""
    seq = _kitti(shared_data)
    errs: list[float] = []
    for k in (10, 100, 150):
        e, flags, _ = _sweep(_read(seq, k), _read(seq, k + 1))
        assert all(flags)
        errs += e
    abs_err = np.abs(errs)
    assert np.median(abs_err) <= 0.03
    assert np.percentile(abs_err, 90) <= 0.08
    assert np.max(abs_err) <= 0.25
