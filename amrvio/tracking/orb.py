"""ORB binary features (Rublee et al. 2011) on OpenCV: descriptors at given pixels, a well-spread
multi-scale detection, and Hamming distances.

Descriptors at given pixels (for example the tracked corners of a keyframe) use the same oriented
BRIEF as :func:`detect_orb`: the orientation is the intensity-centroid angle of the 31-pixel
circular patch, computed here exactly as OpenCV's ORB does for the keypoints it detects, so that a
corner described at a tracked pixel and the same corner detected by ORB in another image give
matching descriptors. All pixels are on level 0 of the pyramid.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

F64 = NDArray[np.float64]
I64 = NDArray[np.int64]
U8 = NDArray[np.uint8]

PATCH_SIZE = 31
"""Side of the ORB patch (pixels on the keypoint's level); OpenCV's default."""
EDGE_PX = 22
"""ORB drops keypoints closer than this to the image border (OpenCV's ``edgeThreshold``; its
default is 31). 22 = ceil(15 sqrt 2), the reach of the rotated pattern: from 22 pixels on, a
descriptor is the same as in a larger image (tested), below it the border reflection enters."""
SCALE_FACTOR = 1.2
"""Pyramid scale between levels (OpenCV's and ORB-SLAM's default)."""
DESCRIPTOR_BYTES = 32


def _circle_half_widths(half: int) -> I64:
    """Half width of each row ``v = 0..half`` of the circular patch of ORB's intensity centroid
    (``umax`` of OpenCV's orb.cpp, made symmetric the same way)."""
    vmax = int(np.floor(half * np.sqrt(2.0) / 2 + 1))
    vmin = int(np.ceil(half * np.sqrt(2.0) / 2))
    umax = [0] * (half + 2)
    for v in range(vmax + 1):
        umax[v] = int(round(np.sqrt(half * half - v * v)))
    v0 = 0
    for v in range(half, vmin - 1, -1):
        while umax[v0] == umax[v0 + 1]:
            v0 += 1
        umax[v] = v0
        v0 += 1
    return np.array(umax[: half + 1], dtype=np.int64)


_HALF = PATCH_SIZE // 2
_ROWS = np.arange(-_HALF, _HALF + 1, dtype=np.int64)  # v
_WIDTHS = _circle_half_widths(_HALF)[np.abs(_ROWS)]  # d(v)


def _check_image(img: U8) -> None:
    if img.ndim != 2 or img.dtype != np.uint8:
        raise ShapeError(f"ORB expects an (H, W) uint8 image, got {img.shape} {img.dtype}")


def centroid_angles_deg(img: U8, uv: F64) -> F64:
    """(N,) ORB orientation in degrees [0, 360) of the (N, 2) pixels ``uv`` (rounded, level 0):
    the angle of the intensity centroid ``atan2(m01, m10)`` over the circular patch of radius 15
    (Rosin 1999; Rublee et al. 2011, eq. 2-3). Each patch row is summed from row prefix sums of
    ``I`` and ``x I``, so a pixel costs 31 rows, not 749 pixels. Pixels closer than 16 to the
    border see a clipped patch (ORB rejects them anyway)."""
    _check_image(img)
    h, w = img.shape
    c = np.rint(uv).astype(np.int64)
    if len(c) == 0:
        return np.zeros(0)
    # prefix sums along rows: S0[y, x] = sum_{x' < x} I, S1[y, x] = sum_{x' < x} x' I;
    # int32 is exact while 255 * w^2 / 2 < 2^31 (w < 4100)
    it = np.dtype(np.int32) if w < 4000 else np.dtype(np.int64)
    ii: NDArray[np.signedinteger] = img.astype(it)
    xs: NDArray[np.signedinteger] = np.arange(w, dtype=it)
    s0 = np.zeros((h, w + 1), dtype=it)
    s1 = np.zeros((h, w + 1), dtype=it)
    np.cumsum(ii, axis=1, dtype=it, out=s0[:, 1:])
    np.cumsum(ii * xs[None, :], axis=1, dtype=it, out=s1[:, 1:])
    y = np.clip(c[:, 1:2] + _ROWS[None, :], 0, h - 1)
    lo = np.clip(c[:, 0:1] - _WIDTHS[None, :], 0, w)
    hi = np.clip(c[:, 0:1] + _WIDTHS[None, :] + 1, 0, w)
    r0 = s0[y, hi] - s0[y, lo]
    r1 = s1[y, hi] - s1[y, lo]
    m10 = (r1.astype(np.int64) - c[:, 0:1] * r0).sum(axis=1).astype(np.float64)
    m01 = (r0.astype(np.int64) * _ROWS[None, :]).sum(axis=1).astype(np.float64)
    ang: F64 = np.degrees(np.arctan2(m01, m10)) % 360.0
    return ang


def _orb(n_features: int, n_levels: int) -> cv2.ORB:
    return cv2.ORB.create(nfeatures=max(n_features, 1), scaleFactor=SCALE_FACTOR, nlevels=n_levels,
                          edgeThreshold=EDGE_PX, patchSize=PATCH_SIZE, fastThreshold=20)


def describe_at(img: U8, uv: F64) -> tuple[NDArray[np.intp], U8]:
    """ORB descriptors at the (N, 2) pixels ``uv`` of the (H, W) uint8 ``img``.

    Returns (indices into ``uv`` of the pixels described, sorted; (K, 32) uint8 descriptors).
    Pixels that ORB rejects (within :data:`EDGE_PX` of the border) are dropped.
    """
    _check_image(img)
    p = np.asarray(uv, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] != 2:
        raise ShapeError(f"uv must be (N, 2), got {p.shape}")
    h, w = img.shape
    finite = np.all(np.isfinite(p), axis=1)
    inside = finite & (p[:, 0] >= EDGE_PX) & (p[:, 0] < w - EDGE_PX) & (p[:, 1] >= EDGE_PX) & \
        (p[:, 1] < h - EDGE_PX)
    idx = np.flatnonzero(inside)
    if len(idx) == 0:
        return idx, np.zeros((0, DESCRIPTOR_BYTES), dtype=np.uint8)
    ang = centroid_angles_deg(img, p[idx])
    kps = [cv2.KeyPoint(float(x), float(y), float(PATCH_SIZE), float(a), 0.0, 0, int(i))
           for (x, y), a, i in zip(np.rint(p[idx]), ang, idx, strict=True)]
    kept, desc = _orb(len(kps), 1).compute(img, kps)
    if desc is None or not kept:
        return np.zeros(0, dtype=np.intp), np.zeros((0, DESCRIPTOR_BYTES), dtype=np.uint8)
    ids = np.array([k.class_id for k in kept], dtype=np.intp)
    order = np.argsort(ids, kind="stable")
    return ids[order], np.ascontiguousarray(desc[order])


@dataclass(frozen=True, slots=True)
class OrbFeatures:
    """Detected features: (N, 2) level-0 pixels ``uv``, (N, 32) uint8 ``descriptors`` and (N,)
    pyramid ``octave`` (the keypoint's scale is ``SCALE_FACTOR ** octave``)."""

    uv: F64
    descriptors: U8
    octave: I64

    def __len__(self) -> int:
        return len(self.uv)


def detect_orb(img: U8, n_features: int, n_levels: int = 8, cell_px: int = 64) -> OrbFeatures:
    """At most ``n_features`` ORB features of the (H, W) uint8 ``img``, spread over the image:
    ORB detects twice as many, then each ``cell_px`` square cell keeps its strongest features
    (an equal share of the budget), and the strongest of the rest fill what is left."""
    _check_image(img)
    if n_features <= 0:
        raise ShapeError(f"n_features must be positive, got {n_features}")
    orb = _orb(2 * n_features, n_levels)
    kps, desc = orb.detectAndCompute(img, None)
    if desc is None or not kps:
        return OrbFeatures(np.zeros((0, 2)), np.zeros((0, DESCRIPTOR_BYTES), dtype=np.uint8),
                           np.zeros(0, dtype=np.int64))
    uv = np.array([k.pt for k in kps], dtype=np.float64)
    resp = np.array([k.response for k in kps], dtype=np.float64)
    octave = np.array([k.octave for k in kps], dtype=np.int64)
    h, w = img.shape
    cols = max(1, int(np.ceil(w / cell_px)))
    rows = max(1, int(np.ceil(h / cell_px)))
    cell = np.minimum((uv[:, 1] // cell_px).astype(np.int64), rows - 1) * cols + \
        np.minimum((uv[:, 0] // cell_px).astype(np.int64), cols - 1)
    order = np.lexsort((np.arange(len(uv)), -resp, cell))  # by cell, strongest first, stable
    first = np.searchsorted(cell[order], cell[order])
    rank = np.empty(len(uv), dtype=np.int64)
    rank[order] = np.arange(len(uv)) - first
    share = max(1, n_features // (rows * cols))
    by_strength = np.lexsort((np.arange(len(uv)), -resp))
    # first every cell's share, then the strongest of the rest
    pick = np.sort(np.concatenate([np.flatnonzero(rank < share),
                                   by_strength[rank[by_strength] >= share]])[:n_features])
    return OrbFeatures(uv[pick], np.ascontiguousarray(desc[pick]), octave[pick])


def hamming(a: U8, b: U8) -> I64:
    """Row-wise Hamming distances between (N, 32) uint8 descriptors ``a`` and ``b``: (N,)."""
    if a.shape != b.shape or a.ndim != 2:
        raise ShapeError(f"hamming: descriptor arrays differ, {a.shape} vs {b.shape}")
    return np.bitwise_count(np.bitwise_xor(a, b)).sum(axis=1).astype(np.int64)


HAMMING_BLOCK = 1 << 17
"""Descriptor pairs per block of :func:`hamming_matrix` (one uint64 XOR each: 1 MiB)."""


def hamming_matrix(a: U8, b: U8) -> I64:
    """(N, M) Hamming distances between the (N, 32) and (M, 32) uint8 descriptors. Computed
    ``HAMMING_BLOCK`` pairs at a time, so that the XOR's temporary stays 1 MiB however large N."""
    if a.ndim != 2 or b.ndim != 2 or a.shape[1] != b.shape[1] or a.shape[1] % 8:
        raise ShapeError(f"hamming_matrix: descriptors {a.shape} and {b.shape}")
    a64 = np.ascontiguousarray(a).view(np.uint64)
    b64 = np.ascontiguousarray(b).view(np.uint64)
    out = np.zeros((len(a64), len(b64)), dtype=np.int64)
    rows = max(HAMMING_BLOCK // max(len(b64), 1), 1)
    for lo in range(0, len(a64), rows):
        block = out[lo:lo + rows]
        for j in range(a64.shape[1]):
            block += np.bitwise_count(a64[lo:lo + rows, j : j + 1] ^ b64[None, :, j])
    return out


__all__ = ["DESCRIPTOR_BYTES", "EDGE_PX", "PATCH_SIZE", "SCALE_FACTOR", "OrbFeatures",
           "centroid_angles_deg", "describe_at", "detect_orb", "hamming", "hamming_matrix"]
