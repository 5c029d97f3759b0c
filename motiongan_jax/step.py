"""One training iteration, D then G (docs/DESIGN.md §4.2), in NNX's functional form.

The modules are split once into graph definitions (static) and state (arrays); `train_step` is a
pure function that merges them inside, so the caller can `jax.jit(..., donate_argnums=0)` it.

    key -> fake labels ŷ ~ U{0..C-1} (independent of the batch), z ~ N(0, I)
    one G forward on velocity(curve): (v̂, P̂), kept with its VJP
    D update:  L_D = w_adv [BCE(D(v̂, P̂)ᵃ, 0.1) + BCE(D(u, P)ᵃ, 0.9)] + w_cls BCE(D(u, P)ᶜ, y)
               on the detached fake; Adam step for D
    G update through the *updated* D, G not re-run:
               L_G = w_adv BCE(D(v̂, P̂)ᵃ, 0.9) + w_cls BCE(D(v̂, P̂)ᶜ, ŷ) + w_curve curve + w_bone bone
               dL/d(v̂, P̂) pulled back through the stored VJP of the single G forward; Adam step for G
    with train.g_ema_decay d > 0: G's moving average e ← d e + (1 - d) θ_G, for generation only

D runs three times (fake for D, real for D, fake for G, in that order) with `update_stats=True`,
so its spectral-norm vectors advance three power iterations per step, as in the reference.
No PRNG key lives in the state: the caller passes `fold_in(base_key, step)`.
Velocities (G's input and the real root velocity) come from `curves.velocity`.

`layout` is anything with `num_rows`, `bone_pairs` and `bone_lengths_m` (representation.RowLayout).
"""

from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx, struct

from motiongan_jax import curves, losses
from motiongan_jax.config import GanLoss, choices
from motiongan_jax.representation import LENGTH_UNIT_M, rest_positions
from motiongan_jax.nn import Discriminator, Generator, SpectralNormState, init_split


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


def _num_rel_joints(layout) -> int:
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
    m = model_cfg
    return Generator(num_rel_joints, base_channels=m.top, kt=m.kw, w_dim=m.w_dim, z_dim=m.z_dim,
                     num_styles=num_styles, latent_init=m.latent_init, length_unit=LENGTH_UNIT_M,
                     rest_pose_R=rest_pose_R, residual_root=m.output_prior, frame=m.g_frame, bones=bones,
                     gait_phase=m.gait_phase, root_height=m.root_height, impl=impl, compute_dtype=dtype,
                     rngs=nnx.Rngs(key))


