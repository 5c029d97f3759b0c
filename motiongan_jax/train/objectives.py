"""D's and G's objectives as functions of a merged D (G's loss in one place: every term and the total
from one weights table), and what the step gives G: fake labels, z and gait phase, with the
reconstructed rows of the batch.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from motiongan_jax.motion import trajectory
from motiongan_jax.nn import Discriminator
from motiongan_jax.nn.walker import walked_step
from motiongan_jax.train import losses


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


# G's loss terms and their weights: train.w_g_<name>. The first four are the paper's, always
# computed; the others only when their weight is not 0. The total adds them in this order.
G_TERMS = ("adv", "cls", "curve", "bone", "floor", "skate", "step_height", "root_jerk", "joint_jerk", "stride", "rec")
PAPER_G_TERMS = G_TERMS[:4]


def g_weights(train_cfg) -> dict[str, float]:
    """The weight of every term of G's loss (G_TERMS), from the config."""
    return {name: float(getattr(train_cfg, f"w_g_{name}")) for name in G_TERMS}


def g_losses(d: Discriminator, fake_vel_BxTx3, fake_pose_BxTxR, fake_labels_B, batch: dict, train_cfg,
             length_unit: float, *, bone_pairs, bone_lengths_m, gait=None, log_stride=None) -> dict[str, jax.Array]:
    """Every active term of G's loss (one D call), `g_<name>` unweighted, and `g_total`, their sum
    weighted by `g_weights`. Curve, bone, foot, jerk and reconstruction terms are in units of
    length_unit. The real batch gives the curve, the jerk terms' bounds and the reconstruction's
    targets (the rows `batch["rec_B"]` marks, at the samples `phase_valid_BxT` marks). The gait
    terms need `gait` (data.GaitTargets), the stride term also G's `log_stride` (B, or B x T:
    nn.WalkerGenerator.log_stride)."""
    weights = g_weights(train_cfg)
    active = [n for n in G_TERMS if n in PAPER_G_TERMS or weights[n]]
    real_vel_BxTx3 = trajectory.velocity(batch["root_BxTx3"])
    real_pose_BxTxR = batch["pose_BxTxR"]
    adv_f, cls_f = d(fake_vel_BxTx3, fake_pose_BxTxR, update_stats=True, labels_B=fake_labels_B)
    terms = {"adv": losses.adversarial_loss(adv_f, losses.REAL_TARGET, train_cfg.gan_loss),
             "cls": losses.class_loss(cls_f, fake_labels_B, train_cfg.gan_loss),
             "curve": losses.curve_loss(fake_vel_BxTx3, batch["curve_BxTx3"], train_cfg.curve_points, length_unit),
             "bone": losses.bone_loss(fake_pose_BxTxR, bone_pairs, bone_lengths_m, length_unit)}
    if "floor" in active or "skate" in active:
        feet = losses.foot_losses(fake_vel_BxTx3, fake_pose_BxTxR, gait.toe_joints, gait.contact_height_m,
                                  length_unit)
        terms.update(floor=feet["floor"], skate=feet["skate"])
    if "step_height" in active:
        terms["step_height"] = losses.step_height_loss(fake_vel_BxTx3, fake_pose_BxTxR, fake_labels_B, gait.toe_joints,
                                                       gait.step_height_m_C)
    if "root_jerk" in active:
        terms["root_jerk"] = losses.root_jerk_excess(fake_vel_BxTx3, real_vel_BxTx3, length_unit)
    if "joint_jerk" in active:
        terms["joint_jerk"] = losses.joint_jerk_excess(fake_vel_BxTx3, fake_pose_BxTxR, real_vel_BxTx3,
                                                       real_pose_BxTxR, length_unit)
    if "stride" in active:
        terms["stride"] = losses.stride_loss(log_stride, fake_labels_B, gait,
                                             walked_step(trajectory.velocity(batch["curve_BxTx3"])))
    if "rec" in active:
        valid_BxT = batch["phase_valid_BxT"] & batch["rec_B"][:, None]
        terms["rec"] = losses.reconstruction_loss(fake_vel_BxTx3, fake_pose_BxTxR, real_vel_BxTx3, real_pose_BxTxR,
                                                  valid_BxT, length_unit)
    total = None
    for name in active:
        total = weights[name] * terms[name] if total is None else total + weights[name] * terms[name]
    return {**{f"g_{n}": terms[n] for n in active}, "g_total": total,
            "g_cls_acc_fake": jnp.mean((jnp.argmax(cls_f, -1) == fake_labels_B).astype(jnp.float32))}


def reconstructed_rows(train_cfg) -> int:
    """How many rows of each batch G reconstructs (the first half under train.w_g_rec, else none):
    the batch's `rec_B` marks them (data.sampling.make_sample_batch)."""
    return train_cfg.batch_size // 2 if train_cfg.w_g_rec else 0


def generator_inputs(cfg, num_styles: int, batch: dict, key) -> tuple[jax.Array, jax.Array, jax.Array | None]:
    """(labels_B, z_BxZ, phase_offset_B) the step gives G: labels, z and gait-phase offsets drawn
    from `key`; the rows `batch["rec_B"]` marks take their window's own style (and z = 0 under
    train.rec_z = "zero"), so that G reconstructs them (at their measured phase: the step)."""
    labels, z, phase = sample_draws(cfg, num_styles, batch["curve_BxTx3"].shape[0], key)
    if cfg.train.w_g_rec:
        rec_B = batch["rec_B"]
        labels = jnp.where(rec_B, batch["label_B"], labels)
        if cfg.train.rec_z == "zero":
            z = jnp.where(rec_B[:, None], 0.0, z)
    return labels, z, phase


def sample_draws(cfg, num_styles: int, batch: int, key) -> tuple[jax.Array, jax.Array, jax.Array | None]:
    """(labels_B, z_BxZ, phase_offset_B): fake labels ŷ ~ U{0..C-1}, z ~ N(0, I) and, for a G with
    a gait clock, phase offsets φ0 ~ U[0, 2π) (else None), from one split of `key`, each part
    used once. (Under JAX's partitionable threefry the first two parts of split(key, 3) are those
    of split(key), so labels and z are what they were before the phase had its own key.)"""
    k_label, k_z, k_phase = jax.random.split(key, 3)
    labels = jax.random.randint(k_label, (batch,), 0, num_styles, dtype=jnp.int32)
    z = jax.random.normal(k_z, (batch, cfg.model.z_dim), jnp.float32)
    if not cfg.model.gait_phase:
        return labels, z, None
    return labels, z, jax.random.uniform(k_phase, (batch,), jnp.float32, 0.0, 2 * jnp.pi)
