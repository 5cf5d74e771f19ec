"""Shared fixtures, and the skip policy (tests/skip_policy.py: a skip it does not allow fails the run)."""

from __future__ import annotations

from pathlib import Path

import pytest

from tests.skip_policy import pytest_configure, skip_shared_missing

__all__ = ["pytest_configure", "shared_data"]

SHARED_DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The real sequences in ../shared/data; skips the test (an allowed skip) when the folder is absent."""
    if not SHARED_DATA.is_dir():
        skip_shared_missing(f"{SHARED_DATA} (only developer machines and CI have it)")
    return SHARED_DATA