def _build_d(model_cfg, seq_len: int, num_rel_joints: int, num_styles: int, key, impl: str = "fast",
             dtype: str = "float32") -> Discriminator:
    return Discriminator(num_rel_joints, num_styles=num_styles, seq_len=seq_len, base_channels=model_cfg.top,
                         kt=model_cfg.kw, length_unit=LENGTH_UNIT_M, impl=impl,
                         compute_dtype=dtype, projection=model_cfg.d_cond,
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
    num_rel_joints = _num_rel_joints(layout)
    k_g, k_d = jax.random.split(key)
    kwargs = (("impl", conv_impl(cfg, impl)), ("dtype", compute_dtype(cfg, dtype)))
    g_kwargs = kwargs + (("bones", generator_bones(cfg.model, layout)),)
    g_def, g_params = init_split(_build_g, (cfg.model, num_rel_joints, num_styles, output_prior_rows(cfg.model, layout)),
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


# ---------------------------------------------------------------------------------------------
# Running G with given parameters (previews, generation, analysis)


def generator(state: TrainState, g_params=None) -> Generator:
    """G as an NNX module (a fresh copy; mutating it does not touch the state)."""
    return nnx.merge(state.g_def, state.g_params if g_params is None else g_params, copy=True)


def discriminator(state: TrainState) -> Discriminator:
    return nnx.merge(state.d_def, state.d_params, state.d_sn_state, copy=True)


def generator_state(state: TrainState) -> TrainState:
    """The state with only what G needs (its `g_params`), so that jitted inference neither copies
    nor keys on D, the optimisers or the moving average."""
    return state.replace(d_params=None, d_sn_state=None, opt_g_state=None, opt_d_state=None, g_ema_params=None)


def _zeros_z(state: TrainState, batch: int) -> jax.Array:
    return jnp.zeros((batch, generator_z_dim(state)), jnp.float32)


def has_gait_phase(state: TrainState) -> bool:
    """Whether the state's G keeps a gait phase (model.gait_phase): it then has a stride head."""
    return "stride_head" in state.g_params


def generator_z_dim(state: TrainState) -> int:
    return int(state.g_params["latent"]["embed"].shape[-1])


def latent_w(state: TrainState, labels_B: jax.Array, z_BxZ: jax.Array | None = None) -> jax.Array:
    """Style code w (B x w_dim); z defaults to zeros, as the reference's inference tools use."""
    labels_B = jnp.asarray(labels_B, jnp.int32)
    z = _zeros_z(state, labels_B.shape[0]) if z_BxZ is None else z_BxZ
    return generator(state).style(labels_B, z)


def generator_apply(state: TrainState, curve_vel_BxTx3: jax.Array, labels_B: jax.Array | None = None,
                    z_BxZ: jax.Array | None = None, *, w_BxD: jax.Array | None = None,
                    phase_offset_B: jax.Array | None = None):
    """(root_vel_BxTx3, pose_BxTxR) from G with the state's parameters.

    Give either labels (and optionally z, default zeros) or a style code `w_BxD` directly. To run
    other parameters, pass `state.replace(g_params=...)`. A G with a gait phase takes its phase
    offsets (radians, B) from `phase_offset_B`, default 0.
    """
    g = generator(state)
    if w_BxD is None:
        if labels_B is None:
            raise ValueError("generator_apply needs labels_B or w_BxD")
        labels_B = jnp.asarray(labels_B, jnp.int32)
        z = _zeros_z(state, labels_B.shape[0]) if z_BxZ is None else z_BxZ
        w_BxD = g.style(labels_B, z)
    return g(curve_vel_BxTx3, w_BxD, phase_offset_B)


# ---------------------------------------------------------------------------------------------
# Losses as functions of a merged D


def d_losses(d: Discriminator, fake_vel_BxTx3, fake_pose_BxTxR, real_vel_BxTx3, real_pose_BxTxR,
             labels_B, train_cfg, fake_labels_B=None) -> dict[str, jax.Array]:
    """D's loss terms; the fake is detached here, so no gradient can reach G through them.
    Calls D twice (fake, then real), advancing its spectral-norm vectors each time. A projection
    D judges the fakes as `fake_labels_B` (the styles G was asked for) and the reals as `labels_B`."""
    mode = train_cfg.gan_loss
    adv_f, _ = d(jax.lax.stop_gradient(fake_vel_BxTx3), jax.lax.stop_gradient(fake_pose_BxTxR),
                 update_stats=True, labels_B=fake_labels_B)
    adv_r, cls_r = d(real_vel_BxTx3, real_pose_BxTxR, update_stats=True, labels_B=labels_B)
    adv_fake = losses.adversarial_loss(adv_f, losses.FAKE_TARGET, mode)
    adv_real = losses.adversarial_loss(adv_r, losses.REAL_TARGET, mode)
    cls = losses.class_loss(cls_r, labels_B, mode)
    d_adv = adv_fake + adv_real
    return {
        "d_adv_fake": adv_fake,
        "d_adv_real": adv_real,
        "d_adv": d_adv,
        "d_cls": cls,
        "d_total": train_cfg.w_d_adv * d_adv + train_cfg.w_d_cls * cls,
        "d_acc_real": jnp.mean((adv_r > 0).astype(jnp.float32)),  # sigmoid > 0.5
        "d_acc_fake": jnp.mean((adv_f < 0).astype(jnp.float32)),
        "d_cls_acc_real": jnp.mean((jnp.argmax(cls_r, -1) == labels_B).astype(jnp.float32)),
    }


def g_losses(d: Discriminator, fake_vel_BxTx3, fake_pose_BxTxR, fake_labels_B, curve_BxTx3,
             bone_pairs, bone_lengths_m, train_cfg, length_unit: float, *, log_stride_B=None,
             gait=None, real_vel_BxTx3=None) -> dict[str, jax.Array]:
    """G's loss terms (one D call). Curve, bone and foot losses are in units of length_unit.
    The gait terms (train.w_g_stride, w_g_floor, w_g_skate) need `gait`, the stride term also
    G's `log_stride_B`, the root jerk term (train.w_g_root_jerk) the real batch's root velocity."""
    t = train_cfg
    adv_f, cls_f = d(fake_vel_BxTx3, fake_pose_BxTxR, update_stats=True, labels_B=fake_labels_B)
    adv = losses.adversarial_loss(adv_f, losses.REAL_TARGET, t.gan_loss)
    cls = losses.class_loss(cls_f, fake_labels_B, t.gan_loss)
    curve = losses.curve_loss(fake_vel_BxTx3, curve_BxTx3, t.curve_points, length_unit)
    bone = losses.bone_loss(fake_pose_BxTxR, bone_pairs, bone_lengths_m, length_unit)
    terms = {"g_adv": adv, "g_cls": cls, "g_curve": curve, "g_bone": bone}
    total = t.w_g_adv * adv + t.w_g_cls * cls + t.w_g_curve * curve + t.w_g_bone * bone
    if t.w_g_floor or t.w_g_skate:
        feet = losses.foot_losses(fake_vel_BxTx3, fake_pose_BxTxR, gait.toe_joints, gait.contact_height_m,
                                  length_unit)
        terms.update(g_floor=feet["floor"], g_skate=feet["skate"])
        total = total + t.w_g_floor * feet["floor"] + t.w_g_skate * feet["skate"]
    if t.w_g_root_jerk:
        terms["g_root_jerk"] = losses.root_jerk_excess(fake_vel_BxTx3, real_vel_BxTx3, length_unit)
        total = total + t.w_g_root_jerk * terms["g_root_jerk"]
    if t.w_g_stride:
        terms["g_stride"] = losses.stride_loss(log_stride_B, fake_labels_B, gait.stride_m_C)
        total = total + t.w_g_stride * terms["g_stride"]
    return {**terms, "g_total": total,
            "g_cls_acc_fake": jnp.mean((jnp.argmax(cls_f, -1) == fake_labels_B).astype(jnp.float32))}


def sample_labels_and_z(cfg, num_styles: int, batch: int, key) -> tuple[jax.Array, jax.Array]:
    """Fake labels ŷ ~ U{0..C-1} and z ~ N(0, I)."""
    k_label, k_z = jax.random.split(key)
    labels = jax.random.randint(k_label, (batch,), 0, num_styles, dtype=jnp.int32)
    return labels, jax.random.normal(k_z, (batch, cfg.model.z_dim), jnp.float32)


def sample_phase(cfg, batch: int, key) -> jax.Array | None:
    """Gait-phase offsets φ0 ~ U[0, 2π) (B,) for a G with model.gait_phase; else None. Drawn from
    fold_in(key, 1) so that the labels and z of configs without it stay as they were."""
    if not cfg.model.gait_phase:
        return None
    return jax.random.uniform(jax.random.fold_in(key, 1), (batch,), jnp.float32, 0.0, 2 * jnp.pi)


# ---------------------------------------------------------------------------------------------
# The step


def check_batch(batch: dict, num_rows: int) -> None:
    """Shapes must agree (B x T x 3, B x T x R, B); checked at trace time, costs nothing after."""
    b, t, _ = batch["curve_BxTx3"].shape
    want = {"root_BxTx3": (b, t, 3), "pose_BxTxR": (b, t, num_rows), "curve_BxTx3": (b, t, 3), "label_B": (b,)}
    want.update({k: (b, t) for k in ("phase_BxT", "phase_valid_BxT") if k in batch})
    bad = {k: batch[k].shape for k, shape in want.items() if batch[k].shape != shape}
    if bad:
        raise ValueError(f"batch shapes disagree: {bad}; expected {want}")


def needs_gait_targets(train_cfg) -> bool:
    """Whether the config's G loss has a term that reads data.GaitTargets."""
    return bool(train_cfg.w_g_stride or train_cfg.w_g_floor or train_cfg.w_g_skate)


def make_train_step(cfg, layout, num_styles: int, gait=None) -> Callable:
    """`train_step(state, batch, key) -> (state, metrics)`, pure; jit it with donate_argnums=0.

    batch: root_BxTx3, pose_BxTxR, curve_BxTx3 (metres), label_B (int32); see CONTRACTS.md.
    metrics: scalar loss terms (unweighted; *_total are weighted), D accuracies, and the global L2
    norms of grads, params (after the update) and updates of each network.
    `gait` (data.GaitTargets, from the real training clips) is needed by the gait loss terms.
    """
    tcfg = cfg.train
    rec_half = tcfg.batch_size // 2 if tcfg.w_g_rec else 0
    if needs_gait_targets(tcfg) and gait is None:
        raise ValueError("the gait loss terms (train.w_g_stride, w_g_floor, w_g_skate) need gait targets")
    if gait is not None and len(gait.stride_m_C) != num_styles:
        raise ValueError(f"gait targets have {len(gait.stride_m_C)} stride lengths for {num_styles} styles")
    if tcfg.gan_loss not in choices(GanLoss):
        raise ValueError(f"train.gan_loss must be one of {choices(GanLoss)}, got {tcfg.gan_loss!r}")
    _num_rel_joints(layout)
    bone_pairs = tuple((int(a), int(b)) for a, b in layout.bone_pairs)
    bone_lengths = np.asarray(layout.bone_lengths_m, np.float32)
    if bone_lengths.shape != (len(bone_pairs),):
        raise ValueError(f"{len(bone_pairs)} bone pairs but bone_lengths_m has shape {bone_lengths.shape}")
    tx_g, tx_d = optimizers(cfg)
    ema_decay = float(tcfg.g_ema_decay)

    num_rows = int(layout.num_rows)

    def train_step(state: TrainState, batch: dict, key: jax.Array) -> tuple[TrainState, dict]:
        check_batch(batch, num_rows)
        curve = batch["curve_BxTx3"]
        fake_labels, z = sample_labels_and_z(cfg, num_styles, curve.shape[0], key)
        phase = sample_phase(cfg, curve.shape[0], key)
        curve_vel = curves.velocity(curve)
        real_vel = curves.velocity(batch["root_BxTx3"])
        real_pose = batch["pose_BxTxR"]
        if rec_half:  # the first half: each window's own style and measured phase, z = 0 or as drawn
            rec_B = jnp.arange(curve.shape[0]) < rec_half
            fake_labels = jnp.where(rec_B, batch["label_B"], fake_labels)
            if tcfg.rec_z == "zero":
                z = jnp.where(rec_B[:, None], 0.0, z)

        # The single G forward; its VJP carries G's loss gradient back after the D update.
        def g_forward(g_params):
            g = nnx.merge(state.g_def, g_params, copy=True)
            w = g.style(fake_labels, z)
            phase_BxT = None
            if rec_half:
                phase_BxT = jnp.where(rec_B[:, None], batch["phase_BxT"], g.walked_phase(curve_vel, w, phase))
            root_vel, pose = g(curve_vel, w, phase, phase_BxT)
            return root_vel, pose, (g.log_stride(w) if cfg.model.gait_phase else None)

        fake, g_vjp = jax.vjp(g_forward, state.g_params)

        # --- D update on the detached fake and the real batch --------------------------------
        def d_objective(d_params):
            d = nnx.merge(state.d_def, d_params, state.d_sn_state, copy=True)
            terms = d_losses(d, *fake[:2], real_vel, real_pose, batch["label_B"], tcfg, fake_labels)
            return terms["d_total"], (terms, nnx.state(d, SpectralNormState))

        (_, (d_terms, sn)), d_grads = jax.value_and_grad(d_objective, has_aux=True)(state.d_params)
        d_updates, opt_d = tx_d.update(d_grads, state.opt_d_state, state.d_params)
        d_params = optax.apply_updates(state.d_params, d_updates)

        # --- G update through the updated D --------------------------------------------------
        def g_objective(fake_out):
            d = nnx.merge(state.d_def, d_params, sn, copy=True)
            terms = g_losses(d, *fake_out[:2], fake_labels, curve, bone_pairs, bone_lengths, tcfg,
                             LENGTH_UNIT_M, log_stride_B=fake_out[2], gait=gait, real_vel_BxTx3=real_vel)
            if rec_half:
                h = rec_half
                terms["g_rec"] = losses.reconstruction_loss(fake_out[0][:h], fake_out[1][:h], real_vel[:h],
                                                            real_pose[:h], batch["phase_valid_BxT"][:h],
                                                            LENGTH_UNIT_M)
                terms["g_total"] = terms["g_total"] + tcfg.w_g_rec * terms["g_rec"]
            return terms["g_total"], (terms, nnx.state(d, SpectralNormState))

        (_, (g_terms, sn)), fake_grads = jax.value_and_grad(g_objective, has_aux=True)(fake)
        (g_grads,) = g_vjp(fake_grads)
        g_updates, opt_g = tx_g.update(g_grads, state.opt_g_state, state.g_params)
        g_params = optax.apply_updates(state.g_params, g_updates)

        metrics = {**d_terms, **g_terms,
                   "g_grad_norm": optax.tree.norm(g_grads),
                   "g_param_norm": optax.tree.norm(g_params),
                   "g_update_norm": optax.tree.norm(g_updates),
                   "d_grad_norm": optax.tree.norm(d_grads),
                   "d_param_norm": optax.tree.norm(d_params),
                   "d_update_norm": optax.tree.norm(d_updates)}
        g_ema = state.g_ema_params
        if (g_ema is None) != (ema_decay == 0):
            raise ValueError(f"train.g_ema_decay is {ema_decay} but the state "
                             f"{'has no' if g_ema is None else 'has an'} EMA of G; build it with init_state")
        if g_ema is not None:
            g_ema = jax.tree.map(lambda e, p: ema_decay * e + (1 - ema_decay) * p, g_ema, g_params)
        new_state = state.replace(g_params=g_params, d_params=d_params, d_sn_state=sn,
                                  opt_g_state=opt_g, opt_d_state=opt_d, step=state.step + 1,
                                  g_ema_params=g_ema)
        return new_state, metrics

    return train_step
