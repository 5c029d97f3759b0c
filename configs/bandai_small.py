"""The small model on the Bandai Namco data (pass --data DIR) (motiongan_jax.config.bandai_small)."""

from motiongan_jax.config import bandai_small


def get_config():
    return bandai_small()
