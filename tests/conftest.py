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


@pytest.fixture(scope="session", autouse=True)
def _private_cache(tmp_path_factory):
    """Tests never read or write the user's cache (the embedded dataset, preprocessed clips)."""
    old = os.environ.get("MOTIONGAN_CACHE")
    os.environ["MOTIONGAN_CACHE"] = str(tmp_path_factory.mktemp("motiongan_cache"))
    yield
    if old is None:
        os.environ.pop("MOTIONGAN_CACHE", None)
    else:
        os.environ["MOTIONGAN_CACHE"] = old


@pytest.fixture(scope="session")
def repo() -> Path:
    return Path(__file__).resolve().parents[1]
