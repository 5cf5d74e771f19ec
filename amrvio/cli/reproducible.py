"""Bit-reproducible runs: the same command on the same input gives the same output files.

A run's numerics depend, in their last bits, on where the process's memory lies. Measured on a
700-frame simulated drive with the VIO on: six runs of the same input gave three or four
different trajectories (two trials). They part at a smoother update whose inputs (time, IMU
samples, observations) are identical to the bit, after a few hundred frames whose outputs were
identical too; the solver's floating-point work depends on the memory layout (the native
solvers, GTSAM and Eigen, are the likely source). The tracker's discrete choices (RANSAC,
gates, keyframes) then grow a 1e-16 difference into different keyframes. Python's hash seed and
the kernel's address-space randomisation (ASLR) are what change the layout from one process to
the next: with ``PYTHONHASHSEED=0`` and ASLR off, the six runs gave one trajectory; either alone
was not enough.

The CPU matters too. NumPy's OpenBLAS picks its kernels for the processor it finds: on an Intel
Xeon with AVX-512 (the SkylakeX kernels) the hand-held phone recording kept 49 of its 100 frames in
one map, on an AMD EPYC 71, with the same code and libraries; the Xeon with
``OPENBLAS_CORETYPE=Haswell`` (the AVX2 kernels, which the EPYC uses) gave 71 again.

``amrvio run`` and ``amrvio batch`` therefore start themselves again, once and before any work,
with ``PYTHONHASHSEED=0``, the ``ADDR_NO_RANDOMIZE`` personality (Linux; what ``setarch -R``
does) and, on an x86-64 processor with AVX2 and FMA, ``OPENBLAS_CORETYPE=Haswell`` (unless the
user set it), unless ``AMRVIO_REPRODUCIBLE=0``. ASLR hardens a process against memory-corruption
exploits; a user who runs amrvio on recordings they do not trust can keep it with
``AMRVIO_REPRODUCIBLE=0`` and lose bit-reproducibility only. Where the kernel refuses the
personality, or on another system, the command runs as it is and one log line says so. The same
layout needs the same command line, environment and installed code (a changed docstring moves
it); the library called from Python (``run_pipeline``) is not re-executed.
"""

from __future__ import annotations

import logging
import os
import sys
from collections.abc import Mapping, Sequence

log = logging.getLogger(__name__)

ENV_FLAG = "AMRVIO_REPRODUCIBLE"
"""``0``: leave the process as it is; ``started``: set by the re-execution (it happens once)."""
ADDR_NO_RANDOMIZE = 0x0040000  # <linux/personality.h>
_QUERY = 0xFFFFFFFF  # personality(0xffffffff) returns the current persona and changes nothing
COMMANDS = ("run", "batch")


BLAS_CORETYPE = "Haswell"
"""OpenBLAS's AVX2 kernels: what an x86-64 processor with AVX2 and FMA runs, with or without AVX-512."""


def blas_coretype(machine: str, cpu_flags: frozenset[str]) -> str | None:
    """The OpenBLAS core type to pin on this processor (``platform.machine()``, the flags of
    /proc/cpuinfo), or None (another architecture, or no AVX2: OpenBLAS's own choice)."""
    if machine.lower() in ("x86_64", "amd64") and {"avx2", "fma"} <= cpu_flags:
        return BLAS_CORETYPE
    return None


def cpu_flags() -> frozenset[str]:
    """The feature flags of the first processor in /proc/cpuinfo (empty where there is none)."""
    try:
        with open("/proc/cpuinfo", encoding="ascii", errors="replace") as fh:
            for line in fh:
                if line.startswith("flags"):
                    return frozenset(line.split(":", 1)[1].split())
    except OSError:
        pass
    return frozenset()


def reexec_command(orig_argv: Sequence[str], executable: str, environ: Mapping[str, str],
                   persona: int | None, coretype: str | None = None) -> tuple[list[str], dict[str, str]] | None:
    """The (argv, environment) to execute ``executable`` with for a reproducible run, or None
    when the process needs none: turned off (``AMRVIO_REPRODUCIBLE=0``), already restarted, or
    already set up (hash seed 0 and ``persona`` with ASLR off). ``persona`` None: not Linux, or
    the persona could not be read (nothing is done). ``orig_argv``: ``sys.orig_argv``, the
    interpreter's own command line (its first item is replaced by ``executable``). ``coretype``:
    the OpenBLAS core type to pin (:func:`blas_coretype`), unless ``environ`` names one."""
    flag = environ.get(ENV_FLAG, "")
    if flag in ("0", "started") or persona is None or not orig_argv:
        return None
    blas_ok = coretype is None or "OPENBLAS_CORETYPE" in environ
    if environ.get("PYTHONHASHSEED") == "0" and persona & ADDR_NO_RANDOMIZE and blas_ok:
        return None
    env = dict(environ)
    env["PYTHONHASHSEED"] = "0"
    env[ENV_FLAG] = "started"
    if coretype is not None:
        env.setdefault("OPENBLAS_CORETYPE", coretype)
    return [executable, *orig_argv[1:]], env


def _personality(persona: int) -> int:
    import ctypes

    libc = ctypes.CDLL(None, use_errno=True)
    libc.personality.argtypes = [ctypes.c_ulong]
    libc.personality.restype = ctypes.c_int
    return int(libc.personality(persona))


def current_persona() -> int | None:
    """The process's Linux persona, or None elsewhere or when it cannot be read."""
    if not sys.platform.startswith("linux"):
        return None
    try:
        persona = _personality(_QUERY)
    except (OSError, AttributeError):
        return None
    return None if persona < 0 else persona


def make_reproducible(command: str) -> None:
    """Re-execute this process for a reproducible ``command`` (one of ``COMMANDS``; others are
    left alone) as the module docstring says. Returns only when nothing is done."""
    if command not in COMMANDS:
        return
    import platform

    persona = current_persona()
    coretype = blas_coretype(platform.machine(), cpu_flags()) if persona is not None else None
    plan = reexec_command(getattr(sys, "orig_argv", []), sys.executable, os.environ, persona, coretype)
    if plan is None:
        if persona is None and os.environ.get(ENV_FLAG) != "0":
            log.warning("amrvio %s: address-space randomisation could not be turned off on this "
                        "system; the outputs may differ from run to run", command)
        return
    if persona is None or _personality(persona | ADDR_NO_RANDOMIZE) < 0:
        log.warning("amrvio %s: the kernel refused to turn address-space randomisation off; the "
                    "outputs may differ from run to run", command)
        return
    argv, env = plan
    sys.stdout.flush()
    sys.stderr.flush()
    try:
        os.execve(argv[0], argv, env)
    except OSError as err:
        log.warning("amrvio %s: could not start again reproducibly (%s); the outputs may differ from "
                    "run to run", command, err)


__all__ = ["ADDR_NO_RANDOMIZE", "BLAS_CORETYPE", "COMMANDS", "ENV_FLAG", "blas_coretype", "cpu_flags",
           "current_persona", "make_reproducible", "reexec_command"]
