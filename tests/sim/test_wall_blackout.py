"""The wall scene (one textured plane fills the view of wall-scan) and the lens black-out
(--blackout): dark frames, physics of a partly covered exposure, metadata, validation."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import yaml

from amrvio.errors import ConfigError
from amrvio.sim.blackout import Blackout, frames_touched, open_pieces, parse_blackouts


def test_wall_fills_the_view_of_wall_scan_at_the_analytic_depth() -> None:
    """Rendered depth against the ray-plane intersection with x = WALL_X_M: the wall covers most of
    every frame, and the principal point always sees it at the analytic depth."""
    from amrvio.sim.motion import default_T_body_cam, make_motion
    from amrvio.sim.render import SceneRenderer
    from amrvio.sim.scene import WALL_X_M, make_scene
    from amrvio.sim.simulate import SimConfig, layout_for_scene, make_camera

    scene = make_scene("wall", 0)
    camera = make_camera(SimConfig(width=160, height=102))
    renderer = SceneRenderer(scene, camera)
    m = make_motion("wall-scan", 20.0, layout_for_scene(scene), seed=0)
    T_bc = default_T_body_cam()
    us, vs = np.meshgrid(np.arange(camera.width, dtype=float), np.arange(camera.height, dtype=float))
    rays = camera.unproject(np.stack([us.ravel(), vs.ravel()], axis=1))  # z = 1
    fractions = []
    for t in np.linspace(0.0, 20.0, 21):
        T_wc = m.T_world_body(float(t)) @ T_bc
        d_world = rays @ T_wc.R.T
        # X = c + z d (d has z-component 1 in the camera): z = (WALL_X_M - c_x) / d_x
        with np.errstate(divide="ignore"):
            z_wall = np.where(d_world[:, 0] > 0, (WALL_X_M - T_wc.t[0]) / d_world[:, 0], np.inf)
        X = T_wc.t + z_wall[:, None] * d_world
        on_wall = np.isfinite(z_wall) & (np.abs(X[:, 1]) <= 7.0) & (X[:, 2] >= 0.0) & (X[:, 2] <= 5.0)
        depth = renderer.depth(T_wc).ravel()
        match = on_wall & (np.abs(depth - z_wall) <= 1e-4 * z_wall)
        fractions.append(match.mean())
        centre = int(round(camera.cy)) * camera.width + int(round(camera.cx))
        assert match[centre] and 1.0 < depth[centre] < 3.3
    assert min(fractions) > 0.75 and float(np.mean(fractions)) > 0.85, fractions


def test_parse_blackouts_and_one_line_errors() -> None:
    assert parse_blackouts("") == ()
    assert parse_blackouts("5:1, 1.5:0.5", seconds=10.0) == (Blackout(1.5, 0.5), Blackout(5.0, 1.0))
    bad = {"1": "T0:DUR", "a:1": "T0:DUR", "1:2:3": "T0:DUR", "-1:1": "T0 >= 0", "1:0": "DUR > 0",
           "1:-2": "DUR > 0", "nan:1": "finite", "1:inf": "finite", "9.5:1": "ends after",
           "1:2,2.5:1": "overlap"}
    for spec, why in bad.items():
        with pytest.raises(ConfigError, match=why) as err:
            parse_blackouts(spec, seconds=10.0)
        assert "\n" not in str(err.value) and "--blackout" in str(err.value)
    from amrvio.sim.simulate import SimConfig

    with pytest.raises(ConfigError, match="ends after"):
        SimConfig(seconds=4.0, blackouts="3.5:1")


def test_open_pieces_and_frames_touched() -> None:
    assert open_pieces(1.0, 0.01, []) == [(1.0, 0.01)]
    assert open_pieces(1.0, 0.01, [(0.0, 1.0), (1.011, 2.0)]) == [(1.0, 0.01)]
    assert open_pieces(1.0, 0.01, [(0.5, 1.5)]) == []
    (a, da), = open_pieces(1.0, 0.01, [(1.004, 3.0)])
    assert a == 1.0 and da == pytest.approx(0.004)
    pieces = open_pieces(1.0, 0.01, [(1.002, 1.005)])  # covered in the middle: two open pieces
    assert [p[0] for p in pieces] == [1.0, 1.005] and sum(p[1] for p in pieces) == pytest.approx(0.007)
    f = frames_touched(Blackout(1.0, 0.5), [0.944, 0.994, 1.044, 1.444, 1.494], [0.012] * 5)
    assert f.dark == (2, 3) and f.partial == (1, 4)


def _run(out: Path, **kw: object) -> None:
    from amrvio.sim.simulate import SimConfig, simulate

    base: dict[str, object] = dict(scene="room", motion="turn-in-place", seconds=3.0, fps=10.0, width=64,
                                   height=48, seed=4)
    base.update(kw)
    simulate(SimConfig(**base), out)  # type: ignore[arg-type]


def test_blackout_darkens_its_frames_and_the_data_go_on(tmp_path: Path) -> None:
    from amrvio.io.dataset import open_dataset
    from amrvio.sim.writer import read_frames_csv

    _run(tmp_path / "plain")
    _run(tmp_path / "dark", blackouts="1.0:0.5,2.2:0.3")
    plain, dark = open_dataset(str(tmp_path / "plain")), open_dataset(str(tmp_path / "dark"))
    assert len(dark.frames) == len(plain.frames) == 30
    means = np.array([f.load().mean() for f in dark.frames])
    expect_dark = np.zeros(30, bool)
    expect_dark[10:15] = True  # frames exposed around 1.05 .. 1.45 s
    expect_dark[22:25] = True  # 2.25 .. 2.45 s
    assert means[expect_dark].max() < 2.0  # read noise at zero irradiance (1 DN rms, clipped at 0)
    assert means[~expect_dark].min() > 20.0
    # the frames outside the black-outs, the IMU, the ground truth and the wheels are unchanged
    for k in np.flatnonzero(~expect_dark)[:5]:
        np.testing.assert_array_equal(dark.frames[k].load(), plain.frames[k].load())
    for rel in ("mav0/imu0/data.csv", "mav0/state_groundtruth_estimate0/data.csv", "wheel_odometry.csv"):
        assert (tmp_path / "dark" / rel).read_bytes() == (tmp_path / "plain" / rel).read_bytes(), rel
    # the metadata names the dark frames, by index and by stamp
    derived = yaml.safe_load((tmp_path / "dark/sim_config.yaml").read_text())["derived"]
    first, second = derived["blackouts"]
    assert first["t0_s"] == 1.0 and first["dur_s"] == 0.5 and first["dark_frames"] == [10, 14]
    assert first["dark_stamps_ns"] == [dark.frames[10].t_ns, dark.frames[14].t_ns]
    assert second["dark_frames"] == [22, 24] and second["partly_covered_frames"] == []
    assert plain.groundtruth is not None and derived["blackouts"] and "blackouts" in (
        tmp_path / "dark/sim_config.yaml").read_text()
    rows = read_frames_csv(tmp_path / "dark/sim_frames.csv")
    np.testing.assert_array_equal([r.lens_open_fraction == 0.0 for r in rows], expect_dark)
    assert all(r.n_subframes == 0 for r, d in zip(rows, expect_dark, strict=True) if d)


def test_a_partly_covered_exposure_collects_the_light_of_its_open_part(tmp_path: Path) -> None:
    """Noise-free linear sensor: covering the first 8 of 12 ms leaves a third of the energy."""
    from amrvio.sim.writer import read_frames_csv

    kw = dict(sensor_noise=False, blur=False, vignette_v1=0.0, exposure_ms=12.0)
    _run(tmp_path / "plain", **kw)
    _run(tmp_path / "part", blackouts="0.5:0.152", **kw)  # frame 6 is exposed over [0.644, 0.656]
    a = read_frames_csv(tmp_path / "plain/sim_frames.csv")
    b = read_frames_csv(tmp_path / "part/sim_frames.csv")
    assert b[5].lens_open_fraction == 0.0 and b[6].lens_open_fraction == pytest.approx(1 / 3)
    assert b[6].mean_intensity_dn == pytest.approx(a[6].mean_intensity_dn / 3, rel=0.03)
    assert b[7].mean_intensity_dn == a[7].mean_intensity_dn
    derived = yaml.safe_load((tmp_path / "part/sim_config.yaml").read_text())["derived"]
    assert derived["blackouts"][0]["dark_frames"] == [5, 5]
    assert derived["blackouts"][0]["partly_covered_frames"] == [6]


def test_cli_blackout_is_repeatable_and_comma_separated(tmp_path: Path,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    from amrvio.cli.main import main

    base = ["simulate", "--scene", "wall", "--motion", "wall-scan", "--seconds", "1", "--fps", "10",
            "--resolution", "32x24", "--blur", "off"]
    assert main([*base, "--blackout", "0.2:0.2", "--blackout", "0.6:0.2", "--out", str(tmp_path / "a")]) == 0
    assert "4 dark frames" in capsys.readouterr().out
    assert main([*base, "--blackout", "0.2:0.2,0.6:0.2", "--out", str(tmp_path / "b")]) == 0
    capsys.readouterr()
    for name in ("sim_frames.csv", "mav0/imu0/data.csv"):
        assert (tmp_path / "a" / name).read_bytes() == (tmp_path / "b" / name).read_bytes()
    for bad in ("0.5:1", "x", "-0.1:0.2"):
        assert main([*base, f"--blackout={bad}", "--out", str(tmp_path / "c")]) == 1
        err = capsys.readouterr().err.strip()
        assert "--blackout" in err and "\n" not in err and "Traceback" not in err


def test_cli_choices_are_the_simulators() -> None:
    from amrvio.cli.cmd_simulate import MOTION_CHOICES, SCENE_CHOICES
    from amrvio.sim.simulate import MOTIONS, SCENES

    assert SCENE_CHOICES == SCENES and MOTION_CHOICES == MOTIONS
