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


@pytest.fixture(scope="session", autouse=True)
def _compilation_cache(tmp_path_factory):
    """One persistent XLA compilation cache for the whole run, shared by the xdist workers and the
    command-line tools the tests start: a program that another process already compiled (the tiny
    train step in every `bin/train.py` restart, say) is loaded instead of compiled again. Keys
    cover the program, the options and the versions, so a hit computes exactly what a compile would."""
    import jax

    root = tmp_path_factory.getbasetemp()
    shared = root.parent if root.name.startswith("popen-gw") else root  # the same folder for every worker
    path = shared / "jax_compilation_cache"
    path.mkdir(exist_ok=True)
    old = os.environ.get("JAX_COMPILATION_CACHE_DIR")
    old_config = jax.config.jax_compilation_cache_dir
    os.environ["JAX_COMPILATION_CACHE_DIR"] = str(path)
    jax.config.update("jax_compilation_cache_dir", str(path))
    yield
    jax.config.update("jax_compilation_cache_dir", old_config)
    if old is None:
        os.environ.pop("JAX_COMPILATION_CACHE_DIR", None)
    else:
        os.environ["JAX_COMPILATION_CACHE_DIR"] = old


@pytest.fixture(scope="session")
def repo() -> Path:
    return Path(__file__).resolve().parents[1]
