"""motiongan_jax: MotionGAN (Watanabe, Nakazawa, Komura) reimplemented in JAX/Flax."""

__version__ = "0.1.0"
