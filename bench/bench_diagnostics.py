"""Diagnostics throughput at 752x480 on one core.

- ``blur+exposure``: per frame, the scene-normalised blur score (Var of the 3x3 Laplacian,
  evaluated on every 2nd row/column of the full-resolution Laplacian) and the exposure change to
  the previous frame (contrast-normalised image, pyramidal KLT (3 levels, 11 px window) of up to 100
  tracks, robust affine fit on 7x7 patches of the 9x9 box-filtered frames; features re-detected
  when fewer than 40 survive, amortised in the figure).
- ``FrameDiagnostics``: the whole stage (adds saturation counts, parallax with the essential
  matrix since no IMU is given, keyframing), for reference.

Frames: scikit-image's bundled "brick" photo tiled to 752x480, moving 2 px/frame with a gain
ramp, so tracking and the fit do real work. Run alone: ``.venv/bin/python -m bench.bench_diagnostics``.
"""

from __future__ import annotations

import sys
import time

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.diagnostics.blur import BlurScorer, var_laplacian
from amrvio.diagnostics.exposure import (
    ExposureConfig,
    TrackerConfig,
    detect_features,
    detection_mask,
    fit_exposure_frames,
    normalise_for_tracking,
    prepare_exposure_frame,
    track_features,
)
from amrvio.diagnostics.frame import FrameDiagnostics
from amrvio.types.camera import PinholeCamera

W, H = 752, 480


def _frames(n: int) -> list[NDArray[np.uint8]]:
    from skimage import data

    tex = np.asarray(data.brick(), dtype=np.uint8)
    big = np.tile(tex, (2, 3))
    out = []
    for i in range(n):
        x0, y0 = 2 * i % (big.shape[1] - W), i % (big.shape[0] - H)
        crop = big[y0 : y0 + H, x0 : x0 + W].astype(np.float32)
        gain = 1.0 + 0.2 * np.sin(i / 7.0)
        out.append(np.clip(crop * gain, 0, 255).astype(np.uint8))
    return out


def _blur_exposure_ms(frames: list[NDArray[np.uint8]]) -> float:
    tcfg, ecfg = TrackerConfig(), ExposureConfig()
    scorer = BlurScorer()
    t0 = time.perf_counter()
    prev = prev_norm = None
    pts = np.zeros((0, 2), np.float32)
    for img in frames:
        score = var_laplacian(img, step=2)
        _, std = cv2.meanStdDev(img)
        scorer.update(score / max(float(std[0, 0]) ** 2, 1e-6))
        norm = normalise_for_tracking(img)
        ef = prepare_exposure_frame(img, ecfg)
        if prev is not None and prev_norm is not None:
            p1, ok = track_features(prev_norm, norm, pts, tcfg)
            fit_exposure_frames(prev, ef, pts[ok], p1[ok], ecfg)
            pts = p1[ok]
        if pts.shape[0] < tcfg.min_tracks:
            pts = detect_features(norm, tcfg, mask=detection_mask(ef))
        prev, prev_norm = ef, norm
    return (time.perf_counter() - t0) * 1e3 / len(frames)


def _stage_ms(frames: list[NDArray[np.uint8]]) -> float:
    stage = FrameDiagnostics(camera=PinholeCamera(W, H, 460.0, 460.0, 375.5, 239.5))
    t0 = time.perf_counter()
    for i, img in enumerate(frames):
        stage.process(img, (i + 1) * 50_000_000)
    return (time.perf_counter() - t0) * 1e3 / len(frames)


def run(quick: bool) -> list[dict[str, object]]:
    cv2.setNumThreads(1)
    n, repeats = (60, 3) if quick else (200, 5)
    frames = _frames(n)
    be = float(np.median([_blur_exposure_ms(frames) for _ in range(repeats)]))
    blur = float(np.median([
        (lambda t0: (sum(var_laplacian(f, step=2) for f in frames), time.perf_counter() - t0)[1])(
            time.perf_counter()) * 1e3 / n for _ in range(repeats)
    ]))
    st = float(np.median([_stage_ms(frames) for _ in range(repeats)]))
    return [
        {"name": "diagnostics blur+exposure throughput 752x480", "value": 1e3 / be,
         "unit": "frames/s", "note": f"one core, {be:.2f} ms/frame, median of {repeats} x {n} frames"
                                       " (target >= 400)"},
        {"name": "diagnostics blur score 752x480", "value": blur, "unit": "ms/frame",
         "note": "var of Laplacian, every 2nd row/col of the full-res Laplacian"},
        {"name": "FrameDiagnostics full stage 752x480 (no IMU)", "value": 1e3 / st,
         "unit": "frames/s", "note": f"{st:.2f} ms/frame incl. parallax via essential matrix"},
    ]


if __name__ == "__main__":
    for row in run("--quick" in sys.argv):
        print(f"{row['name']}: {row['value']:.3g} {row['unit']} ({row['note']})")
