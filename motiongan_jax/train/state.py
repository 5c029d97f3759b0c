"""The train state: G, D, their optimisers and G's moving average, built from a config.

The modules are split once into graph definitions (static) and state (arrays), so that the step
(train.step) is a pure function of (state, batch, key). No PRNG key lives in the state.
`layout` is anything with `num_rows`, `bone_pairs` and `bone_lengths_m` (motion.representation.RowLayout).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import nnx, struct

from motiongan_jax.motion.representation import LENGTH_UNIT_M, rest_positions
from motiongan_jax.nn import (
    Discriminator,
    Generator,
    ProjectionDiscriminator,
    SpectralNormState,
    WalkerGenerator,
    init_split,
)


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


def count_rel_joints(layout) -> int:
    rows = int(layout.num_rows)
    if rows % 3:
        raise ValueError(f"layout.num_rows must be a multiple of 3, got {rows}")
    return rows // 3


def output_prior_rows(model_cfg, layout) -> tuple[float, ...] | None:
    """The rest pose rows (metres) G adds to its pose head under model.output_prior; None for
    the paper's G."""
    if not model_cfg.output_prior:
        return None
    if layout is None or layout.rest_offsets_m is None:
        raise ValueError("model.output_prior needs the skeleton's rest offsets")
    return tuple(float(v) for v in rest_positions(layout)[1:].reshape(-1))


def conv_impl(cfg, impl: str | None = None) -> str:
    """How G and D run their convolutions: `impl` if given, else `compute.conv_impl` ("fast":
    nn/conv.py; "xla": the straightforward form; same parameters)."""
    return impl if impl is not None else cfg.compute.conv_impl


def compute_dtype(cfg, dtype: str | None = None) -> str:
    """G's and D's activation dtype: `dtype` if given, else `compute.compute_dtype`. "bfloat16" is
    mixed precision (for GPUs): parameters, optimizer state, normalisation statistics and losses
    stay float32."""
    return dtype if dtype is not None else cfg.compute.compute_dtype


def generator_bones(model_cfg, layout) -> tuple[tuple[int, int, float], ...] | None:
    """(parent, child, length in metres) of every bone when model.exact_bones, else None."""
    if not model_cfg.exact_bones:
        return None
    if layout is None:
        raise ValueError("model.exact_bones needs the skeleton's bone lengths (a layout)")
    return tuple((int(a), int(b), float(length)) for (a, b), length in zip(layout.bone_pairs, layout.bone_lengths_m))


def _build_g(model_cfg, num_rel_joints: int, num_styles: int, rest_pose_R, key, impl: str = "fast",
             dtype: str = "float32", bones=None) -> Generator:
    """The paper's G, or the walker around it when the model section asks for any of its options."""
    m = model_cfg
    paper = dict(base_channels=m.base_channels, kt=m.time_kernel, w_dim=m.w_dim, z_dim=m.z_dim, num_styles=num_styles,
                 latent_init=m.latent_init, length_unit=LENGTH_UNIT_M, impl=impl, compute_dtype=dtype,
                 rngs=nnx.Rngs(key))
    if not (m.output_prior or m.g_frame != "world" or bones is not None or m.gait_phase or m.root_height):
        return Generator(num_rel_joints, **paper)
    return WalkerGenerator(num_rel_joints, rest_pose_R=rest_pose_R, residual_root=m.output_prior, frame=m.g_frame,
                           bones=bones, gait_phase=m.gait_phase, root_height=m.root_height, **paper)


def _build_d(model_cfg, seq_len: int, num_rel_joints: int, num_styles: int, key, impl: str = "fast",
             dtype: str = "float32") -> Discriminator:
    """The paper's D, or with model.d_cond its projection variant."""
    build = ProjectionDiscriminator if model_cfg.d_cond else Discriminator
    return build(num_rel_joints, num_styles=num_styles, seq_len=seq_len, base_channels=model_cfg.base_channels,
                 kt=model_cfg.time_kernel, length_unit=LENGTH_UNIT_M, impl=impl, compute_dtype=dtype,
                 rngs=nnx.Rngs(key))


def build_models(cfg, num_rel_joints: int, num_styles: int, key: jax.Array, layout=None, *,
                 impl: str | None = None, dtype: str | None = None) -> tuple[Generator, Discriminator]:
    """(G, D) as NNX modules from a full Config, initialised like `init_state` with this key (equal
    up to float rounding: init_state compiles its init). Wrap in nnx.eval_shape for shapes only.
    `layout` is needed only for model.output_prior and exact_bones; `impl`, `dtype`: see `conv_impl`,
    `compute_dtype`."""
    k_g, k_d = jax.random.split(key)
    impl, dtype = conv_impl(cfg, impl), compute_dtype(cfg, dtype)
    return (_build_g(cfg.model, num_rel_joints, num_styles, output_prior_rows(cfg.model, layout), k_g, impl, dtype,
                     generator_bones(cfg.model, layout)),
            _build_d(cfg.model, cfg.data.window_T, num_rel_joints, num_styles, k_d, impl, dtype))


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
    `generator_apply` follow them; parameters and optimizer state are float32 either way."""
    num_rel_joints = count_rel_joints(layout)
    k_g, k_d = jax.random.split(key)
    kwargs = (("impl", conv_impl(cfg, impl)), ("dtype", compute_dtype(cfg, dtype)))
    g_kwargs = kwargs + (("bones", generator_bones(cfg.model, layout)),)
    g_def, g_params = init_split(_build_g,
                                 (cfg.model, num_rel_joints, num_styles, output_prior_rows(cfg.model, layout)),
                                 k_g, nnx.Param, build_kwargs=g_kwargs)
    d_def, d_params, d_sn = init_split(_build_d, (cfg.model, cfg.data.window_T, num_rel_joints, num_styles),
                                       k_d, nnx.Param, SpectralNormState, build_kwargs=kwargs)
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
