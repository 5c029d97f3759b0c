"""Networks (Flax NNX, NHWC = (B, T, W, C)): G with its Latent Transform, and D."""

from __future__ import annotations

from typing import NamedTuple

from flax import nnx

from motiongan_jax.nn.discriminator import Discriminator
from motiongan_jax.nn.generator import Generator
from motiongan_jax.nn.latent import LatentTransform
from motiongan_jax.nn.layers import SpectralNormState


class Models(NamedTuple):
    generator: Generator
    discriminator: Discriminator


def build_models(model_cfg, num_joints: int, num_styles: int, seq_len: int, rngs: nnx.Rngs) -> Models:
    """G and D from a `config.ModelConfig`; D is built for windows of `seq_len` samples."""
    g = Generator(num_joints, top=model_cfg.top, kw=model_cfg.kw, w_dim=model_cfg.w_dim,
                  z_dim=model_cfg.z_dim, num_styles=num_styles, rngs=rngs)
    d = Discriminator(num_joints, num_styles=num_styles, seq_len=seq_len, top=model_cfg.top,
                      kw=model_cfg.kw, rngs=rngs)
    return Models(g, d)


def count_params(module: nnx.Module) -> int:
    """Trainable parameters (nnx.Param); spectral-norm u/v are state, not counted."""
    import jax

    return sum(int(x.size) for x in jax.tree_util.tree_leaves(nnx.state(module, nnx.Param)))


__all__ = ["Discriminator", "Generator", "LatentTransform", "Models", "SpectralNormState",
           "build_models", "count_params"]
