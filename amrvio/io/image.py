"""Image decoding that checks what it decodes: the one place an image file becomes pixels.

OpenCV's JPEG decoder does not report a truncated file: it returns the decoded part and fills the
rest with grey, so a half-written frame would be tracked as a real one. :func:`decode_image`
therefore checks the container before decoding (a JPEG needs its end-of-image marker ``FFD9``
after the start of scan, a PNG its ``IEND`` chunk), then checks the decoded array: 8 or 16 bit,
1, 3 or 4 channels, each side between :data:`MIN_SIDE_PX` and :data:`MAX_SIDE_PX`. Every failure
is a :class:`~amrvio.errors.DatasetFormatError` naming the file. The readers give each
:class:`~amrvio.types.sensors.Frame` an :class:`ImageFile` loader, so that ``Frame.load()`` goes
through here.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import DatasetFormatError

U8 = NDArray[np.uint8]

MIN_SIDE_PX = 8
"""Smallest image side accepted (px): a feature tracker needs more than a few pixels."""
MAX_SIDE_PX = 16384
"""Largest image side accepted (px)."""

_PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
_PNG_IEND = b"\x00\x00\x00\x00IEND\xaeB`\x82"


def _jpeg_problem(data: bytes) -> str | None:
    """Why a JPEG stream is incomplete, or None. Walks the marker segments to the first start of
    scan (SOS, ``FFDA``), so an EXIF thumbnail's own end marker does not count, then looks for the
    end-of-image marker (``FFD9``): inside entropy-coded data a ``FF`` byte is always followed by
    ``00`` or a restart marker, so ``FFD9`` there is the real end."""
    i, n = 2, len(data)
    while True:
        if i + 4 > n:
            return "truncated JPEG: the file ends before the image data"
        if data[i] != 0xFF:
            return f"corrupt JPEG: no marker at byte {i}"
        marker = data[i + 1]
        if marker == 0xFF:  # fill byte
            i += 1
            continue
        if marker == 0xDA:
            break
        if 0xD0 <= marker <= 0xD7 or marker == 0x01:  # markers without a length
            i += 2
            continue
        i += 2 + int.from_bytes(data[i + 2:i + 4], "big")
    if data.find(b"\xff\xd9", i) < 0:
        return "truncated JPEG: no end-of-image marker (FFD9); the file was cut short"
    return None


def container_problem(data: bytes) -> str | None:
    """Why the encoded bytes are incomplete (JPEG without its end marker, PNG without IEND), or
    None (also for formats without such a check: OpenCV reports those itself)."""
    if not data:
        return "image file is empty"
    if data[:2] == b"\xff\xd8":
        return _jpeg_problem(data)
    if data[:8] == _PNG_MAGIC and data.rfind(_PNG_IEND) < 0:
        return "incomplete PNG: no IEND chunk (the file was cut short or is corrupt)"
    return None


def check_decoded(img: NDArray[np.generic], where: str) -> None:
    """The decoded array is an image amrvio can use: 8/16 bit, 1/3/4 channels, sane size."""
    if img.ndim not in (2, 3) or (img.ndim == 3 and img.shape[2] not in (1, 3, 4)):
        raise DatasetFormatError(where, f"unsupported image layout {img.shape} (need grey, BGR "
                                        "or BGRA)")
    if img.dtype not in (np.uint8, np.uint16):
        raise DatasetFormatError(where, f"unsupported image depth {img.dtype} (need 8 or 16 bit)")
    h, w = int(img.shape[0]), int(img.shape[1])
    if not (MIN_SIDE_PX <= w <= MAX_SIDE_PX and MIN_SIDE_PX <= h <= MAX_SIDE_PX):
        raise DatasetFormatError(where, f"image is {w}x{h}; each side must be in "
                                        f"[{MIN_SIDE_PX}, {MAX_SIDE_PX}] px")


def to_grey(img: NDArray[np.generic], where: str) -> U8:
    """A checked decoded image (grey, BGR or BGRA; 8 or 16 bit) as (H, W) uint8 grey."""
    import cv2

    check_decoded(img, where)
    if img.ndim == 3:
        if img.shape[2] == 1:
            img = img[:, :, 0]
        else:
            code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
            img = cv2.cvtColor(img, code)
    if img.dtype == np.uint16:
        img = (img.astype(np.uint16) >> 8).astype(np.uint8)
    return np.ascontiguousarray(img, dtype=np.uint8)


def decode_image(data: bytes, where: str) -> U8:
    """Encoded image bytes (JPEG, PNG, PGM, BMP, TIFF) as (H, W) uint8 grey; a
    DatasetFormatError naming ``where`` when the bytes are incomplete or not a usable image."""
    import cv2

    problem = container_problem(data)
    if problem is not None:
        raise DatasetFormatError(where, problem)
    img = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise DatasetFormatError(where, "image cannot be decoded")
    return to_grey(img, where)


def read_image(path: Path) -> U8:
    """The image file ``path`` as (H, W) uint8 grey, checked (see :func:`decode_image`)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise DatasetFormatError(path, "image file is missing") from None
    except OSError as err:
        raise DatasetFormatError(path, f"cannot read image file: {err.strerror or err}") from None
    return decode_image(data, str(path))


@dataclass(frozen=True, slots=True)
class ImageFile:
    """A Frame loader: reads and checks the image file ``path`` when called."""

    path: Path

    def __call__(self) -> U8:
        return read_image(self.path)


__all__ = ["MAX_SIDE_PX", "MIN_SIDE_PX", "ImageFile", "check_decoded", "container_problem",
           "decode_image", "read_image", "to_grey"]
