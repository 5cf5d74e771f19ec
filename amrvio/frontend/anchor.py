"""Re-tracking of each track from the keyframe image where it was first seen ("anchor"):
removes the drift that frame-to-frame KLT accumulates before a keyframe is made."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.tracking.brightness import affine_from_quantiles, image_quantiles

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class AnchorImage:
    """A keyframe image (H, W) uint8 and its intensity quantiles (for brightness changes)."""

    image: U8
    quantiles: F64

    @staticmethod
    def of(image: U8) -> AnchorImage:
        return AnchorImage(image, image_quantiles(image))


@dataclass(frozen=True, slots=True)
class AnchorConfig:
    """LK window (px), largest accepted disagreement with the frame-to-frame track (px),
    whether to compensate the brightness change first, and the pyramid levels of the LK (the
    frame-to-frame track starts it within ``max_shift_px`` of the answer, well inside one
    window at full resolution; each level costs a window per point)."""

    win_size: int = 21
    max_shift_px: float = 2.0
    photometric: bool = True
    pyr_levels: int = 1


def retrack_from_anchors(img: U8, pts: F64, first_kf: I64, first_uv: F64,
                         anchors: Mapping[int, AnchorImage],
                         config: AnchorConfig) -> tuple[F64, NDArray[np.bool_]]:
    """Re-track (N, 2) ``pts`` of ``img`` from ``first_uv`` (N, 2) in their keyframe image
    ``anchors[first_kf]`` (tracks with ``first_kf`` < 0 or without an image are left alone).

    Returns the refined (N, 2) positions and an (N,) mask of tracks to drop (the anchored
    position disagrees by more than ``max_shift_px``)."""
    n = len(pts)
    if pts.shape != (n, 2) or first_uv.shape != (n, 2) or first_kf.shape != (n,):
        raise ShapeError("retrack_from_anchors: pts, first_uv (N, 2) and first_kf (N,)")
    out = pts.copy()
    drop = np.zeros(n, dtype=bool)
    win = (config.win_size, config.win_size)
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 20, 0.01)
    q_cur = image_quantiles(img)
    h_img, w_img = img.shape
    margin = 4 * config.win_size + 8
    for fk in np.unique(first_kf[first_kf >= 0]):
        anchor = anchors.get(int(fk))
        if anchor is None:
            continue
        sel = np.flatnonzero(first_kf == fk)
        bright = (affine_from_quantiles(anchor.quantiles, q_cur) if config.photometric
                  else None)
        # crop both images to the tracks' bounding box (+ margin for the window at both
        # levels; an even offset keeps level 1 aligned): a whole-image pyramid per keyframe
        # group dominated this stage
        both = np.vstack([first_uv[sel], pts[sel]])
        lo = np.maximum(np.floor(both.min(axis=0)).astype(int) - margin, 0) // 2 * 2
        hi = np.minimum(np.ceil(both.max(axis=0)).astype(int) + margin, (w_img, h_img))
        ref_c = anchor.image[lo[1] : hi[1], lo[0] : hi[0]]
        if bright is not None and not bright.is_identity():
            ref_c = bright.apply(ref_c)
        img_c = img[lo[1] : hi[1], lo[0] : hi[0]]
        off = lo.astype(np.float64)
        p0 = (first_uv[sel] - off).astype(np.float32).reshape(-1, 1, 2)
        p1 = (pts[sel] - off).astype(np.float32).reshape(-1, 1, 2).copy()
        p1, st, _ = cv2.calcOpticalFlowPyrLK(ref_c, img_c, p0, p1, winSize=win,
                                             maxLevel=config.pyr_levels,
                                             criteria=crit, flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
        p1 = p1.reshape(-1, 2).astype(np.float64) + off
        shift = np.linalg.norm(p1 - pts[sel], axis=1)
        ok = (st.ravel() == 1) & (shift < config.max_shift_px)
        out[sel[ok]] = p1[ok]
        drop[sel[~ok & (st.ravel() == 1)]] = True
    return out, drop


__all__ = ["AnchorConfig", "AnchorImage", "retrack_from_anchors"]
