"""Surface textures for the simulator: real photographs, procedural noise, and their mip pyramids.

Every texture is a square, power-of-two, *periodic* albedo map in [0, 1] (linear, not sRGB), so that a
quad can tile it at a known ``texels_per_m`` and the renderer can wrap texture coordinates.

- Photographs come from the files that scikit-image ships in ``skimage/data`` (no download): they are
  converted to grey, from sRGB to linear albedo, and made periodic by mirror tiling.
- Procedural textures are seeded multi-scale noise with a 1/f^beta spectrum, synthesised in the
  Fourier domain, hence periodic by construction.

:class:`MipTexture` holds the pre-filtered pyramid (cv2.pyrDown with wrap-around borders): level L+1
texel ``j`` sits at level-L coordinate ``2 j``, so a level-0 texture coordinate ``s`` becomes
``s / 2**L`` on level L.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import ShapeError

F32 = NDArray[np.float32]

# Grey photographs shipped inside scikit-image (file names relative to skimage/data).
PHOTO_FILES: dict[str, str] = {
    "brick": "brick.png",
    "gravel": "gravel.png",
    "grass": "grass.png",
    "camera": "camera.png",
    "coffee": "coffee.png",
    "astronaut": "astronaut.png",
    "rocket": "rocket.jpg",
    "moon": "moon.png",
    "chelsea": "chelsea.png",
    "coins": "coins.png",
    "motorcycle": "motorcycle_left.png",
    "text": "text.png",
    "page": "page.png",
    "horse": "horse.png",
}


def skimage_data_dir() -> Path:
    """Folder of the sample images installed with scikit-image."""
    import skimage.data

    return Path(skimage.data.__file__).resolve().parent


def srgb_to_linear(v: NDArray[np.floating]) -> F32:
    """sRGB-encoded values in [0, 1] -> linear values (IEC 61966-2-1)."""
    x = np.asarray(v, dtype=np.float64)
    lin = np.where(x <= 0.04045, x / 12.92, ((x + 0.055) / 1.055) ** 2.4)
    return lin.astype(np.float32)


def _check_size(size: int) -> None:
    if size < 8 or size & (size - 1):
        raise ShapeError(f"texture size must be a power of two >= 8, got {size}")


@functools.lru_cache(maxsize=32)
def load_photo(name: str, size: int = 1024) -> F32:
    """A read-only periodic ``(size, size)`` linear-albedo texture made from a scikit-image sample photograph.

    The photo is read in grey, centre-cropped to a square, resized to ``size / 2`` and mirror-tiled
    to ``size`` (seamless wrap-around). Albedo is rescaled to [0.03, 0.9] after linearisation.
    """
    import cv2

    _check_size(size)
    if name not in PHOTO_FILES:
        raise ShapeError(f"unknown photo texture {name!r}; choose one of {sorted(PHOTO_FILES)}")
    path = skimage_data_dir() / PHOTO_FILES[name]
    if not path.is_file():
        raise FileNotFoundError(f"{path}: scikit-image sample image is missing")
    # Pillow, not cv2.imread: libpng in OpenCV prints an iCCP warning on page.png to stderr.
    from PIL import Image

    with Image.open(path) as im:
        img = np.asarray(im.convert("L"), dtype=np.uint8)
    h, w = img.shape
    side = min(h, w)
    y0, x0 = (h - side) // 2, (w - side) // 2
    crop = img[y0 : y0 + side, x0 : x0 + side]
    half = cv2.resize(crop, (size // 2, size // 2), interpolation=cv2.INTER_AREA)
    lin = srgb_to_linear(half.astype(np.float32) / 255.0)
    tile = np.block([[lin, lin[:, ::-1]], [lin[::-1, :], lin[::-1, ::-1]]])
    out = _rescale(tile, 0.03, 0.9)
    out.setflags(write=False)
    return out


def _rescale(a: NDArray[np.floating], lo: float, hi: float) -> F32:
    amin, amax = float(a.min()), float(a.max())
    if amax - amin < 1e-12:
        return np.full(a.shape, 0.5 * (lo + hi), dtype=np.float32)
    out = lo + (hi - lo) * (np.asarray(a, dtype=np.float64) - amin) / (amax - amin)
    return out.astype(np.float32)


@functools.lru_cache(maxsize=32)
def procedural_noise(size: int, seed: int, beta: float = 1.6, contrast: float = 1.0) -> F32:
    """Read-only periodic multi-scale noise ``(size, size)`` with power spectrum ~ 1/f^beta, albedo in [0.05, 0.85].

    Synthesised as seeded white noise shaped in the Fourier domain, so it tiles seamlessly.
    ``contrast`` < 1 pulls the values towards the mean.
    """
    _check_size(size)
    rng = np.random.default_rng(seed)
    white = rng.standard_normal((size, size))
    fy = np.fft.fftfreq(size)[:, None]
    fx = np.fft.rfftfreq(size)[None, :]
    f = np.sqrt(fx * fx + fy * fy)
    f[0, 0] = 1.0
    amp = f ** (-beta / 2.0)
    amp[0, 0] = 0.0
    field = np.fft.irfft2(np.fft.rfft2(white) * amp, s=(size, size))
    field = (field - field.mean()) / (field.std() + 1e-12)
    # Logistic squash keeps the tails inside the albedo range without hard clipping.
    squashed = 1.0 / (1.0 + np.exp(-1.2 * contrast * field))
    out = _rescale(squashed, 0.05, 0.85)
    out.setflags(write=False)
    return out


def checkerboard(size: int, square_texels: int, low: float = 0.05, high: float = 0.85) -> F32:
    """Periodic checkerboard ``(size, size)``: texel ``(i, j)`` is high where
    ``(i // square + j // square)`` is even. ``size`` must be a multiple of ``2 * square_texels``."""
    _check_size(size)
    if square_texels <= 0 or size % (2 * square_texels):
        raise ShapeError("checkerboard size must be a multiple of 2 * square_texels")
    idx = np.arange(size) // square_texels
    even = (idx[:, None] + idx[None, :]) % 2 == 0
    return np.where(even, high, low).astype(np.float32)


def constant(size: int, value: float) -> F32:
    """A uniform texture (used for emissive light panels and plain paint)."""
    _check_size(size)
    return np.full((size, size), value, dtype=np.float32)


@dataclass(frozen=True, slots=True, eq=False)
class MipTexture:
    """Pre-filtered pyramid of a periodic texture. ``levels[0]`` is the texture itself."""

    levels: tuple[F32, ...]
    is_constant: bool

    @staticmethod
    def build(texture: NDArray[np.floating], min_size: int = 8) -> MipTexture:
        """Build the pyramid with cv2.pyrDown on wrap-padded copies (keeps periodicity)."""
        import cv2

        tex = np.ascontiguousarray(texture, dtype=np.float32)
        if tex.ndim != 2 or tex.shape[0] != tex.shape[1]:
            raise ShapeError(f"texture must be square (S, S), got {tex.shape}")
        _check_size(tex.shape[0])
        if not np.all(np.isfinite(tex)) or float(tex.min()) < 0.0:
            raise ShapeError("texture must be finite and non-negative")
        levels = [tex]
        pad = 4
        while levels[-1].shape[0] > min_size:
            cur = levels[-1]
            padded = np.pad(cur, pad, mode="wrap")
            down = cv2.pyrDown(padded)
            n = cur.shape[0] // 2
            levels.append(np.ascontiguousarray(down[pad // 2 : pad // 2 + n, pad // 2 : pad // 2 + n]))
        for lv in levels:
            lv.setflags(write=False)
        is_const = bool(float(tex.max()) - float(tex.min()) < 1e-7)
        return MipTexture(tuple(levels), is_const)

    @property
    def size(self) -> int:
        return int(self.levels[0].shape[0])

    @property
    def mean(self) -> float:
        return float(self.levels[-1].mean())
