"""Where the project keeps what it can make again: preprocessed clips, the generated embedded dataset,
compiled programs. Safe to delete."""

from __future__ import annotations

import os
from pathlib import Path


def cache_root() -> Path:
    """Where preprocessed clips and the generated embedded dataset live: $MOTIONGAN_CACHE,
    default ~/.cache/motiongan_jax."""
    return Path(os.environ.get("MOTIONGAN_CACHE", Path.home() / ".cache" / "motiongan_jax"))
