"""Fuzz, class 5 of issue 14: every numeric option of every command, given values no run can use
(inf, NaN, out of range, absurdly large, not a number). Each is refused before any work with one
line that names the option and, for a number out of range, states the range; ``--help`` states
the same range. Values at the edges of the ranges are accepted.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from amrvio.cli.main import build_parser
from amrvio.eval.example import EXAMPLE_EST, EXAMPLE_GT
from tests.fuzz.helpers import cli, expect_error, strict_json

NOWHERE = "/nonexistent-amrvio-dataset"
BASE: dict[str, list[str]] = {
    "run": ["run", NOWHERE, "--out", "/proc/amrvio-fuzz-out"],
    "diagnose": ["diagnose", NOWHERE, "--out", "/proc/amrvio-fuzz-out"],
    "eval": ["eval", str(EXAMPLE_EST), str(EXAMPLE_GT)],
    "simulate": ["simulate", "--out", "/proc/amrvio-fuzz-out"],
    "batch": ["batch", NOWHERE, "--out", "/proc/amrvio-fuzz-out"],
}

FLOAT_JUNK = ("inf", "-inf", "nan", "1e300", "abc", "")
INT_JUNK = ("1.5", "inf", "nan", "99999999999999999999", "abc", "")

# (command, option, bad values)
BAD: list[tuple[str, str, tuple[str, ...]]] = [
    ("run", "--camera-height", (*FLOAT_JUNK, "0", "-1", "0.001", "101")),
    ("run", "--max-frames", (*INT_JUNK, "0", "-1", "10000001")),
    ("run", "--seed", (*INT_JUNK, "-1", "4294967296")),
    ("run", "--wheel-factor", (*FLOAT_JUNK, "0", "-1", "0.49", "2.01")),
    ("batch", "--jobs", (*INT_JUNK, "0", "-1", "1025")),
    ("batch", "--max-frames", (*INT_JUNK, "0", "-1", "10000001")),
    ("batch", "--camera-height", (*FLOAT_JUNK, "0", "101")),
    ("diagnose", "--max-frames", (*INT_JUNK, "0", "-1")),
    ("diagnose", "--assumed-exposure-ms", (*FLOAT_JUNK, "0", "-1", "1001")),
    ("diagnose", "--smear-bound-px", (*FLOAT_JUNK, "0", "-2")),
    ("diagnose", "--ev-step", (*FLOAT_JUNK, "0", "-0.3", "21")),
    ("diagnose", "--estimate-photometric", (*INT_JUNK, "-1", "1", "1001")),
    ("diagnose", "--gyro-bias", ("1,2", "nan,0,0", "inf,0,0", "1e300,0,0", "11,0,0", "a,b,c",
                                 "1,2,3,4", "")),
    ("eval", "--delta", (*FLOAT_JUNK, "0", "-1", "2e6")),
    ("eval", "--max-diff", (*FLOAT_JUNK, "-1", "3601")),
    ("eval", "--n-align", (*INT_JUNK, "0", "-1")),
    ("eval", "--drift-window", (*FLOAT_JUNK, "0", "-1", "2e7")),
    ("simulate", "--seconds", (*FLOAT_JUNK, "0", "-1", "0.01", "3601", "1e9")),
    ("simulate", "--seed", (*INT_JUNK, "-1", "4294967296")),
    ("simulate", "--imu-rate", (*FLOAT_JUNK, "0", "-1", "1e9")),
    ("simulate", "--exposure-ms", (*FLOAT_JUNK, "0", "-1", "60")),
    ("simulate", "--gain", (*FLOAT_JUNK, "0", "-1", "65")),
    ("simulate", "--response-gamma", (*FLOAT_JUNK, "0.1", "6")),
    ("simulate", "--vignette-v1", (*FLOAT_JUNK, "-1", "0.5")),
    ("simulate", "--fps", (*FLOAT_JUNK, "0", "-1", "1001")),
    ("simulate", "--resolution", ("100000x100000", "0x0", "8x8", "-1x480", "axb", "752",
                                  "752x480x3", "4096x4096", "")),
    ("simulate", "--replay-start", (*FLOAT_JUNK, "-1", "1e7")),
    ("simulate", "--replay-smoothing", (*FLOAT_JUNK, "-1", "1e7")),
    ("simulate", "--ev-steps", ("1:inf", "nan:1", "1:1e300", "100:1", "1:+11", "x", "1:2:3",
                                "-1:1")),
    ("simulate", "--blur-bursts", ("0:1:1e9", "0:1:inf", "0:0:1", "-1:1:1", "0:100:1",
                                   "a:b:c", "0:1", "0:1:31")),
    ("simulate", "--wheel-slips", ("0:1:1e9", "0:1:nan", "0:0:0.1", "-1:1:0.1", "1:2",
                                   "0:1:-2", "0:1:11")),
]
CASES = [(cmd, opt, v) for cmd, opt, vals in BAD for v in vals]


@pytest.mark.parametrize(("cmd", "option", "value"), CASES,
                         ids=[f"c5-{c}{o}={v or 'empty'}" for c, o, v in CASES])
def test_a_bad_option_value_is_one_line(cmd: str, option: str, value: str,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    o = cli([*BASE[cmd], f"{option}={value}"], capsys)
    line = expect_error(o, cmd)
    named = option if option not in ("--ev-steps", "--blur-bursts", "--wheel-slips") else \
        option.lstrip("-").replace("-", " ").split()[0]
    assert named in line.replace("-", " ") or option in line, line
    assert "Traceback" not in o.err


# every numeric option states its range in --help, and the error states the same range
RANGED = [("run", "--camera-height", "[0.01, 100]"), ("run", "--max-frames", "[1, 10000000]"),
          ("run", "--seed", "[0, 4294967295]"), ("run", "--wheel-factor", "[0.5, 2]"),
          ("batch", "--jobs", "[1, 1024]"),
          ("batch", "--camera-height", "[0.01, 100]"), ("diagnose", "--ev-step", "(0, 20]"),
          ("diagnose", "--assumed-exposure-ms", "(0, 1000]"),
          ("diagnose", "--smear-bound-px", "(0, 1000]"), ("eval", "--delta", "(0, 1e6]"),
          ("eval", "--max-diff", "[0, 3600]"), ("eval", "--drift-window", "(0, 1e7]"),
          ("eval", "--n-align", "[1, 10000000]"), ("simulate", "--seconds", "[0.05, 3600]"),
          ("simulate", "--imu-rate", "[1, 10000]"), ("simulate", "--fps", "(0, 1000]"),
          ("simulate", "--gain", "(0, 64]"), ("simulate", "--response-gamma", "[0.2, 5]"),
          ("simulate", "--replay-start", "[0, 1e6]"), ("simulate", "--seed", "[0, 4294967295]")]


@pytest.mark.parametrize(("cmd", "option", "rng"), RANGED,
                         ids=[f"c5-help-{c}{o}" for c, o, _ in RANGED])
def test_help_and_error_state_the_range(cmd: str, option: str, rng: str,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    with pytest.raises(SystemExit):
        build_parser().parse_args([cmd, "--help"])
    help_text = " ".join(capsys.readouterr().out.split())
    assert rng in help_text, (option, help_text)
    line = expect_error(cli([*BASE[cmd], option, "1e300"], capsys), cmd)
    assert rng in line and option in line, line


def test_simulate_cli_bounds_match_the_library() -> None:
    from amrvio.cli.cmd_simulate import MAX_PIXELS, OPTION_BOUNDS
    from amrvio.sim import simulate

    assert OPTION_BOUNDS == simulate.SIM_BOUNDS and MAX_PIXELS == simulate.MAX_PIXELS


# values at the edges are accepted: eval runs and writes strict JSON, or (where the value makes
# the figure impossible on this pair of files) says why in one line
EDGES: list[tuple[tuple[str, ...], str | None]] = [
    (("--delta", "1e6"), None), (("--delta", "1e6", "--delta-unit", "m"), None),
    (("--delta", "0.5"), "must be an integer"), (("--delta", "0.5", "--delta-unit", "m"), None),
    (("--max-diff", "0"), "no timestamps match within 0.0 s"), (("--max-diff", "3600"), None),
    (("--n-align", "10000000"), None), (("--drift-window", "1e7"), None),
    (("--drift-window", "1e-6"), None), (("--align", "none"), None), (("--align", "origin"), None),
    (("--align", "se3"), None)]


@pytest.mark.parametrize(("options", "error"), EDGES,
                         ids=[f"c5-edge-eval{'='.join(o)}" for o, _ in EDGES])
def test_edge_values_are_accepted(options: tuple[str, ...], error: str | None, tmp_path: Path,
                                  capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "e.json"
    o = cli([*BASE["eval"], *options, "--json", str(out)], capsys)
    if error is not None:
        expect_error(o, "eval", words=error)
        return
    assert o.rc == 0, o.err
    js = strict_json(out)
    assert js["matched_poses"] > 0
