"""One training iteration, D then G (docs/DESIGN.md §4.2), in NNX's functional form.

`train_step` is a pure function of (state, batch, key) that merges the modules' graph definitions
with the state inside, so the caller can `jax.jit(..., donate_argnums=0)` it.

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
Velocities (G's input and the real root velocity) come from `motion.trajectory.velocity`.
"""

from __future__ import annotations

from typing import Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx

from motiongan_jax.config import GanLoss, choices
from motiongan_jax.model.build import count_rel_joints
from motiongan_jax.model.state import TrainState, optimizers
from motiongan_jax.motion import trajectory
from motiongan_jax.motion.representation import LENGTH_UNIT_M
from motiongan_jax.nn import SpectralNormState
from motiongan_jax.train.objectives import d_losses, g_losses, generator_inputs


def check_batch(batch: dict, num_rows: int, rec: bool = False) -> None:
    """Shapes must agree (B x T x 3, B x T x R, B); checked at trace time, costs nothing after.
    `rec`: the batch must mark its reconstructed rows (`rec_B`) and carry their phase."""
    b, t, _ = batch["curve_BxTx3"].shape
    want = {"root_BxTx3": (b, t, 3), "pose_BxTxR": (b, t, num_rows), "curve_BxTx3": (b, t, 3), "label_B": (b,)}
    want.update({k: (b, t) for k in ("phase_BxT", "phase_valid_BxT") if k in batch or rec})
    if "rec_B" in batch or rec:
        want["rec_B"] = (b,)
    missing = sorted(k for k in want if k not in batch)
    if missing:
        raise ValueError(f"the batch lacks {', '.join(missing)} (train.w_g_rec needs the reconstructed rows marked: "
                         "data.sampling.make_sample_batch with rec_rows)")
    bad = {k: batch[k].shape for k, shape in want.items() if batch[k].shape != shape}
    if bad:
        raise ValueError(f"batch shapes disagree: {bad}; expected {want}")


def needs_gait_targets(train_cfg) -> bool:
    """Whether the config's G loss has a term that reads data.GaitTargets."""
    return bool(train_cfg.w_g_stride or train_cfg.w_g_floor or train_cfg.w_g_skate or train_cfg.w_g_step_height)


def make_train_step(cfg, layout, num_styles: int, gait=None) -> Callable:
    """`train_step(state, batch, key) -> (state, metrics)`, pure; jit it with donate_argnums=0.

    batch: root_BxTx3, pose_BxTxR, curve_BxTx3 (metres), label_B (int32); see CONTRACTS.md.
    metrics: scalar loss terms (unweighted; *_total are weighted), D accuracies, and the global L2
    norms of grads, params (after the update) and updates of each network.
    `gait` (data.GaitTargets, from the real training clips) is needed by the gait loss terms.
    """
    tcfg = cfg.train
    if needs_gait_targets(tcfg) and gait is None:
        raise ValueError("the gait loss terms (train.w_g_stride, w_g_floor, w_g_skate, w_g_step_height) "
                         "need gait targets")
    if gait is not None and not len(gait.stride_m_C) == len(gait.speed_mps_C) == num_styles:
        raise ValueError(f"gait targets have {len(gait.stride_m_C)} stride lengths and {len(gait.speed_mps_C)} "
                         f"speeds for {num_styles} styles")
    if tcfg.gan_loss not in choices(GanLoss):
        raise ValueError(f"train.gan_loss must be one of {choices(GanLoss)}, got {tcfg.gan_loss!r}")
    count_rel_joints(layout)
    bone_pairs = tuple((int(a), int(b)) for a, b in layout.bone_pairs)
    bone_lengths = np.asarray(layout.bone_lengths_m, np.float32)
    if bone_lengths.shape != (len(bone_pairs),):
        raise ValueError(f"{len(bone_pairs)} bone pairs but bone_lengths_m has shape {bone_lengths.shape}")
    tx_g, tx_d = optimizers(cfg)
    ema_decay = float(tcfg.g_ema_decay)

    num_rows = int(layout.num_rows)

    def train_step(state: TrainState, batch: dict, key: jax.Array) -> tuple[TrainState, dict]:
        check_batch(batch, num_rows, rec=bool(tcfg.w_g_rec))
        fake_labels, z, phase = generator_inputs(cfg, num_styles, batch, key)
        curve_vel = trajectory.velocity(batch["curve_BxTx3"])
        real_vel = trajectory.velocity(batch["root_BxTx3"])
        real_pose = batch["pose_BxTxR"]

        # The single G forward; its VJP carries G's loss gradient back after the D update. The
        # reconstructed rows walk their window's measured phase, the others G's own clock.
        def g_forward(g_params):
            g = nnx.merge(state.g_def, g_params, copy=True)
            w = g.style(fake_labels, z)
            phase_BxT = None
            if tcfg.w_g_rec:
                phase_BxT = jnp.where(batch["rec_B"][:, None], batch["phase_BxT"], g.walked_phase(curve_vel, w, phase))
            root_vel, pose = g(curve_vel, w, phase, phase_BxT)
            return root_vel, pose, (g.log_stride(w, curve_vel) if g.has_gait_phase else None)

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
            terms = g_losses(d, *fake_out[:2], fake_labels, batch, tcfg, LENGTH_UNIT_M, bone_pairs=bone_pairs,
                             bone_lengths_m=bone_lengths, gait=gait, log_stride=fake_out[2])
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
