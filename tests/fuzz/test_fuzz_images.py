"""Fuzz, classes 1, 2 and 7 of issue 14: broken, truncated, odd-sized and unreadable images, for
``info --check-images``, ``run`` and ``diagnose``.

An image that cannot be used is a counted skip naming the file, never a tracked frame: ``run``
and ``diagnose`` exit 0 with one frame fewer in their outputs, ``info --check-images`` lists it
and exits 1 with one line naming it. An image amrvio can use (16 bit, colour, PNG bytes under a
.jpg name, bytes after the JPEG end) is no skip at all.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterator
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.fuzz.helpers import (
    N_SYNTH,
    Outcome,
    check_diagnose_dir,
    check_run_dir,
    cli,
    copy_of,
    expect_error,
    images_of,
    make_folder,
    make_real_kitti,
    make_synth_euroc,
    make_synth_kitti,
    strict_json,
)

COMMANDS = ("info", "run", "diagnose")


def _bytes(p: Path) -> bytes:
    return p.read_bytes()


def _reencode(p: Path, img: np.ndarray) -> None:
    ok, buf = cv2.imencode(p.suffix, img)
    assert ok
    p.write_bytes(buf.tobytes())


def _img(p: Path) -> np.ndarray:
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    assert img is not None
    return np.asarray(img)


def _replace_with_dir(p: Path) -> None:
    p.unlink()
    p.mkdir()


def _dangling(p: Path) -> None:
    p.unlink()
    p.symlink_to(p.with_name("does-not-exist.png"))


def _exif_thumbnail_then_cut(p: Path) -> None:
    """A JPEG whose EXIF-like APP1 segment holds a complete thumbnail (with its own FFD9), and
    whose main image is cut short: only the walk to the main scan sees that it is incomplete."""
    data = _bytes(p)
    ok, thumb = cv2.imencode(".jpg", np.full((8, 8), 128, np.uint8))
    assert ok
    payload = b"Exif\0\0" + thumb.tobytes()
    app1 = b"\xff\xe1" + (len(payload) + 2).to_bytes(2, "big") + payload
    full = data[:2] + app1 + data[2:]
    p.write_bytes(full[: len(full) - len(data) // 3])


# name -> (breaker, the image is skipped?)
BREAKERS: dict[str, tuple[Callable[[Path], object], bool]] = {
    "cut_in_half": (lambda p: p.write_bytes(_bytes(p)[: len(_bytes(p)) // 2]), True),
    "cut_to_100_bytes": (lambda p: p.write_bytes(_bytes(p)[:100]), True),
    "last_2_bytes_cut": (lambda p: p.write_bytes(_bytes(p)[:-2]), True),
    "empty_file": (lambda p: p.write_bytes(b""), True),
    "random_bytes": (lambda p: p.write_bytes(np.random.default_rng(1).bytes(2000)), True),
    "zero_bytes": (lambda p: p.write_bytes(bytes(len(_bytes(p)))), True),
    "header_only": (lambda p: p.write_bytes(_bytes(p)[:8]), True),
    "a_folder": (_replace_with_dir, True),
    "dangling_link": (_dangling, True),
    "4x4_pixels": (lambda p: _reencode(p, np.full((4, 4), 99, np.uint8)), True),
    "wider": (lambda p: _reencode(p, cv2.resize(_img(p), (72, 48))), True),
    "transposed": (lambda p: _reencode(p, np.ascontiguousarray(_img(p).T)), True),
    "16_bit": (lambda p: _reencode(p, _img(p).astype(np.uint16) * 257), False),
    "colour": (lambda p: _reencode(p, cv2.cvtColor(_img(p), cv2.COLOR_GRAY2BGR)), False),
}
JPEG_BREAKERS: dict[str, tuple[Callable[[Path], object], bool]] = {
    "png_bytes_in_a_jpg": (lambda p: p.write_bytes(cv2.imencode(".png", _img(p))[1].tobytes()),
                           False),
    "bytes_after_the_end": (lambda p: p.write_bytes(_bytes(p) + b"trailing junk"), False),
    "thumbnail_then_cut": (_exif_thumbnail_then_cut, True),
    "colour_alpha_png": (lambda p: p.write_bytes(cv2.imencode(
        ".png", cv2.cvtColor(_img(p), cv2.COLOR_GRAY2BGRA))[1].tobytes()), False),
}

CASES = [(ext, name, cmd) for ext in (".png", ".jpg") for name in BREAKERS for cmd in COMMANDS]
CASES += [(".jpg", name, cmd) for name in JPEG_BREAKERS for cmd in COMMANDS]


@pytest.fixture(scope="module")
def bases(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("bases")
    return {
        ".png": make_synth_kitti(root / "png"),
        ".jpg": make_synth_kitti(root / "jpg", ext=".jpg"),
        "euroc": make_synth_euroc(root / "euroc"),
        "folder": make_folder(root / "folder"),
    }


def _command(cmd: str, root: Path, out: Path, extra: tuple[str, ...] = ()) -> list[str]:
    if cmd == "info":
        return ["info", str(root), "--check-images", "--json", str(out.with_suffix(".json")),
                *extra]
    if cmd == "diagnose":
        return ["diagnose", str(root), "--out", str(out), "--no-plots", *extra]
    return ["run", str(root), "--out", str(out), *extra]


def _expect_skip(cmd: str, o: Outcome, out: Path, bad: Path, n: int, index: int) -> None:
    if cmd == "info":
        expect_error(o, "info", bad, words="1 of")
        js = strict_json(out.with_suffix(".json"))
        assert [b["index"] for b in js["images_unusable"]] == [index]
        assert f"frame {index}: {bad}" in o.out
    elif cmd == "run":
        assert o.rc == 0, o.err
        s = check_run_dir(out, n_frames=n - 1, n_skipped=1)
        assert s["skipped_frames"][0]["file"] == str(bad)
    else:
        assert o.rc == 0, o.err
        check_diagnose_dir(out, n - 1)


def _expect_ok(cmd: str, o: Outcome, out: Path, n: int) -> None:
    assert o.rc == 0, o.err
    if cmd == "info":
        js = strict_json(out.with_suffix(".json"))
        assert js["images_checked"] == n and js["images_unusable"] == []
    elif cmd == "run":
        check_run_dir(out, n_frames=n, n_skipped=0)
    else:
        check_diagnose_dir(out, n)


@pytest.mark.parametrize(("ext", "breaker", "cmd"), CASES,
                         ids=[f"c1-{e[1:]}-{b}-{c}" for e, b, c in CASES])
def test_one_broken_image_mid_sequence(ext: str, breaker: str, cmd: str, bases: dict[str, Path],
                                       tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    root = copy_of(bases[ext], tmp_path / "seq")
    bad = images_of(root)[2]
    brk, skipped = {**BREAKERS, **JPEG_BREAKERS}[breaker]
    brk(bad)
    out = tmp_path / "out"
    o = cli(_command(cmd, root, out), capsys)
    if skipped:
        _expect_skip(cmd, o, out, bad, N_SYNTH, 2)
    else:
        _expect_ok(cmd, o, out, N_SYNTH)


EDGE = [(b, c) for b in ("cut_in_half", "random_bytes") for c in COMMANDS]


@pytest.mark.parametrize(("breaker", "cmd"), EDGE, ids=[f"c1-first-frame-{b}-{c}" for b, c in EDGE])
def test_a_broken_first_image_is_passed_over(breaker: str, cmd: str, bases: dict[str, Path],
                                             tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    root = copy_of(bases[".jpg"], tmp_path / "seq")
    bad = images_of(root)[0]
    BREAKERS[breaker][0](bad)
    out = tmp_path / "out"
    _expect_skip(cmd, cli(_command(cmd, root, out), capsys), out, bad, N_SYNTH, 0)


@pytest.mark.parametrize(("breaker", "cmd"), EDGE, ids=[f"c1-every-frame-{b}-{c}" for b, c in EDGE])
def test_every_image_broken_is_one_error(breaker: str, cmd: str, bases: dict[str, Path],
                                         tmp_path: Path,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    root = copy_of(bases[".jpg"], tmp_path / "seq")
    images = images_of(root)
    for p in images:
        BREAKERS[breaker][0](p)
    out = tmp_path / "out"
    expect_error(cli(_command(cmd, root, out), capsys), cmd, images[0])
    assert not (out / "trajectory.tum").exists()


# class 2: a frame of another size mid-sequence, in each layout
LAYOUTS = ("euroc", "folder", ".png")
SIZES: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "larger": lambda img: cv2.resize(img, (128, 96)),
    "smaller": lambda img: img[:40, :56].copy(),
    "transposed": lambda img: np.ascontiguousarray(img.T),
}
SIZE_CASES = [(lay, s, c) for lay in LAYOUTS for s in SIZES for c in COMMANDS]


@pytest.mark.parametrize(("layout", "size", "cmd"), SIZE_CASES,
                         ids=[f"c2-{lay.strip('.')}-{s}-{c}" for lay, s, c in SIZE_CASES])
def test_a_frame_of_another_size_is_a_named_skip(layout: str, size: str, cmd: str,
                                                 bases: dict[str, Path], tmp_path: Path,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    root = copy_of(bases[layout], tmp_path / "seq")
    bad = images_of(root)[3]
    _reencode(bad, SIZES[size](_img(bad)))
    out = tmp_path / "out"
    o = cli(_command(cmd, root, out), capsys)
    _expect_skip(cmd, o, out, bad, N_SYNTH, 3)
    if cmd == "info":
        assert "but the recording's images are 64x48" in o.err


# class 1 on real images: a truncated KITTI JPEG is skipped and the rest is still tracked
@pytest.mark.parametrize("index", [0, 3], ids=["c1-kitti-real-first-truncated",
                                               "c1-kitti-real-mid-truncated"])
def test_real_kitti_truncated_jpeg_is_skipped_not_tracked(index: int, shared_data: Path,
                                                          tmp_path: Path,
                                                          capsys: pytest.CaptureFixture[str]
                                                          ) -> None:
    n = 14
    root = make_real_kitti(shared_data, tmp_path / "seq", n)
    bad = images_of(root)[index]
    data = bad.read_bytes()
    bad.write_bytes(data[: len(data) // 2])
    out = tmp_path / "out"
    o = cli(["run", str(root), "--out", str(out)], capsys)
    assert o.rc == 0, o.err
    s = check_run_dir(out, n_frames=n - 1, n_skipped=1)
    traj = np.loadtxt(out / "trajectory.tum", ndmin=2)
    t_bad = float((root / "times.txt").read_text().split()[index])
    assert not np.any(np.isclose(traj[:, 0], t_bad, atol=1e-6)), "the bad frame got a pose"
    counts = s["status_counts"]
    assert isinstance(counts, dict) and counts["tracked"] >= n - 4


# class 7: folders that cannot be listed, files that cannot be read, absurd names
def _deny_listing(monkeypatch: pytest.MonkeyPatch, folder: Path) -> None:
    real_listdir, real_iterdir, real_scandir = os.listdir, Path.iterdir, os.scandir

    def listdir(p: str = ".") -> list[str]:
        if Path(str(p)) == folder:
            raise PermissionError(13, "Permission denied", str(p))
        return real_listdir(p)

    def iterdir(self: Path) -> Iterator[Path]:
        if self == folder:
            raise PermissionError(13, "Permission denied", str(self))
        return real_iterdir(self)

    monkeypatch.setattr(os, "listdir", listdir)
    monkeypatch.setattr(Path, "iterdir", iterdir)
    monkeypatch.setattr(os, "scandir", real_scandir)


DENY = [(lay, c) for lay in (".png", "euroc") for c in COMMANDS]


@pytest.mark.parametrize(("layout", "cmd"), DENY,
                         ids=[f"c7-unlistable-image-folder-{lay.strip('.')}-{c}" for lay, c in DENY])
def test_an_image_folder_that_cannot_be_listed(layout: str, cmd: str, bases: dict[str, Path],
                                               tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    # root cannot make a folder unreadable, so the listing itself is refused
    root = copy_of(bases[layout], tmp_path / "seq")
    folder = images_of(root)[0].parent
    out = tmp_path / "out"
    out.mkdir()
    _deny_listing(monkeypatch, folder)
    expect_error(cli(_command(cmd, root, out), capsys), cmd, folder, words="Permission denied")


@pytest.mark.parametrize("cmd", COMMANDS, ids=[f"c7-unreadable-image-{c}" for c in COMMANDS])
def test_an_image_that_cannot_be_read_is_skipped(cmd: str, bases: dict[str, Path],
                                                 tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
                                                 capsys: pytest.CaptureFixture[str]) -> None:
    root = copy_of(bases[".png"], tmp_path / "seq")
    bad = images_of(root)[2]
    real = Path.read_bytes

    def read_bytes(self: Path) -> bytes:
        if self == bad:
            raise PermissionError(13, "Permission denied", str(self))
        return real(self)

    monkeypatch.setattr(Path, "read_bytes", read_bytes)
    out = tmp_path / "out"
    o = cli(_command(cmd, root, out), capsys)
    _expect_skip(cmd, o, out, bad, N_SYNTH, 2)


NAMES = [("100000_chars", "x" * 100_000 + ".png"), ("300_chars", "y" * 300 + ".png"),
         ("a_folder_name", "."), ("absolute_path_of_a_text_file", "ABSOLUTE")]
NAME_CASES = [(n, c) for n, _ in NAMES for c in COMMANDS]


@pytest.mark.parametrize(("what", "cmd"), NAME_CASES,
                         ids=[f"c7-image-name-{n}-{c}" for n, c in NAME_CASES])
def test_absurd_image_names_in_data_csv(what: str, cmd: str, bases: dict[str, Path],
                                        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """A data.csv row naming an impossible image: a line-numbered error for a name no file
    system has, else the row counts as a missing image (skipped with a warning) or, for a name
    that is a folder or another file, a skipped frame."""
    root = copy_of(bases["euroc"], tmp_path / "seq")
    csv_path = root / "mav0" / "cam0" / "data.csv"
    lines = csv_path.read_text().splitlines()
    stamp = lines[3].split(",")[0]
    name = dict(NAMES)[what]
    if name == "ABSOLUTE":
        name = str(root / "notes.txt")
        (root / "notes.txt").write_text("not an image\n")
    lines[3] = f"{stamp},{name}"
    csv_path.write_text("\n".join(lines) + "\n")
    out = tmp_path / "out"
    o = cli(_command(cmd, root, out), capsys)
    if what == "100000_chars":
        expect_error(o, cmd, csv_path, line=4, words="image name of 100004 characters")
    elif what in ("300_chars", "a_folder_name"):  # no such file: the row is left out (a warning)
        assert o.rc == 0, o.err
        if cmd == "run":
            check_run_dir(out, n_frames=N_SYNTH - 1, n_skipped=0)
        elif cmd == "diagnose":
            check_diagnose_dir(out, N_SYNTH - 1)
    else:  # names a file that is no image: a skipped frame
        bad = root / "mav0" / "cam0" / "data" / name
        _expect_skip(cmd, o, out, bad, N_SYNTH, 2)
