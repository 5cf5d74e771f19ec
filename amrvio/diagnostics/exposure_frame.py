"""A frame prepared for the exposure fit of :mod:`amrvio.diagnostics.exposure`: integral images of
the intensity and of the clipped pixels, from which the box mean and clip flag around any pixel
cost four look-ups, so that only the patches around tracked points are ever filtered."""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np
from numba import njit
from numpy.typing import NDArray

from amrvio.photometric.affine import SATURATED_DN, UNDEREXPOSED_DN, linearise

F64 = NDArray[np.float64]


@dataclass(frozen=True, slots=True, eq=False)
class ExposureFrame:
    """A frame prepared for the patch fit, as two integral images (cv2.integral), from which a
    box mean and its clip flag at any pixel cost four look-ups each, so that only the patches
    around tracked points are ever filtered: ``integral`` (H+1, W+1) of the intensity
    (linearised first when an inverse response is given) and ``clip_integral`` (H+1, W+1) of the
    raw pixels that are saturated (>= 250) or under-exposed (<= 5), None when none is. ``box``: the side of the
    smoothing box; ``linear``: linearised through an inverse response; ``clip_levels``: the raw
    clip levels in the units of the intensity."""

    integral: NDArray[np.float64]
    clip_integral: NDArray[np.int32] | None
    box: int
    linear: bool = False
    clip_levels: tuple[float, float] = (UNDEREXPOSED_DN, SATURATED_DN)

    @property
    def shape(self) -> tuple[int, int]:
        return self.integral.shape[0] - 1, self.integral.shape[1] - 1

    @property
    def bad(self) -> NDArray[np.bool_]:
        """(H, W) True where the box touches a clipped raw pixel or reaches outside the image
        (for feature detection, which wants the whole frame; the fit looks up its samples)."""
        k, ci = self.box, self.clip_integral
        bad = np.ones(self.shape, dtype=bool)
        e = k // 2
        if ci is None:
            bad[e : e + self.shape[0] - k + 1, e : e + self.shape[1] - k + 1] = False
            return bad
        counts = ci[k:, k:] - ci[:-k, k:] - ci[k:, :-k] + ci[:-k, :-k]  # boxes from their corner
        bad[e : e + counts.shape[0], e : e + counts.shape[1]] = counts > 0
        return bad


@dataclass(frozen=True, slots=True, eq=False)
class PatchSamples:
    """Corresponding samples of N patch pairs, each (N, (2r-1)^2), row-major within a patch:
    ``x`` box means of ``prev`` on integer grids, ``y`` those of ``cur`` at the matching
    sub-pixel positions (bilinear), ``weight`` ``1 / (1 + (Laplacian of x / curvature_dn)^2)``
    (sub-pixel resampling error grows as (d^2 / 2) times the Laplacian, so flat samples are
    trusted), ``usable`` False where a box touched a clipped raw pixel of either frame or left
    either image (in ``cur``, any of the four boxes blended)."""

    x: F64
    y: F64
    weight: F64
    usable: NDArray[np.bool_]


_NO_CLIP = np.zeros((1, 1), np.int32)


def patch_samples(prev: ExposureFrame, cur: ExposureFrame, corner_prev: NDArray[np.intp],
                  base_cur: NDArray[np.intp], frac_cur: NDArray[np.float32], radius: int,
                  curvature_dn: float) -> PatchSamples:
    """The :class:`PatchSamples` of patches of radius ``radius`` around the (N, 2) integer pixels
    ``corner_prev`` of ``prev`` and around ``base_cur + frac_cur`` in ``cur`` (integer part and
    fraction in [0, 1), the same for every sample of a patch, so that the patch is one bilinear
    blend of a (2r)^2 grid of integer box means). The curvature needs the ring around the
    (2r-1)^2 samples, so the ``prev`` grid is (2r+1)^2."""
    if prev.box != cur.box:
        raise ValueError(f"frames prepared with different boxes: {prev.box}, {cur.box}")
    x, y, w, ok = _patch_samples(
        prev.integral, _NO_CLIP if prev.clip_integral is None else prev.clip_integral,
        prev.clip_integral is not None, cur.integral,
        _NO_CLIP if cur.clip_integral is None else cur.clip_integral, cur.clip_integral is not None,
        prev.box, np.ascontiguousarray(corner_prev, np.intp), np.ascontiguousarray(base_cur, np.intp),
        np.ascontiguousarray(frac_cur, np.float32), max(int(radius), 1), 1.0 / curvature_dn)
    return PatchSamples(x, y, w, ok)


