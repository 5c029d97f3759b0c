"""The paper's architecture on the Bandai Namco data (pass --data DIR) (motiongan_jax.config.bandai)."""

from motiongan_jax.config import bandai


def get_config():
    return bandai()
