"""The small model on the embedded dataset, the shipped model's (motiongan_jax.config.small)."""

from motiongan_jax.config import small


def get_config():
    return small()
