"""A frame prepared for the exposure fit of :mod:`amrvio.diagnostics.exposure`: integral images of
the intensity and of the clipped pixels, from which the box mean and clip flag around any pixel
cost four look-ups, so that only the patches around tracked points are ever filtered."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import cv2
import numpy as np
from numpy.typing import NDArray

from amrvio.photometric.affine import SATURATED_DN, UNDEREXPOSED_DN, linearise

F64 = NDArray[np.float64]


@functools.lru_cache(maxsize=16)
def _grid_offsets(side: int, row: int) -> NDArray[np.intp]:
    """Flat offsets (side^2,) of a ``side`` x ``side`` pixel grid in an image of ``row``
    entries per row (row-major, the grid's own rows first)."""
    offs = np.arange(side, dtype=np.intp)
    out = (offs[:, None] * row + offs[None, :]).ravel()
    out.setflags(write=False)
    return out


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

    def patch_grid(self, corner: NDArray[np.intp], radius: int, side: int
                   ) -> tuple[F64, NDArray[np.bool_]]:
        """Box means (N, side^2) on ``side`` x ``side`` integer grids that start ``radius``
        pixels up and left of the (N, 2) integer pixels ``corner`` (row-major), and True where
        a sample's box touches a clipped raw pixel, or where any box of the grid reaches outside
        the image (the whole patch is then masked)."""
        h, w = self.shape
        k, row = self.box, w + 1
        u0 = corner[:, 0] - radius - k // 2  # the first box's top-left pixel
        v0 = corner[:, 1] - radius - k // 2
        inside = (u0 >= 0) & (v0 >= 0) & (u0 <= w - side + 1 - k) & (v0 <= h - side + 1 - k)
        i00 = (np.where(inside, v0 * row + u0, 0)[:, None]
               + _grid_offsets(side, row)[None, :])
        i01, i10, i11 = i00 + k, i00 + k * row, i00 + k * row + k
        f = self.integral.reshape(-1)
        # int32 integrals: every partial difference is a sum over part of the image (no overflow)
        t = f.take(np.stack((i11, i01, i10, i00)))
        mean = np.asarray(t[0] - t[1] - t[2] + t[3], np.float64) * (1.0 / (k * k))
        outside = np.broadcast_to(~inside[:, None], i00.shape)
        if self.clip_integral is None:  # nothing clips in this frame
            return mean, outside
        c = self.clip_integral.reshape(-1).take(np.stack((i11, i01, i10, i00)))
        return mean, (c[0] - c[1] - c[2] + c[3] > 0) | outside

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

__all__ = ["ExposureFrame", "clip_levels", "integral_frame"]
