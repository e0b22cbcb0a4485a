"""Shared pytest fixtures."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def shared_data_dir() -> Path:
    """Where the outside test material lives: $RAINGAUGE_SHARED_DATA or ../shared/data."""
    env = os.environ.get("RAINGAUGE_SHARED_DATA")
    return Path(env) if env else REPO.parent / "shared" / "data"


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """Path to ../shared/data; skips the test when the material is absent."""
    path = shared_data_dir()
    if not path.is_dir():
        pytest.skip(f"outside test data not found at {path} (set RAINGAUGE_SHARED_DATA to its folder)")
    return path
