"""Corner detection for tracking: Shi-Tomasi corners (Shi and Tomasi 1994) with an optional mask,
a margin at the image border, exclusion of existing points, and optional bucketing over a grid so
that the corners spread over the image."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

F64 = NDArray[np.float64]
U8 = NDArray[np.uint8]


@dataclass(frozen=True, slots=True)
class DetectorConfig:
    """Detector settings (pixels).

    ``max_corners``: the feature budget (the default for ``n_wanted``, and with bucketing the
    per-cell cap ``ceil(max_corners / cells) + 1``). ``quality_level``: of the strongest corner's
    minimum eigenvalue. ``min_distance_px``: between corners, and from existing points.
    ``border_px``: no corner closer to the image edge. ``grid_rows`` x ``grid_cols``: buckets;
    0 turns bucketing off (then the strongest corners are kept).
    """

    max_corners: int = 1500
    quality_level: float = 0.001
    min_distance_px: int = 10
    block_size: int = 5
    border_px: int = 0
    grid_rows: int = 0
    grid_cols: int = 0

    @property
    def bucketed(self) -> bool:
        return self.grid_rows > 0 and self.grid_cols > 0


def detection_mask(
    shape_hw: tuple[int, int],
    config: DetectorConfig,
    existing_px: F64 | None = None,
    mask: U8 | None = None,
) -> U8 | None:
    """uint8 mask (255 = a corner may go there): ``mask`` (or everything), less the border margin
    and discs of radius ``min_distance_px`` around the (N, 2) ``existing_px``. None when that
    allows every pixel."""
    h, w = shape_hw
    has_existing = existing_px is not None and len(existing_px) > 0
    if mask is None and config.border_px <= 0 and not has_existing:
        return None
    if mask is None:
        out = np.full((h, w), 255, dtype=np.uint8)
    else:
        if mask.shape != (h, w):
            raise ShapeError(f"mask must be ({h}, {w}), got {mask.shape}")
        out = np.where(np.asarray(mask) > 0, np.uint8(255), np.uint8(0)).astype(np.uint8)
    b = config.border_px
    if b > 0:
        out[:b, :] = 0
        out[h - b :, :] = 0
        out[:, :b] = 0
        out[:, w - b :] = 0
    if has_existing and existing_px is not None:
        r = config.min_distance_px
        for x, y in np.round(existing_px).astype(int):
            cv2.circle(out, (int(x), int(y)), r, 0, -1)
    return out


def detect_corners(
    img: U8,
    config: DetectorConfig,
    *,
    n_wanted: int | None = None,
    existing_px: F64 | None = None,
    mask: U8 | None = None,
) -> F64:
    """At most ``n_wanted`` (default ``config.max_corners``) new (M, 2) pixel corners of the
    (H, W) uint8 ``img``, strongest first, away from the (N, 2) ``existing_px`` and inside the
    optional uint8 ``mask`` (non-zero = allowed). With bucketing, the cells with the fewest
    existing points are filled first and each cell holds at most the per-cell cap."""
    if img.ndim != 2 or img.dtype != np.uint8:
        raise ShapeError(f"detect_corners expects an (H, W) uint8 image, got {img.shape} {img.dtype}")
    existing = np.zeros((0, 2)) if existing_px is None else np.asarray(existing_px, np.float64)
    if existing.ndim != 2 or existing.shape[1] != 2:
        raise ShapeError(f"existing_px must be (N, 2), got {existing.shape}")
    n = config.max_corners if n_wanted is None else n_wanted
    if n <= 0:
        return np.zeros((0, 2))
    h, w = img.shape
    allowed = detection_mask((h, w), config, existing, mask)
    max_cand = 4 * n + 200 if config.bucketed else n
    cand = cv2.goodFeaturesToTrack(
        img, maxCorners=max_cand, qualityLevel=config.quality_level,
        minDistance=config.min_distance_px, mask=allowed, blockSize=config.block_size,
    )
    if cand is None:
        return np.zeros((0, 2))
    c = cand.reshape(-1, 2).astype(np.float64)
    if not config.bucketed:
        return c
    return c[_bucket(c, existing, n, (h, w), config)]


def _bucket(c: F64, existing: F64, n_wanted: int, shape_hw: tuple[int, int],
            config: DetectorConfig) -> NDArray[np.intp]:
    """Indices (sorted) of the candidates ``c`` (strongest first) kept by the grid rule."""
    h, w = shape_hw
    gr, gc = config.grid_rows, config.grid_cols
    cell = (np.minimum((c[:, 1] * gr / h).astype(int), gr - 1) * gc
            + np.minimum((c[:, 0] * gc / w).astype(int), gc - 1))
    # occupancy of existing features per cell, so that empty cells are filled first
    occ = np.zeros(gr * gc, dtype=int)
    if len(existing):
        e = existing
        ec = (np.clip((e[:, 1] * gr / h).astype(int), 0, gr - 1) * gc
              + np.clip((e[:, 0] * gc / w).astype(int), 0, gc - 1))
        np.add.at(occ, ec, 1)
    cap = int(np.ceil(config.max_corners / (gr * gc))) + 1
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
    return np.sort(sel)


__all__ = ["DetectorConfig", "detect_corners", "detection_mask"]
