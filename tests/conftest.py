"""Shared fixtures, and the skip policy (tests/skip_policy.py: a skip it does not allow fails the run)."""

from __future__ import annotations

import os
import platform
from pathlib import Path

import pytest

from amrvio.cli.reproducible import blas_coretype, cpu_flags
from tests.skip_policy import pytest_configure, skip_shared_missing

# `amrvio run` pins OpenBLAS's kernels (amrvio.cli.reproducible), and tests compare the Python API
# with the CLI to the bit: the test processes load NumPy's OpenBLAS with the same kernels (measured:
# on an AMD EPYC with AVX-512, whose own choice is the SkylakeX kernels, the events of the tiny
# simulated run differed from the CLI's at its third frame). It acts only on an OpenBLAS not yet
# loaded, and NumPy is not imported above.
_BLAS_CORETYPE = blas_coretype(platform.machine(), cpu_flags())
if _BLAS_CORETYPE is not None:
    os.environ.setdefault("OPENBLAS_CORETYPE", _BLAS_CORETYPE)

__all__ = ["make_tiny_sim", "pytest_configure", "shared_data", "tiny_sim"]

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real sequences in ../shared/data; skips the test (an allowed skip) when the folder is absent."""
    if not SHARED_DATA.is_dir():
        skip_shared_missing(f"{SHARED_DATA} (only developer machines and CI have it)")
    return SHARED_DATA


def make_tiny_sim(root: Path, scene: str = "room", motion: str = "handheld", seed: int = 0,
                  ev_steps: str = "1.5:+1") -> Path:
    """A 3 s simulated recording (EuRoC layout, IMU, ground truth), 376x240 at 10 frames/s, no
    blur, one exposure step: 30 frames that the VO tracks. The exposures are short (3 ms, 6 ms
    after the step), so that rendering without blur is physically consistent: the IMU predicts at
    most 4 px of smear. (With the default 12 ms and the hand-held motion the IMU predicts 8-16 px
    on 9 frames, which the VIO rightly gates as blurred although the images are sharp.)"""
    from amrvio.sim.simulate import SimConfig, simulate

    simulate(SimConfig(scene=scene, motion=motion, seconds=3.0, seed=seed, fps=10.0, width=376,
                       height=240, blur=False, exposure_ms=3.0, ev_steps=ev_steps), root)
    return root


@pytest.fixture(scope="session")
def tiny_sim(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One :func:`make_tiny_sim` recording per test session (read only)."""
    return make_tiny_sim(tmp_path_factory.mktemp("tiny_sim") / "room_handheld")
