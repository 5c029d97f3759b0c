"""D's and G's objectives as functions of a merged D, and the step's draws of fake labels, z and
gait phase.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from motiongan_jax.nn import Discriminator
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


def g_losses(d: Discriminator, fake_vel_BxTx3, fake_pose_BxTxR, fake_labels_B, curve_BxTx3,
             bone_pairs, bone_lengths_m, train_cfg, length_unit: float, *, log_stride_B=None,
             gait=None, real_vel_BxTx3=None, real_pose_BxTxR=None) -> dict[str, jax.Array]:
    """G's loss terms (one D call). Curve, bone and foot losses are in units of length_unit.
    The gait terms (train.w_g_stride, w_g_floor, w_g_skate) need `gait`, the stride term also
    G's `log_stride_B`, the root jerk term (train.w_g_root_jerk) the real batch's root velocity,
    the joint jerk term (train.w_g_joint_jerk) its root velocity and pose."""
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
    if t.w_g_joint_jerk:
        terms["g_joint_jerk"] = losses.joint_jerk_excess(fake_vel_BxTx3, fake_pose_BxTxR, real_vel_BxTx3,
                                                         real_pose_BxTxR, length_unit)
        total = total + t.w_g_joint_jerk * terms["g_joint_jerk"]
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
