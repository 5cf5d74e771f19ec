"""KLT feature tracking: bucketed corner detection, pyramidal Lucas-Kanade with a
forward-backward check after affine photometric compensation, and essential-matrix
outlier rejection (USAC)."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError
from amrvio.frontend.photometric_comp import (
    AffineBrightness,
    fit_affine_quantiles,
)
from amrvio.geometry.projection import project

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class KltConfig:
    """Front-end settings (pixels)."""

    max_features: int = 1500
    grid_rows: int = 6
    grid_cols: int = 16
    min_distance_px: int = 10
    quality_level: float = 0.001
    win_size: int = 21
    pyr_levels: int = 3
    wide_pyr_levels: int = 5
    fb_thresh_px: float = 1.0
    border_px: int = 8
    photometric: bool = True
    ransac_thresh_px: float = 1.0
    max_iterations: int = 30  # 15 measured: KITTI alike, sim corridor 0.13 -> 0.75 % ATE
    seed: int = 0


@dataclass(frozen=True, slots=True)
class KltResult:
    """Tracked positions (N, 2) for the N input points; ``ok``: (N,) bool; the brightness
    change used; ``n_fb_rejected`` and ``n_epi_rejected`` count the rejections."""

    pts: F64
    ok: NDArray[np.bool_]
    brightness: AffineBrightness
    n_fb_rejected: int
    n_epi_rejected: int


def detect_bucketed(
    img: U8, existing_px: F64, n_wanted: int, config: KltConfig
) -> F64:
    """Shi-Tomasi corners spread over a grid: at most ``n_wanted`` new (M, 2) pixel corners,
    kept away from ``existing_px`` (N, 2) and balanced per cell (strongest first)."""
    h, w = img.shape
    if n_wanted <= 0:
        return np.zeros((0, 2))
    mask = np.zeros((h, w), dtype=np.uint8)
    b = config.border_px
    mask[b : h - b, b : w - b] = 255
    r = config.min_distance_px
    for x, y in np.round(existing_px).astype(int):
        cv2.circle(mask, (int(x), int(y)), r, 0, -1)
    cand = cv2.goodFeaturesToTrack(
        img, maxCorners=4 * n_wanted + 200, qualityLevel=config.quality_level,
        minDistance=r, mask=mask, blockSize=5,
    )
    if cand is None:
        return np.zeros((0, 2))
    c = cand.reshape(-1, 2).astype(np.float64)
    gr, gc = config.grid_rows, config.grid_cols
    cell = (np.minimum((c[:, 1] * gr / h).astype(int), gr - 1) * gc
            + np.minimum((c[:, 0] * gc / w).astype(int), gc - 1))
    # occupancy of existing features per cell, so that empty cells are filled first
    occ = np.zeros(gr * gc, dtype=int)
    if len(existing_px):
        e = existing_px
        ec = (np.clip((e[:, 1] * gr / h).astype(int), 0, gr - 1) * gc
              + np.clip((e[:, 0] * gc / w).astype(int), 0, gc - 1))
        np.add.at(occ, ec, 1)
    cap = int(np.ceil((config.max_features) / (gr * gc))) + 1
    # candidates arrive strongest first: rank within cell, keep while the cell is below cap
    order = np.argsort(cell, kind="stable")
    cs = cell[order]
    first = np.searchsorted(cs, cs)
    rank_in_cell = np.empty_like(order)
    rank_in_cell[order] = np.arange(len(order)) - first
    keep = rank_in_cell + occ[cell] < cap
    sel = np.flatnonzero(keep)
    # then take globally by (rank within cell, strength) to respect n_wanted evenly
    sel = sel[np.lexsort((sel, rank_in_cell[sel]))][:n_wanted]
    return c[np.sort(sel)]


def predict_tracks(K: F64, T_cam_world_pred: F64, R_cur_prev: F64, pts: F64,
                   points_world: F64, has_point: NDArray[np.bool_],
                   shape_hw: tuple[int, int]) -> F64:
    """Motion prior for KLT: (N, 2) predicted positions of (N, 2) ``pts``. Tracks with a map
    point (``has_point``, (N, 3) ``points_world``) are projected with the predicted pose; the
    others follow the rotation-only homography K R K^-1 (H&Z 8.4.2). Clipped to the image."""
    n = len(pts)
    if pts.shape != (n, 2) or points_world.shape != (n, 3) or has_point.shape != (n,):
        raise ShapeError("predict_tracks: pts (N, 2), points_world (N, 3), has_point (N,)")
    pred = pts.copy()
    if has_point.any():
        uv, z = project(K, T_cam_world_pred, points_world[has_point])
        ok = z > 0
        sub = pred[has_point]
        sub[ok] = uv[ok]
        pred[has_point] = sub
    rest = ~has_point
    if rest.any():
        Hm = K @ R_cur_prev @ np.linalg.inv(K)
        ph = np.column_stack([pts[rest], np.ones(int(rest.sum()))]) @ Hm.T
        pred[rest] = ph[:, :2] / ph[:, 2:3]
    h, w = shape_hw
    pred[:, 0] = np.clip(pred[:, 0], 0, w - 1)
    pred[:, 1] = np.clip(pred[:, 1], 0, h - 1)
    return pred


class KltTracker:
    """Tracks points from one image to the next. Stateless between calls apart from config."""

    def __init__(self, config: KltConfig | None = None) -> None:
        self.config = config or KltConfig()

    def track(
        self,
        img_prev: U8,
        img_cur: U8,
        pts_prev: F64,
        *,
        pts_pred: F64 | None = None,
        wide: bool = False,
        K: F64 | None = None,
        epipolar_check: bool = True,
    ) -> KltResult:
        """Track (N, 2) ``pts_prev`` into ``img_cur``; ``pts_pred`` is an (N, 2) initial guess
        (from a motion prior). ``wide`` uses a deeper pyramid (after blur or a gap)."""
        cfg = self.config
        n = len(pts_prev)
        if n == 0:
            return KltResult(np.zeros((0, 2)), np.zeros(0, dtype=bool), AffineBrightness(), 0, 0)
        bright = fit_affine_quantiles(img_prev, img_cur) if cfg.photometric else AffineBrightness()
        ref = img_prev if bright.is_identity() else bright.apply(img_prev)
        levels = cfg.wide_pyr_levels if wide else cfg.pyr_levels
        win = (cfg.win_size, cfg.win_size)
        crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, cfg.max_iterations, 0.01)
        p0 = pts_prev.astype(np.float32).reshape(-1, 1, 2)
        flags = 0
        if pts_pred is not None:
            p1 = pts_pred.astype(np.float32).reshape(-1, 1, 2).copy()
            flags = cv2.OPTFLOW_USE_INITIAL_FLOW
        else:
            p1 = p0.copy()
        p1, st, _ = cv2.calcOpticalFlowPyrLK(ref, img_cur, p0, p1, winSize=win,
                                             maxLevel=levels, criteria=crit, flags=flags)
        pb = p0.copy()
        pb, stb, _ = cv2.calcOpticalFlowPyrLK(img_cur, ref, p1, pb, winSize=win,
                                              maxLevel=levels, criteria=crit,
                                              flags=cv2.OPTFLOW_USE_INITIAL_FLOW)
        p1f = p1.reshape(-1, 2).astype(np.float64)
        fb = np.linalg.norm(pb.reshape(-1, 2) - pts_prev, axis=1)
        h, w = img_cur.shape
        b = cfg.border_px * 0.5
        inside = ((p1f[:, 0] >= b) & (p1f[:, 0] < w - b) & (p1f[:, 1] >= b)
                  & (p1f[:, 1] < h - b))
        ok = (st.ravel() == 1) & (stb.ravel() == 1) & inside & np.isfinite(p1f).all(axis=1)
        ok_klt = ok.copy()
        ok &= fb < cfg.fb_thresh_px
        n_fb = int((ok_klt & ~ok).sum())
        n_epi = 0
        if epipolar_check and int(ok.sum()) >= 15:
            idx = np.flatnonzero(ok)
            flow = np.linalg.norm(p1f[idx] - pts_prev[idx], axis=1)
            if float(np.median(flow)) > 1.0:
                cv2.setRNGSeed(cfg.seed)
                if K is not None:  # essential matrix, USAC (MAGSAC++)
                    F, m = cv2.findEssentialMat(pts_prev[idx], p1f[idx], K, cv2.USAC_MAGSAC,
                                                0.999, cfg.ransac_thresh_px)
                else:
                    F, m = cv2.findFundamentalMat(pts_prev[idx], p1f[idx], cv2.USAC_MAGSAC,
                                                  cfg.ransac_thresh_px, 0.999, 200)
                if F is not None and m is not None and F.shape == (3, 3):
                    bad = idx[m.ravel() == 0]
                    ok[bad] = False
                    n_epi = len(bad)
        return KltResult(p1f, ok, bright, n_fb, n_epi)


__all__ = ["KltConfig", "KltResult", "KltTracker", "detect_bucketed", "predict_tracks"]
