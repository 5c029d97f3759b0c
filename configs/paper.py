"""The paper's configuration: CMU styled walks, 28 styles (pass --data DIR) (motiongan_jax.config.paper)."""

from motiongan_jax.config import paper


def get_config():
    return paper()
