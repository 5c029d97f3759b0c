"""Tests only: the smallest shapes that exercise every layer (motiongan_jax.config.tiny)."""

from motiongan_jax.config import tiny


def get_config():
    return tiny()
