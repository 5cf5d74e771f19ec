"""KITTI odometry sequences.

Layout: ``PATH/image_0/NNNNNN.png`` (left grey camera, rectified), ``PATH/calib.txt`` (``P0:``,
3x4 row-major), ``PATH/times.txt`` (seconds, one per image) and, when present, the poses
``PATH/poses.txt`` or ``poses/NN.txt`` beside ``sequences/`` (``NN`` = the sequence folder name).
Poses are ``T_cam0_camk`` (camera 0 at frame k in the camera 0 frame at frame 0).
"""

from __future__ import annotations

from pathlib import Path

from amrvio.errors import DatasetFormatError, TrajectoryFormatError
from amrvio.io.base import Dataset, first_image_shape, rethrow_as_dataset_error
from amrvio.io.calib_load import load_checked_calibration
from amrvio.io.image import ImageFile
from amrvio.io.table import check_columns, check_increasing, read_table, seconds_column_ns
from amrvio.io.trajectory import read_kitti
from amrvio.types.sensors import Frame

_IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".pgm", ".bmp", ".tif", ".tiff")


def find_poses(seq: Path) -> Path | None:
    """``seq/poses.txt``, else ``poses/<seq name>.txt`` one or two levels up."""
    candidates = [seq / "poses.txt"]
    for up in (seq.parent, seq.parent.parent):
        candidates.append(up / "poses" / f"{seq.name}.txt")
    return next((c for c in candidates if c.is_file()), None)


def read_kitti_odometry(path: Path, calib: Path | None = None) -> Dataset:
    """Open a KITTI odometry sequence folder; ``calib`` overrides ``calib.txt``."""
    image_dir = path / "image_0"
    if not image_dir.is_dir():
        raise DatasetFormatError(path, "KITTI sequence: image_0/ folder is missing")
    try:
        images = sorted(p for p in image_dir.iterdir() if p.suffix.lower() in _IMAGE_SUFFIXES)
    except OSError as err:
        raise DatasetFormatError(image_dir, f"cannot list the image folder: {err.strerror}") from None
    if not images:
        raise DatasetFormatError(image_dir, "no images")
    times_path = path / "times.txt"
    table = read_table(times_path, None, "times.txt", allow_header=False)
    check_columns(table, 1, "times.txt row", n_max=1)
    stamps = seconds_column_ns(table, 0, "time [s]")
    check_increasing(table, stamps, "times.txt")
    if len(stamps) != len(images):
        raise DatasetFormatError(
            times_path, f"{len(stamps)} times for {len(images)} images in {image_dir}"
        )
    frames = tuple(
        Frame(t_ns=int(t), index=i, path=p, loader=ImageFile(p))
        for i, (t, p) in enumerate(zip(stamps.tolist(), images, strict=True))
    )
    image_hw, image_name = first_image_shape(frames)
    calib_path = calib if calib is not None else path / "calib.txt"
    camera, T_body_cam = load_checked_calibration(
        calib_path if calib_path.is_file() else None, image_hw, image_name
    )

    groundtruth = None
    poses_path = find_poses(path)
    if poses_path is not None:
        try:
            groundtruth = read_kitti(poses_path, stamps.astype(float) * 1e-9)
        except TrajectoryFormatError as err:
            raise rethrow_as_dataset_error(err) from None
    return Dataset(
        kind="kitti",
        root=path,
        frames=frames,
        camera=camera,
        T_body_cam=T_body_cam,
        groundtruth=groundtruth,
        groundtruth_frame="cam" if groundtruth is not None else "",
    )
