"""The train state: G, D, their optimisers and G's moving average, built from a config.

The modules are split once into graph definitions (static) and state (arrays), so that the step
(train.step) is a pure function of (state, batch, key). No PRNG key lives in the state.
G and D come from model.build; `layout` as there.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import nnx, struct

from motiongan_jax.model import build


@struct.dataclass
class TrainState:
    g_params: Any  # nnx.State of G's nnx.Param (Latent Transform included)
    d_params: Any  # nnx.State of D's nnx.Param (raw, un-normalised weights)
    d_sn_state: Any  # nnx.State of D's SpectralNormState (power-iteration u, v)
    opt_g_state: Any
    opt_d_state: Any
    step: jax.Array  # int32 scalar: completed iterations
    g_def: nnx.GraphDef = struct.field(pytree_node=False)
    d_def: nnx.GraphDef = struct.field(pytree_node=False)
    g_ema_params: Any = None  # EMA of g_params under train.g_ema_decay > 0, else None


def optimizers(cfg) -> tuple[optax.GradientTransformation, optax.GradientTransformation]:
    """(Adam for G, Adam for D), β = (beta1, beta2), eps 1e-8, no decay or schedule (DESIGN.md §4.3)."""
    t = cfg.train
    return (optax.adam(t.lr_g, b1=t.beta1, b2=t.beta2, eps=1e-8),
            optax.adam(t.lr_d, b1=t.beta1, b2=t.beta2, eps=1e-8))


def init_state(cfg, layout, num_styles: int, key: jax.Array, *, impl: str | None = None,
               dtype: str | None = None) -> TrainState:
    """Fresh G, D, spectral-norm vectors and both Adam states; step 0. `impl` (see `conv_impl`)
    only chooses how the convolutions are computed: same parameters, same results; `dtype` (see
    `compute_dtype`) the activations' dtype. Both live in the graph definitions, so the step and
    `model.apply` follow them; parameters and optimizer state are float32 either way."""
    k_g, k_d = jax.random.split(key)
    g_def, g_params = build.init_generator(cfg, layout, num_styles, k_g, impl=impl, dtype=dtype)
    d_def, d_params, d_sn = build.init_discriminator(cfg, layout, num_styles, k_d, impl=impl, dtype=dtype)
    tx_g, tx_d = optimizers(cfg)
    opt_g, opt_d = jax.jit(lambda g, d: (tx_g.init(g), tx_d.init(d)))(g_params, d_params)
    # its own buffers: the step donates the state, and one buffer cannot be donated twice
    g_ema = jax.tree.map(jnp.copy, g_params) if cfg.train.g_ema_decay > 0 else None
    return TrainState(g_params=g_params, d_params=d_params, d_sn_state=d_sn, opt_g_state=opt_g,
                      opt_d_state=opt_d, step=jnp.zeros((), jnp.int32), g_def=g_def, d_def=d_def,
                      g_ema_params=g_ema)


def inference_state(state: TrainState, params: str = "ema") -> TrainState:
    """The state with the G parameters that generation should use: `params` "ema" takes the
    moving average when the run keeps one (train.g_ema_decay > 0) and the raw parameters
    otherwise; "raw" always the raw ones."""
    if params not in ("ema", "raw"):
        raise ValueError(f"params must be 'ema' or 'raw', got {params!r}")
    if params == "raw" or state.g_ema_params is None:
        return state
    return state.replace(g_params=state.g_ema_params)
