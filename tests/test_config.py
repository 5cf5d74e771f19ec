"""The configuration tree: YAML keys equal field names, unknown keys and wrong types are errors
naming the key, the dump documents every field and reads back to the same configuration."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from amrvio.config import (
    HELP,
    NOISE_GATES_PX,
    PipelineConfig,
    all_keys,
    config_from_dict,
    config_to_dict,
    dump_config,
    in_tracked_pixels,
    load_config,
    without_photometric,
)
from amrvio.errors import ConfigError
from amrvio.estimator.scale_sources import CameraHeightScale
from amrvio.pipeline.pipeline import Pipeline
from amrvio.types.camera import PinholeCamera


def test_every_key_has_help_and_no_help_is_stale() -> None:
    keys = set(all_keys())
    assert keys - set(HELP) == set()
    assert set(HELP) - keys == set()


def test_dump_reads_back_to_the_defaults(tmp_path: Path) -> None:
    text = dump_config()
    # every field line is preceded by its comment
    lines = text.splitlines()
    for i, line in enumerate(lines[1:], start=1):
        if not line.lstrip().startswith("#"):
            assert lines[i - 1].lstrip().startswith("# "), line
    p = tmp_path / "c.yaml"
    p.write_text(text, encoding="utf-8")
    assert load_config(p) == PipelineConfig()


def test_a_changed_tree_round_trips(tmp_path: Path) -> None:
    base = PipelineConfig()
    cfg = dataclasses.replace(without_photometric(base), seed=7, blur_gating=False)
    p = tmp_path / "c.yaml"
    p.write_text(dump_config(cfg), encoding="utf-8")
    assert load_config(p) == cfg
    assert config_from_dict(config_to_dict(cfg)) == cfg


def test_nested_override_keeps_the_other_defaults() -> None:
    cfg = config_from_dict({"tracking": {"klt": {"detector": {"max_corners": 800}}}, "seed": 3})
    assert cfg.tracking.klt.max_features == 800 == cfg.tracking.klt.detector.max_corners
    assert cfg.seed == 3
    d = PipelineConfig()
    assert cfg.tracking.klt.win_size == d.tracking.klt.win_size
    assert cfg.mapping == d.mapping and cfg.init == d.init
    assert cfg.scale.camera_height_m is None
    assert config_from_dict({"scale": {"camera_height_m": 1}}).scale.camera_height_m == 1.0


@pytest.mark.parametrize(("data", "message"), [
    ({"sed": 1}, "unknown key 'sed'"),
    ({"tracking": {"klt": {"max_featurs": 1}}}, "unknown key 'tracking.klt.max_featurs'"),
    ({"init": {"two_view": {"seed": 1}}}, "unknown key 'init.two_view.seed' (there is one seed"),
    ({"mapping": {"mapper": {"ba_window": "eight"}}}, "'mapping.mapper.ba_window' must be an integer"),
    ({"mapping": {"mapper": {"ba_window": 8.5}}}, "'mapping.mapper.ba_window' must be an integer"),
    ({"blur_gating": "yes"}, "'blur_gating' must be true or false"),
    ({"seed": True}, "'seed' must be an integer"),
    ({"tracking": {"huber_px": float("inf")}}, "'tracking.huber_px' must be finite"),
    ({"tracking": {"huber_px": "2"}}, "'tracking.huber_px' must be a number"),
    ({"tracking": 3}, "'tracking' must be a mapping"),
    ({"mapping": {"mapper": {"ba_backend": 1}}}, "'mapping.mapper.ba_backend' must be a string"),
    ({"tracking": {"blurred_reference_ratio": -0.5}}, "'tracking.blurred_reference_ratio' must be in [0, 1000]"),
    ({"tracking": {"scaled_relative": {"min_points": 1}}},
     "'tracking.scaled_relative.min_points' must be in [2, 1000000]"),
    ({"recovery": {"max_keyframes": 0}}, "'recovery.max_keyframes' must be in [1, 1000000]"),
])
def test_bad_keys_and_types_name_the_key(data: dict, message: str) -> None:
    with pytest.raises(ConfigError) as err:
        config_from_dict(data, "f.yaml")
    assert message in str(err.value)
    assert str(err.value).startswith("f.yaml: ")


def test_bad_yaml_names_the_file_and_line(tmp_path: Path) -> None:
    p = tmp_path / "bad.yaml"
    p.write_text("seed: 1\ntracking: [\n", encoding="utf-8")
    with pytest.raises(ConfigError, match=r"bad.yaml: line \d+ not valid YAML"):
        load_config(p)
    p.write_text("- 1\n- 2\n", encoding="utf-8")
    with pytest.raises(ConfigError, match="must hold a mapping"):
        load_config(p)


def test_one_seed_reaches_every_random_stage() -> None:
    cfg = dataclasses.replace(PipelineConfig(), seed=11)
    p = Pipeline(np.eye(3), cfg)
    assert p.tracker.klt.seed == 11
    assert p.tracker.seed == 11
    assert p.initializer.cfg.two_view.seed == 11
    assert isinstance(p.scale, CameraHeightScale) and p.scale.seed == 11


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([sys.executable, "-m", "amrvio.cli.main", *args], capture_output=True,
                          text=True, check=False)


def test_cli_config_dump_and_check(tmp_path: Path) -> None:
    r = _cli("config", "--dump")
    assert r.returncode == 0
    assert yaml.safe_load(r.stdout)["tracking"]["klt"]["detector"]["max_corners"] == \
        PipelineConfig().tracking.klt.max_features
    bad = tmp_path / "bad.yaml"
    bad.write_text("init:\n  max_frame: 3\n", encoding="utf-8")
    r = _cli("config", "--check", str(bad))
    assert r.returncode == 1
    assert r.stderr.strip().count("\n") == 0
    assert "unknown key 'init.max_frame'" in r.stderr and str(bad) in r.stderr


def test_cli_run_refuses_a_bad_config_before_any_work(tmp_path: Path) -> None:
    bad = tmp_path / "bad.yaml"
    bad.write_text("mapping:\n  mapper:\n    ba_window: eight\n", encoding="utf-8")
    out = tmp_path / "out"
    r = _cli("run", str(tmp_path / "no_such_dataset"), "--out", str(out), "--config", str(bad))
    assert r.returncode == 1
    assert r.stderr.strip().count("\n") == 0
    assert "mapping.mapper.ba_window" in r.stderr
    assert not out.exists()


def test_noise_gates_are_in_pixels_of_the_tracked_level() -> None:
    """A 1920-wide video is tracked one pyramid level down (max_width_px 1280): every noise gate
    doubles and nothing else changes; up to 1280 wide (KITTI 1241, EuRoC 752) or with no width
    the configuration is returned as it is."""
    cfg = PipelineConfig()
    for width in (None, 752, 1241, 1280):
        assert in_tracked_pixels(cfg, width) is cfg
    out = in_tracked_pixels(cfg, 1920)
    before, after = config_to_dict(cfg), config_to_dict(out)

    def leaves(d: dict, prefix: str = "") -> dict:
        flat: dict = {}
        for k, v in d.items():
            flat.update(leaves(v, f"{prefix}{k}.") if isinstance(v, dict) else {f"{prefix}{k}": v})
        return flat

    b, a = leaves(before), leaves(after)
    assert set(NOISE_GATES_PX) <= set(b)
    for key in b:
        assert a[key] == (2 * b[key] if key in NOISE_GATES_PX else b[key]), key
    assert in_tracked_pixels(cfg, 2600).tracking.pnp_thresh_px == 4 * cfg.tracking.pnp_thresh_px  # two levels


def test_the_pipeline_gives_its_stages_the_gates_of_the_tracked_level() -> None:
    """The user's configuration stays as given; the stages of a 1920-wide camera get it in
    tracked pixels (the PnP gate doubled), those of a 752-wide one unchanged."""
    for width, factor in ((1920, 2.0), (752, 1.0)):
        cam = PinholeCamera(width=width, height=480, fx=500.0, fy=500.0, cx=width / 2, cy=240.0)
        pipe = Pipeline(cam)
        assert pipe.cfg == PipelineConfig()
        assert pipe.tracker.cfg.pnp_thresh_px == factor * PipelineConfig().tracking.pnp_thresh_px
