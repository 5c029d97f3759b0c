"""Latent Transform: style label + z -> style code w (docs/DESIGN.md §3.3).

    w = MLP5(PixelNorm([z, E[label]]))   (all five layers followed by LeakyReLU 0.01)

Init. The embedding E (C x z_dim) is N(0, 1) (nn.Embedding default). The five 1x1 convs use
N(0, 0.02²) weights and zero biases. The reference does not name this init, but its w is
|w| ≈ 2e-5 at initialisation (DESIGN.md §3.2, §6). That magnitude is what N(0, 0.02²) with zero
bias gives through five layers (each layer multiplies the second moment by about
fan_in · 0.02² / 2 ≈ 0.013), whereas PyTorch's default U(±1/sqrt(fan_in)) init would give
|w| ≈ 0.1. We keep the reference's tiny w: with it the AdaIN scales start at their biases a_s and
the style label barely changes G's output at initialisation (tests/test_nn.py checks both).
`init="torch_default"` (config `model.latent_init`) uses PyTorch's default U(±1/sqrt(fan_in))
weights and biases instead, so w starts at |w| ~ 0.1 and the style path is not starved early:
for short CPU runs, not the paper.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import nnx

from motiongan_jax.config import LatentInit, choices
from motiongan_jax.nn.layers import (
    Dense,
    leaky_relu,
    normal_init,
    pixel_norm,
    torch_default_dense,
    zeros_init,
)

NUM_LAYERS = 5


class LatentTransform(nnx.Module):
    def __init__(self, num_styles: int, *, z_dim: int = 64, w_dim: int = 64, init: LatentInit = "paper",
                 rngs: nnx.Rngs):
        if init not in choices(LatentInit):
            raise ValueError(f"latent init must be one of {choices(LatentInit)}, got {init!r}")
        self.num_styles = num_styles
        self.z_dim = z_dim
        # The embedding width equals z_dim: the reference reshapes it to z's shape.
        self.embed = nnx.Param(jax.random.normal(rngs.params(), (num_styles, z_dim)))
        dims = [2 * z_dim] + [w_dim] * NUM_LAYERS
        if init == "paper":
            layers = (Dense(dims[i], dims[i + 1], kernel_init=normal_init(0.02), bias_init=zeros_init, rngs=rngs)
                      for i in range(NUM_LAYERS))
        else:
            layers = (torch_default_dense(dims[i], dims[i + 1], rngs=rngs) for i in range(NUM_LAYERS))
        self.layers = nnx.List(layers)

    def embedding(self, labels_B: jax.Array) -> jax.Array:
        return jnp.take(self.embed[...], labels_B, axis=0)

    def from_embedding(self, embed_BxZ: jax.Array, z_BxZ: jax.Array) -> jax.Array:
        """w from an explicit (possibly blended) label embedding."""
        h = pixel_norm(jnp.concatenate([z_BxZ, embed_BxZ], axis=-1))
        for layer in self.layers:
            h = leaky_relu(layer(h))
        return h

    def __call__(self, labels_B: jax.Array, z_BxZ: jax.Array) -> jax.Array:
        return self.from_embedding(self.embedding(labels_B), z_BxZ)
