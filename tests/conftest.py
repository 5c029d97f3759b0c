"""Shared pytest fixtures."""

from __future__ import annotations

import os
from pathlib import Path

import pytest


@pytest.fixture(scope="session")
def shared_data() -> Path:
    """The shared motion data folder (../shared/data beside the checkout, or $MOTIONGAN_SHARED_DATA)."""
    default = Path(__file__).resolve().parents[2] / "shared" / "data"
    path = Path(os.environ.get("MOTIONGAN_SHARED_DATA", default))
    if not path.is_dir():
        pytest.skip(f"shared data not found at {path}: set MOTIONGAN_SHARED_DATA")
    return path
