"""G run with per-layer AdaIN scales and biases: blending in AdaIN space, the twin of blending in w
(analysis.style_space).
"""

from __future__ import annotations

from typing import Sequence

import chex
import jax
import jax.numpy as jnp
import numpy as np
from flax import nnx

from motiongan_jax.model import apply as model_apply
from motiongan_jax.nn.layers import AdaIN


def adain_styles(state, w_BxD) -> dict[str, tuple[jax.Array, jax.Array]]:
    """(s, b) of every AdaIN layer of G for the codes w, keyed by block name."""
    return model_apply.generator(state).adain_styles(jnp.asarray(w_BxD, jnp.float32))


def blend_adain(styles: Sequence[dict], weights) -> dict[str, tuple[jax.Array, jax.Array]]:
    """Σ_i weights_i (s_i, b_i), layer by layer (the reference's AdaIN-space blending)."""
    wts = [float(x) for x in np.asarray(weights, np.float64).reshape(-1)]
    if len(wts) != len(styles):
        raise ValueError(f"{len(styles)} style dicts but {len(wts)} weights")
    return jax.tree.map(lambda *leaves: sum(w * x for w, x in zip(wts, leaves)), *styles)


class _FixedAdaIN(AdaIN):
    """An AdaIN whose (s, b) are given instead of computed from w. It inherits AdaIN.__call__, so
    the normalisation and modulation are exactly the real layer's; only `style` is replaced."""

    def __init__(self, s_BxC: jax.Array, b_BxC: jax.Array):  # no parameters: AdaIN.__init__ not run
        self.s_BxC = nnx.data(s_BxC)
        self.b_BxC = nnx.data(b_BxC)

    def style(self, w_BxD):
        del w_BxD
        return self.s_BxC, self.b_BxC


def generator_apply_adain(state, curve_vel_BxTx3, adain: dict, w_BxD=None):
    """(root_vel, pose) from G with the given (s_BxC, b_BxC) in the named AdaIN layers.

    Layers not in `adain` use `w_BxD` (required then). Works on a private copy of G: the AdaIN
    modules of that copy are swapped for fixed ones (nn/generator.py has no override hook).
    """
    g = model_apply.generator(state)
    unknown = set(adain) - set(g.BLOCKS)
    if unknown:
        raise ValueError(f"unknown AdaIN block(s) {sorted(unknown)}; G has {g.BLOCKS}")
    missing = [n for n in g.BLOCKS if n not in adain]
    if missing and w_BxD is None:
        raise ValueError(f"no (s, b) for {missing} and no w_BxD to compute them")
    B = curve_vel_BxTx3.shape[0]
    for name, (s, b) in adain.items():
        block = getattr(g, name)
        C = block.adain.scale.kernel.shape[-1]
        chex.assert_shape([s, b], (B, C))
        block.adain = _FixedAdaIN(jnp.asarray(s, jnp.float32), jnp.asarray(b, jnp.float32))
    w = jnp.zeros((B, g.w_dim), jnp.float32) if w_BxD is None else jnp.asarray(w_BxD, jnp.float32)
    return g(curve_vel_BxTx3, w)