@njit(cache=True, nogil=True)
def _box_grid(integral: NDArray[np.generic], clip: NDArray[np.int32], has_clip: bool, k: int,
              u: int, v: int, side: int, mean: F64, bad: NDArray[np.bool_]) -> None:
    """Box means (side, side) of ``k`` x ``k`` boxes whose grid starts ``u``, ``v`` at the first
    box's top-left pixel, and True where a box touches a clipped pixel or the grid leaves the
    image (then the grid is read at 0, 0 and every sample is bad)."""
    h, w = integral.shape[0] - 1, integral.shape[1] - 1
    outside = not (u >= 0 and v >= 0 and u <= w - side + 1 - k and v <= h - side + 1 - k)
    if outside:
        u = v = 0
    inv = 1.0 / (k * k)
    for i in range(side):
        r0, r1 = v + i, v + i + k
        for j in range(side):
            c0, c1 = u + j, u + j + k
            mean[i, j] = (integral[r1, c1] - integral[r0, c1] - integral[r1, c0]
                          + integral[r0, c0]) * inv
            bad[i, j] = outside or (has_clip and clip[r1, c1] - clip[r0, c1] - clip[r1, c0]
                                    + clip[r0, c0] > 0)


@njit(cache=True, nogil=True)
def _patch_samples(int0: NDArray[np.generic], clip0: NDArray[np.int32], has0: bool,
                   int1: NDArray[np.generic], clip1: NDArray[np.int32], has1: bool, k: int,
                   q0: NDArray[np.intp], base: NDArray[np.intp], frac: NDArray[np.float32], r: int,
                   inv_curv: float) -> tuple[F64, F64, F64, NDArray[np.bool_]]:
    n, s, half = q0.shape[0], 2 * r - 1, k // 2
    x, y, wt = np.empty((n, s * s)), np.empty((n, s * s)), np.empty((n, s * s))
    ok = np.empty((n, s * s), np.bool_)
    p, bad0 = np.empty((s + 2, s + 2)), np.empty((s + 2, s + 2), np.bool_)
    g, bad1 = np.empty((s + 1, s + 1)), np.empty((s + 1, s + 1), np.bool_)
    one = np.float32(1.0)
    for t in range(n):
        _box_grid(int0, clip0, has0, k, q0[t, 0] - r - half, q0[t, 1] - r - half, s + 2, p, bad0)
        _box_grid(int1, clip1, has1, k, base[t, 0] - (r - 1) - half, base[t, 1] - (r - 1) - half,
                  s + 1, g, bad1)
        fx, fy = frac[t, 0], frac[t, 1]
        gx, gy = one - fx, one - fy
        for i in range(s):
            for j in range(s):
                c = p[i + 1, j + 1]
                lap = (p[i + 2, j + 1] + p[i, j + 1] + p[i + 1, j + 2] + p[i + 1, j] - 4.0 * c) * inv_curv
                e = i * s + j
                x[t, e] = c
                wt[t, e] = 1.0 / (lap * lap + 1.0)
                y[t, e] = (gy * (gx * g[i, j] + fx * g[i, j + 1])
                           + fy * (gx * g[i + 1, j] + fx * g[i + 1, j + 1]))
                ok[t, e] = not (bad0[i + 1, j + 1] or bad1[i, j] or bad1[i, j + 1]
                                or bad1[i + 1, j] or bad1[i + 1, j + 1])
    return x, y, wt, ok


def integral_frame(
    image: NDArray[np.generic],
    box: int,
    inverse_response: NDArray[np.floating] | None = None,
) -> ExposureFrame:
    """The :class:`ExposureFrame` of an (H, W) grey frame with ``box`` x ``box`` box means
    (linearised through ``inverse_response`` when given). Two integral images cost less than
    filtering the whole frame (0.2 ms against 0.9 ms at 752x480)."""
    img = np.asarray(image)
    k = max(1, int(box))
    if inverse_response is not None:
        integral = cv2.integral(linearise(img, inverse_response).astype(np.float32),
                                sdepth=cv2.CV_64F)
    elif img.dtype != np.uint8:
        integral = cv2.integral(img.astype(np.float32), sdepth=cv2.CV_64F)
    else:  # exact in int32 up to 8.4 Mpixel
        integral = cv2.integral(img, sdepth=cv2.CV_32S if img.size < 2**23 else cv2.CV_64F)
    if img.dtype != np.uint8:
        img = np.clip(img, 0, 255).astype(np.uint8)
    inside = cv2.inRange(img, int(UNDEREXPOSED_DN) + 1, int(SATURATED_DN) - 1)
    clip_integral = None  # a frame without a clipped pixel needs no second integral
    if cv2.countNonZero(inside) < img.size:
        clipped = cv2.threshold(inside, 0, 1, cv2.THRESH_BINARY_INV)[1]
        clip_integral = cv2.integral(clipped, sdepth=cv2.CV_32S)
    return ExposureFrame(integral, clip_integral, k, inverse_response is not None,
                         clip_levels(inverse_response))


def clip_levels(inverse_response: NDArray[np.floating] | None) -> tuple[float, float]:
    """The raw clip levels (5, 250 DN), linearised when an inverse response is given."""
    raw = np.array([UNDEREXPOSED_DN, SATURATED_DN])
    lev = raw if inverse_response is None else linearise(raw, inverse_response)
    return float(lev[0]), float(lev[1])

__all__ = ["ExposureFrame", "PatchSamples", "clip_levels", "integral_frame", "patch_samples"]
