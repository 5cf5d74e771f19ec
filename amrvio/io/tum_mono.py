"""TUM monoVO sequences (Engel et al. 2016, photometrically calibrated).

Layout: ``PATH/images/`` or ``PATH/images.zip`` (``00000.jpg``...), ``times.txt`` (``id t_s
exposure_ms`` per line; the exposure column may be absent), ``camera.txt`` (DSO format),
``pcalib.txt`` (inverse response) and ``vignette.png``. Zip members are read lazily, one at a
time, when ``Frame.load()`` is called. A times.txt row without an image is skipped (one warning).
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path, PurePosixPath

import numpy as np
from numpy.typing import NDArray

from amrvio.errors import DatasetFormatError
from amrvio.io.base import Dataset, first_image_shape, warn_missing_images
from amrvio.io.calib_load import load_checked_calibration, read_photometric
from amrvio.io.image import ImageFile, decode_image
from amrvio.io.table import (
    check_columns,
    check_increasing,
    float_columns,
    read_table,
    seconds_column_ns,
)
from amrvio.types.sensors import Frame

U8 = NDArray[np.uint8]

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".pgm", ".bmp", ".tif", ".tiff")


@dataclass(frozen=True, slots=True)
class ZipImage:
    """Reads one image member of a zip archive as (H, W) uint8 grey when called."""

    archive: Path
    member: str

    def __call__(self) -> U8:

        where = f"{self.archive}!{self.member}"
        try:
            with zipfile.ZipFile(self.archive) as zf:
                data = zf.read(self.member)
        except (OSError, KeyError, zipfile.BadZipFile) as err:
            raise DatasetFormatError(where, f"cannot read zip member ({err})") from None
        return decode_image(data, where)

    @property
    def where(self) -> str:
        return f"{self.archive}!{self.member}"


def _image_index(path: Path) -> tuple[dict[str, str], Path | None]:
    """Map image stem -> name, from ``images/`` or else ``images.zip`` (then the zip path)."""
    folder = path / "images"
    if folder.is_dir():
        names = {p.stem: p.name for p in folder.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES}
        return names, None
    archive = path / "images.zip"
    if not archive.is_file():
        raise DatasetFormatError(path, "TUM monoVO sequence: neither images/ nor images.zip found")
    try:
        with zipfile.ZipFile(archive) as zf:
            members = zf.namelist()
    except (OSError, zipfile.BadZipFile) as err:
        raise DatasetFormatError(archive, f"not a readable zip archive ({err})") from None
    names = {
        PurePosixPath(m).stem: m
        for m in members
        if PurePosixPath(m).suffix.lower() in _IMAGE_SUFFIXES
    }
    return names, archive


def read_tum_mono(path: Path, calib: Path | None = None) -> Dataset:
    """Open a TUM monoVO sequence folder; ``calib`` overrides ``camera.txt``."""
    names, archive = _image_index(path)
    times_path = path / "times.txt"
    table = read_table(times_path, None, "times.txt", allow_header=False)
    check_columns(table, 2, "times.txt row", n_max=3)
    stamps = seconds_column_ns(table, 1, "time [s]")
    has_exposure = all(len(r) == 3 for r in table.rows)
    if not has_exposure and any(len(r) == 3 for r in table.rows):
        bad = next(i for i, r in enumerate(table.rows) if len(r) != 3)
        raise DatasetFormatError(
            times_path, "exposure column missing on this line only", table.lines[bad]
        )
    exposure_ms = float_columns(table, [2], "exposure [ms]")[:, 0] if has_exposure else None
    if exposure_ms is not None and np.any(exposure_ms < 0):
        bad = int(np.flatnonzero(exposure_ms < 0)[0])
        raise DatasetFormatError(times_path, "negative exposure time", table.lines[bad])
    check_increasing(table, stamps, "times.txt")
    frames: list[Frame] = []
    missing = 0
    for i, row in enumerate(table.rows):
        name = names.get(row[0])
        if name is None:
            missing += 1
            continue
        exposure_s = None if exposure_ms is None else float(exposure_ms[i]) / 1000.0
        t_ns = int(stamps[i])
        if archive is None:
            image = path / "images" / name
            frames.append(Frame(t_ns, len(frames), image, exposure_s, ImageFile(image)))
        else:
            loader = ZipImage(archive, name)
            frames.append(Frame(t_ns, len(frames), None, exposure_s, loader))
    warn_missing_images(times_path, missing, len(table))
    if not frames:
        raise DatasetFormatError(times_path, "no times.txt row has an image")
    image_hw, image_name = first_image_shape(frames)
    first_loader = frames[0].loader
    if isinstance(first_loader, ZipImage):
        image_name = f"{first_loader.archive}!{first_loader.member}"
    calib_path = calib if calib is not None else path / "camera.txt"
    camera, T_body_cam = load_checked_calibration(
        calib_path if calib_path.is_file() else None, image_hw, image_name
    )
    pcalib = path / "pcalib.txt"
    vignette_path = path / "vignette.png"
    response, vignette = read_photometric(
        pcalib if pcalib.is_file() else None,
        vignette_path if vignette_path.is_file() else None,
        image_hw,
    )
    return Dataset(
        kind="tum-mono",
        root=path,
        frames=tuple(frames),
        camera=camera,
        T_body_cam=T_body_cam,
        inverse_response=response,
        vignette=vignette,
    )
