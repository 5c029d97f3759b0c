"""G, D and the Latent Transform built from a config's model section: the paper's networks, or the
walker around the paper's G when the model section asks for any of its options (nn/walker.py).
`layout` is anything with `num_rows`, `bone_pairs`, `bone_lengths_m` and `rest_offsets_m`
(motion.representation.RowLayout).
"""

from __future__ import annotations

import jax
from flax import nnx

from motiongan_jax.motion.representation import LENGTH_UNIT_M, rest_positions
from motiongan_jax.nn import (
    Discriminator,
    Generator,
    ProjectionDiscriminator,
    SpectralNormState,
    WalkerGenerator,
    init_split,
)


def count_rel_joints(layout) -> int:
    rows = int(layout.num_rows)
    if rows % 3:
        raise ValueError(f"layout.num_rows must be a multiple of 3, got {rows}")
    return rows // 3


def output_prior_rows(model_cfg, layout) -> tuple[float, ...] | None:
    """The rest pose rows (metres) G adds to its pose head under model.walker.output_prior; None
    otherwise."""
    if model_cfg.walker is None or not model_cfg.walker.output_prior:
        return None
    if layout is None or layout.rest_offsets_m is None:
        raise ValueError("model.walker.output_prior needs the skeleton's rest offsets")
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
    """(parent, child, length in metres) of every bone when model.walker.exact_bones, else None."""
    if model_cfg.walker is None or not model_cfg.walker.exact_bones:
        return None
    if layout is None:
        raise ValueError("model.walker.exact_bones needs the skeleton's bone lengths (a layout)")
    return tuple((int(a), int(b), float(length)) for (a, b), length in zip(layout.bone_pairs, layout.bone_lengths_m))


def build_generator(model_cfg, num_rel_joints: int, num_styles: int, rest_pose_R, key, impl: str = "fast",
                    dtype: str = "float32", bones=None) -> Generator:
    """The paper's G (model.walker None), or the walker around it (nn/walker.py)."""
    m = model_cfg
    paper = dict(base_channels=m.base_channels, time_kernel=m.time_kernel, w_dim=m.w_dim, z_dim=m.z_dim,
                 num_styles=num_styles, latent_init=m.latent_init, length_unit=LENGTH_UNIT_M, impl=impl,
                 compute_dtype=dtype, rngs=nnx.Rngs(key))
    if m.walker is None:
        return Generator(num_rel_joints, **paper)
    return WalkerGenerator(num_rel_joints, m.walker, rest_pose_R=rest_pose_R, bones=bones, **paper)


def build_discriminator(model_cfg, seq_len: int, num_rel_joints: int, num_styles: int, key, impl: str = "fast",
                        dtype: str = "float32") -> Discriminator:
    """The paper's D, or with model.d_cond its projection variant."""
    build = ProjectionDiscriminator if model_cfg.d_cond else Discriminator
    return build(num_rel_joints, num_styles=num_styles, seq_len=seq_len, base_channels=model_cfg.base_channels,
                 time_kernel=model_cfg.time_kernel, length_unit=LENGTH_UNIT_M, impl=impl, compute_dtype=dtype,
                 rngs=nnx.Rngs(key))


def build_models(cfg, num_rel_joints: int, num_styles: int, key: jax.Array, layout=None, *,
                 impl: str | None = None, dtype: str | None = None) -> tuple[Generator, Discriminator]:
    """(G, D) as NNX modules from a full Config, initialised like `init_state` with this key (equal
    up to float rounding: init_state compiles its init). Wrap in nnx.eval_shape for shapes only.
    `layout` is needed only for the walker's output prior and exact bones; `impl`, `dtype`: see `conv_impl`,
    `compute_dtype`."""
    k_g, k_d = jax.random.split(key)
    impl, dtype = conv_impl(cfg, impl), compute_dtype(cfg, dtype)
    rest = output_prior_rows(cfg.model, layout)
    return (build_generator(cfg.model, num_rel_joints, num_styles, rest, k_g, impl, dtype,
                            generator_bones(cfg.model, layout)),
            build_discriminator(cfg.model, cfg.data.window_T, num_rel_joints, num_styles, k_d, impl, dtype))


def init_generator(cfg, layout, num_styles: int, key: jax.Array, *, impl: str | None = None,
                   dtype: str | None = None):
    """(graph definition, parameters) of a fresh G (Latent Transform included), compiled fast
    (nn.init_split); `impl`, `dtype`: see `conv_impl`, `compute_dtype`."""
    kwargs = (("impl", conv_impl(cfg, impl)), ("dtype", compute_dtype(cfg, dtype)),
              ("bones", generator_bones(cfg.model, layout)))
    return init_split(build_generator,
                      (cfg.model, count_rel_joints(layout), num_styles, output_prior_rows(cfg.model, layout)),
                      key, nnx.Param, build_kwargs=kwargs)


def init_discriminator(cfg, layout, num_styles: int, key: jax.Array, *, impl: str | None = None,
                       dtype: str | None = None):
    """(graph definition, parameters, spectral-norm vectors) of a fresh D."""
    kwargs = (("impl", conv_impl(cfg, impl)), ("dtype", compute_dtype(cfg, dtype)))
    return init_split(build_discriminator, (cfg.model, cfg.data.window_T, count_rel_joints(layout), num_styles),
                      key, nnx.Param, SpectralNormState, build_kwargs=kwargs)
