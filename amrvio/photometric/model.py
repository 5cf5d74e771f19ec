"""Photometric camera model (seed section 6.2): ``I = G(t * V(x) * L)``, so ``L = G^-1(I) / (V(x) t)``.

- ``G``: the response, a monotone map from exposure energy (normalised so that 1 saturates) to
  intensity in [0, 1] (x 255 for DN). :class:`MonotoneResponse` is a monotone Bernstein polynomial
  (non-decreasing coefficients => non-decreasing polynomial), a small parametric family fitted by
  :mod:`amrvio.photometric.calibrate` (EMoR would need its basis data, which we do not ship).
- ``V``: radial vignetting ``V(r) = 1 + v1 r^2 + v2 r^4 + v3 r^6``, ``r`` = distance to the image
  centre divided by the half-diagonal (so r = 1 in the corners) (:class:`RadialVignette`).
- ``t``: exposure time.

:class:`PhotometricCalibration` holds the DSO/TUM-monoVO representation: a (256,) inverse
response ``G^-1`` (pcalib.txt) and an (H, W) vignette map with max 1 (vignette.png), and applies it.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import comb
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

F64 = NDArray[np.float64]


def bernstein_basis(x: NDArray[np.floating], degree: int) -> F64:
    """(N,) points in [0, 1] -> (N, degree + 1) Bernstein basis values."""
    t = np.clip(np.asarray(x, dtype=np.float64).ravel(), 0.0, 1.0)
    u = 1.0 - t
    n = degree
    tp = np.empty((t.size, n + 1))
    up = np.empty((t.size, n + 1))
    tp[:, 0] = 1.0
    up[:, 0] = 1.0
    for k in range(1, n + 1):  # powers by repeated products (cheaper than **)
        tp[:, k] = tp[:, k - 1] * t
        up[:, k] = up[:, k - 1] * u
    coef = np.array([comb(n, k) for k in range(n + 1)], dtype=np.float64)
    return np.asarray(coef[None, :] * tp * up[:, ::-1])


@dataclass(frozen=True, slots=True)
class MonotoneResponse:
    """Response ``G: [0, 1] -> [0, 1]``, ``G(x) = P(x^gamma)``, ``P(u) = sum_k c_k B_k(u)`` with
    ``0 = c_0 <= c_1 <= ... <= c_n = 1`` (monotone Bernstein polynomial), ``gamma > 0``: a gamma
    curve refined by a monotone polynomial. Inputs are clipped to [0, 1] (saturation)."""

    coeffs: tuple[float, ...]
    gamma: float = 1.0

    def __post_init__(self) -> None:
        c = np.asarray(self.coeffs, dtype=np.float64)
        if c.ndim != 1 or c.size < 2 or not np.all(np.isfinite(c)):
            raise ShapeError(f"response needs >= 2 finite coefficients, got {c.shape}")
        if np.any(np.diff(c) < -1e-12):
            raise ShapeError("response coefficients must be non-decreasing")
        if not np.isfinite(self.gamma) or self.gamma <= 0:
            raise ShapeError(f"response gamma must be > 0, got {self.gamma}")

    @staticmethod
    def from_increments(increments: NDArray[np.floating]) -> MonotoneResponse:
        """Coefficients from (n,) non-negative increments, normalised so that c_n = 1."""
        d = np.asarray(increments, dtype=np.float64)
        if d.ndim != 1 or np.any(d < 0) or float(d.sum()) <= 0:
            raise ShapeError("increments must be non-negative with a positive sum")
        c = np.concatenate([[0.0], np.cumsum(d) / d.sum()])
        return MonotoneResponse(tuple(float(v) for v in c))

    @staticmethod
    def linear(degree: int = 6) -> MonotoneResponse:
        return MonotoneResponse(tuple(float(v) for v in np.linspace(0.0, 1.0, degree + 1)))

    @property
    def degree(self) -> int:
        return len(self.coeffs) - 1

    def curve(self, x: NDArray[np.floating]) -> F64:
        """G(x) for energies ``x`` (any shape), output in [0, 1]."""
        xa = np.asarray(x, dtype=np.float64)
        b = bernstein_basis(np.clip(xa.ravel(), 0.0, 1.0) ** self.gamma, self.degree)
        return np.asarray(b @ np.asarray(self.coeffs)).reshape(xa.shape)

    def inverse_lut(self, samples: int = 4097) -> F64:
        """(256,) ``G^-1`` in DSO pcalib convention: energy in [0, 1] for each DN (255 * G)."""
        x = np.linspace(0.0, 1.0, samples)
        g = self.curve(x) * 255.0
        # make strictly increasing for interpolation (flat parts of G are not invertible)
        g = np.maximum.accumulate(g) + np.linspace(0.0, 1e-9, samples)
        return np.asarray(np.interp(np.arange(256.0), g, x))


@dataclass(frozen=True, slots=True)
class RadialVignette:
    """``V(r) = 1 + v1 r^2 + v2 r^4 + v3 r^6``, r = distance to the centre / half-diagonal."""

    v1: float = 0.0
    v2: float = 0.0
    v3: float = 0.0

    def at_radius(self, r: NDArray[np.floating]) -> F64:
        r2 = np.asarray(r, dtype=np.float64) ** 2
        return np.asarray(1.0 + r2 * (self.v1 + r2 * (self.v2 + r2 * self.v3)))

    @staticmethod
    def radius(uv: NDArray[np.floating], width: int, height: int) -> F64:
        """(N, 2) pixels -> (N,) normalised radius."""
        p = np.asarray(uv, dtype=np.float64)
        cx, cy = (width - 1) / 2.0, (height - 1) / 2.0
        half_diag = float(np.hypot(cx, cy))  # centre to the corner pixel centre
        return np.asarray(np.hypot(p[:, 0] - cx, p[:, 1] - cy) / half_diag)

    def map(self, height: int, width: int) -> F64:
        """(H, W) vignette map (not renormalised: V = 1 at the centre)."""
        if height <= 0 or width <= 0:
            raise ShapeError(f"vignette map size must be positive, got {height}x{width}")
        vv, uu = np.mgrid[0:height, 0:width]
        uv = np.stack([uu.ravel(), vv.ravel()], axis=1)
        return self.at_radius(self.radius(uv, width, height)).reshape(height, width)

    def check_physical(self) -> None:
        """Raise ShapeError unless 0 < V(r) <= V(0) = 1 on r in [0, 1] (light only falls off).

        Not enforced on construction: an estimate may leave this range and is still reported."""
        v = self.at_radius(np.linspace(0.0, 1.0, 201))
        if not np.all(np.isfinite(v)) or float(v.min()) <= 0.0:
            raise ShapeError("vignette must stay positive for r in [0, 1]")
        if float(v.max()) > 1.0 + 1e-12:
            raise ShapeError("vignette must not exceed V(0) = 1 (light falls off towards the corners)")


@dataclass(frozen=True, slots=True)
class PhotometricCalibration:
    """DSO-style photometric calibration: ``inverse_response`` (256,) G^-1 (DN -> energy),
    ``vignette`` (H, W) with max 1, or None for no vignetting."""

    inverse_response: F64
    vignette: F64 | None = None

    def __post_init__(self) -> None:
        g = np.asarray(self.inverse_response, dtype=np.float64)
        if g.shape != (256,) or not np.all(np.isfinite(g)) or np.any(np.diff(g) < 0):
            raise ShapeError("inverse_response must be a finite, non-decreasing (256,) array")
        object.__setattr__(self, "inverse_response", g)
        if self.vignette is not None:
            v = np.asarray(self.vignette, dtype=np.float64)
            if v.ndim != 2 or not np.all(np.isfinite(v)) or float(v.min()) <= 0:
                raise ShapeError("vignette must be a finite, positive (H, W) map")
            object.__setattr__(self, "vignette", v / float(v.max()))

    @staticmethod
    def from_models(
        response: MonotoneResponse, vignette: RadialVignette | None, height: int, width: int
    ) -> PhotometricCalibration:
        vmap = None if vignette is None else vignette.map(height, width)
        return PhotometricCalibration(response.inverse_lut(), vmap)

    @staticmethod
    def load(pcalib_path: str | Path, vignette_path: str | Path | None = None) -> PhotometricCalibration:
        """Read DSO ``pcalib.txt`` (and ``vignette.png``) through :mod:`amrvio.io.calib`."""
        from amrvio.io.calib import read_pcalib, read_vignette

        vig = None if vignette_path is None else read_vignette(vignette_path)
        return PhotometricCalibration(read_pcalib(pcalib_path), vig)

    def save(self, pcalib_path: str | Path, vignette_path: str | Path | None = None) -> None:
        """Write DSO ``pcalib.txt`` (and ``vignette.png``, 16-bit) through :mod:`amrvio.io.calib`."""
        from amrvio.io.calib import write_pcalib, write_vignette

        g = self.inverse_response
        # pcalib must be strictly increasing: lift flat runs by a negligible ramp.
        write_pcalib(pcalib_path, g + np.linspace(0.0, 1e-9 * max(float(g[-1]), 1.0), 256))
        if vignette_path is not None and self.vignette is not None:
            write_vignette(vignette_path, self.vignette)

    def correct(self, image: NDArray[np.generic], exposure_s: float | None = None) -> NDArray[np.float32]:
        """Irradiance ``G^-1(I) / (V(x) t)`` of an (H, W) 8-bit image as float32 (seed 6.2).

        Without ``exposure_s`` the result is the energy ``G^-1(I) / V(x)`` (t = 1)."""
        img = np.asarray(image)
        if img.ndim != 2:
            raise ShapeError(f"image must be (H, W), got {img.shape}")
        if exposure_s is not None and (not np.isfinite(exposure_s) or exposure_s <= 0):
            raise ShapeError(f"exposure_s must be > 0, got {exposure_s}")
        lut = self.inverse_response.astype(np.float32)
        energy: NDArray[np.float32] = lut[np.clip(img, 0, 255).astype(np.intp)]
        if self.vignette is not None:
            if self.vignette.shape != img.shape:
                raise ShapeError(f"vignette {self.vignette.shape} does not match image {img.shape}")
            energy = np.divide(energy, self.vignette.astype(np.float32))
        if exposure_s is not None:
            energy = np.divide(energy, np.float32(exposure_s))
        return np.asarray(energy, dtype=np.float32)


@dataclass(frozen=True, slots=True)
class ResponseComparison:
    """RMS difference of two inverse responses over DN ``low..high`` (fractions of full scale).

    ``rms_at_250``: both normalised to 1 at DN 250. ``rms_scale_aligned``: the reference
    normalised to 1 at DN 250, the estimate scaled by the least-squares factor. An inverse
    response estimated from images is only defined up to one irradiance scale (t_i V L_j is
    observed as a product, and the radiances L_j are free), so the aligned figure measures the
    shape; the DN-250 figure also carries the error of extrapolating to a DN that is rarely
    observed unsaturated.
    """

    rms_at_250: float
    rms_scale_aligned: float


def compare_inverse_responses(
    inverse_response: NDArray[np.floating], reference: NDArray[np.floating], low: int = 6,
    high: int = 249,
) -> ResponseComparison:
    """Compare two (256,) inverse responses (DSO pcalib convention); offsets at DN 0 removed."""
    a = np.asarray(inverse_response, dtype=np.float64)
    b = np.asarray(reference, dtype=np.float64)
    if a.shape != (256,) or b.shape != (256,):
        raise ShapeError(f"inverse responses must be (256,), got {a.shape} and {b.shape}")
    if not (0 <= low < high < 256):
        raise ShapeError(f"need 0 <= low < high < 256, got {low}, {high}")
    a, b = a - a[0], b - b[0]
    if not (a[250] > 0 and b[250] > 0):
        raise ShapeError("inverse responses must increase to a positive value at DN 250")
    s = slice(low, high + 1)
    an, bn = a[s] / a[250], b[s] / b[250]
    k = float(an @ bn) / float(an @ an)  # least-squares scale of the estimate onto the reference
    return ResponseComparison(float(np.sqrt(np.mean((an - bn) ** 2))),
                              float(np.sqrt(np.mean((k * an - bn) ** 2))))
