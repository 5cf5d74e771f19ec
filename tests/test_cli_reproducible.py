"""`amrvio run` and `amrvio batch` restart themselves with a fixed memory layout (hash seed 0, ASLR
off) so that the same command gives the same files (amrvio.cli.reproducible)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap

import pytest

import amrvio.cli.main as cli_main
import amrvio.cli.reproducible as rep
from amrvio.cli.reproducible import ADDR_NO_RANDOMIZE, ENV_FLAG, blas_coretype, cpu_flags, reexec_command

ARGV = ["/usr/bin/python3", "/venv/bin/amrvio", "run", "data", "--out", "o"]


def test_reexec_command_sets_the_hash_seed_and_marks_the_restart() -> None:
    plan = reexec_command(ARGV, "/venv/bin/python", {"HOME": "/h", "PYTHONHASHSEED": "17"}, persona=0)
    assert plan is not None
    argv, env = plan
    assert argv == ["/venv/bin/python", "/venv/bin/amrvio", "run", "data", "--out", "o"]
    assert env["PYTHONHASHSEED"] == "0" and env[ENV_FLAG] == "started" and env["HOME"] == "/h"


@pytest.mark.parametrize(("environ", "persona"), [
    ({ENV_FLAG: "0"}, 0),                                        # turned off by the user
    ({ENV_FLAG: "started"}, 0),                                  # already restarted once
    ({"PYTHONHASHSEED": "0"}, ADDR_NO_RANDOMIZE),                # already set up (setarch -R)
    ({}, None),                                                  # not Linux, or no persona
])
def test_reexec_command_does_nothing_when_not_needed(environ: dict[str, str], persona: int | None) -> None:
    assert reexec_command(ARGV, "/venv/bin/python", environ, persona) is None


def test_openblas_is_pinned_to_its_avx2_kernels_on_x86_64_only() -> None:
    assert blas_coretype("x86_64", frozenset({"avx2", "fma", "avx512f"})) == "Haswell"
    assert blas_coretype("AMD64", frozenset({"avx2", "fma"})) == "Haswell"
    assert blas_coretype("x86_64", frozenset({"sse4_2", "avx"})) is None  # no AVX2: OpenBLAS chooses
    assert blas_coretype("aarch64", frozenset({"avx2", "fma"})) is None
    plan = reexec_command(ARGV, "py", {}, persona=0, coretype="Haswell")
    assert plan is not None and plan[1]["OPENBLAS_CORETYPE"] == "Haswell"
    plan = reexec_command(ARGV, "py", {"OPENBLAS_CORETYPE": "Zen"}, persona=0, coretype="Haswell")
    assert plan is not None and plan[1]["OPENBLAS_CORETYPE"] == "Zen"  # the user's choice stays
    set_up = {"PYTHONHASHSEED": "0"}
    assert reexec_command(ARGV, "py", set_up, persona=ADDR_NO_RANDOMIZE, coretype="Haswell") is not None
    assert reexec_command(ARGV, "py", {**set_up, "OPENBLAS_CORETYPE": "Haswell"}, persona=ADDR_NO_RANDOMIZE,
                          coretype="Haswell") is None


def test_the_cpu_flags_of_this_machine_are_read() -> None:
    flags = cpu_flags()
    if os.path.exists("/proc/cpuinfo"):
        assert flags and all(f == f.strip() and f for f in flags)
    else:
        assert flags == frozenset()


def test_a_hash_seed_alone_or_aslr_alone_is_not_enough() -> None:
    assert reexec_command(ARGV, "py", {"PYTHONHASHSEED": "0"}, persona=0) is not None
    assert reexec_command(ARGV, "py", {}, persona=ADDR_NO_RANDOMIZE) is not None


_PROBE = textwrap.dedent("""
    import os, sys
    from amrvio.cli.reproducible import ADDR_NO_RANDOMIZE, current_persona, make_reproducible
    make_reproducible(sys.argv[1])
    p = current_persona()
    print(os.environ.get("PYTHONHASHSEED"), os.environ.get("AMRVIO_REPRODUCIBLE"),
          sys.flags.hash_randomization, p is not None and bool(p & ADDR_NO_RANDOMIZE),
          os.environ.get("OPENBLAS_CORETYPE"))
""")


def _probe(command: str, **env: str) -> subprocess.CompletedProcess[str]:
    base = {k: v for k, v in os.environ.items() if k not in ("PYTHONHASHSEED", ENV_FLAG, "OPENBLAS_CORETYPE")}
    return subprocess.run([sys.executable, "-c", _PROBE, command], env={**base, **env},
                          capture_output=True, text=True, check=True, timeout=60)


def test_run_restarts_with_hash_seed_0_and_aslr_off_or_says_why_not() -> None:
    import platform

    res = _probe("run")
    if "refused" in res.stderr:  # a kernel (or container) that forbids the personality
        assert res.stdout.split() == ["None", "None", "1", "False", "None"]
    else:
        blas = str(blas_coretype(platform.machine(), cpu_flags()))
        assert res.stdout.split() == ["0", "started", "0", "True", blas], res.stderr


def test_other_commands_and_the_opt_out_leave_the_process_alone() -> None:
    assert _probe("eval").stdout.split()[:3] == ["None", "None", "1"]
    assert _probe("run", AMRVIO_REPRODUCIBLE="0").stdout.split()[:3] == ["None", "0", "1"]


def test_the_console_entry_makes_run_reproducible_before_parsing(monkeypatch: pytest.MonkeyPatch) -> None:
    calls: list[tuple[str, list[str], dict[str, str]]] = []

    class Replaced(Exception):
        pass

    def fake_execve(path: str, argv: list[str], env: dict[str, str]) -> None:
        calls.append((path, argv, env))
        raise Replaced

    monkeypatch.setattr(rep, "current_persona", lambda: 0)
    monkeypatch.setattr(rep, "_personality", lambda persona: 0)
    monkeypatch.setattr(rep.os, "execve", fake_execve)
    monkeypatch.delenv(ENV_FLAG, raising=False)
    monkeypatch.setattr(sys, "argv", ["amrvio", "run", "--help"])
    with pytest.raises(Replaced):
        cli_main.entry()
    assert calls and calls[0][0] == sys.executable and calls[0][2]["PYTHONHASHSEED"] == "0"
    monkeypatch.setattr(sys, "argv", ["amrvio", "eval", "--help"])
    with pytest.raises(SystemExit):  # argparse's --help: no restart for eval
        cli_main.entry()
    assert len(calls) == 1
