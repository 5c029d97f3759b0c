"""GAN, class, curve and bone losses (docs/DESIGN.md §4.1). Pure jnp.

Two forms of the GAN and class losses, chosen by `TrainConfig.gan_loss`:

* "bce_prob" reproduces the reference: PyTorch `BCELoss` on sigmoid probabilities (adversarial)
  and on *softmax probabilities* against one-hot targets averaged over B x C (class), each log
  clamped at >= -100. Its gradient is PyTorch's too: (p - t) / max(p (1 - p), 1e-12) per element.
* "bce_logit": sigmoid BCE on logits and softmax cross-entropy, numerically stable.

Units. Data are in metres, the paper's loss weights were tuned on CMU units (1 unit = 0.056444 m).
The curve and bone losses divide every length by `unit` (representation.LENGTH_UNIT_M) so their
size relative to the GAN terms is the paper's.
"""

from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax

from motiongan_jax.config import GanLoss, choices
from motiongan_jax.motion import representation, trajectory

REAL_TARGET = 0.9  # label smoothing of the reference
FAKE_TARGET = 0.1
_LOG_CLAMP = -100.0
_BCE_GRAD_EPS = 1e-12


@jax.custom_vjp
def _bce_elementwise(p: jax.Array, t: jax.Array) -> jax.Array:
    log_p = jnp.maximum(jnp.log(p), _LOG_CLAMP)
    log_1mp = jnp.maximum(jnp.log1p(-p), _LOG_CLAMP)
    return -(t * log_p + (1.0 - t) * log_1mp)


def _bce_fwd(p, t):
    return _bce_elementwise(p, t), (p, t)


def _bce_bwd(res, g):
    p, t = res
    # PyTorch binary_cross_entropy_backward: the clamp does not zero the gradient.
    dp = g * (p - t) / jnp.maximum(p * (1.0 - p), _BCE_GRAD_EPS)
    dt = g * (jnp.maximum(jnp.log1p(-p), _LOG_CLAMP) - jnp.maximum(jnp.log(p), _LOG_CLAMP))
    return dp, dt


_bce_elementwise.defvjp(_bce_fwd, _bce_bwd)


def bce_prob(p: jax.Array, target) -> jax.Array:
    """PyTorch `BCELoss` (mean): -mean[t log p + (1-t) log(1-p)], logs clamped at >= -100."""
    p = jnp.asarray(p)
    return jnp.mean(_bce_elementwise(p, jnp.broadcast_to(jnp.asarray(target, p.dtype), p.shape)))


def adversarial_loss(logits_B: jax.Array, target: float, mode: GanLoss = "bce_prob") -> jax.Array:
    """BCE of D's real/fake logit against a constant target (0.9 real, 0.1 fake)."""
    if mode == "bce_prob":
        return bce_prob(jax.nn.sigmoid(logits_B), target)
    if mode == "bce_logit":
        return jnp.mean(optax.sigmoid_binary_cross_entropy(logits_B, jnp.full_like(logits_B, target)))
    raise ValueError(f"unknown gan loss {mode!r}; one of {choices(GanLoss)}")


def class_loss(logits_BxC: jax.Array, labels_B: jax.Array, mode: GanLoss = "bce_prob") -> jax.Array:
    """Style-class loss. bce_prob: BCE(softmax, one-hot) averaged over B x C (the reference's,
    not a cross-entropy); bce_logit: softmax cross-entropy averaged over B."""
    if mode == "bce_prob":
        onehot = jax.nn.one_hot(labels_B, logits_BxC.shape[-1], dtype=logits_BxC.dtype)
        return bce_prob(jax.nn.softmax(logits_BxC, axis=-1), onehot)
    if mode == "bce_logit":
        return jnp.mean(optax.softmax_cross_entropy_with_integer_labels(logits_BxC, labels_B))
    raise ValueError(f"unknown gan loss {mode!r}; one of {choices(GanLoss)}")


def curve_loss(root_vel_BxTx3: jax.Array, curve_BxTx3: jax.Array, points: int = 4,
               unit: float = 1.0) -> jax.Array:
    """Trajectory loss: the integrated root velocity must hit `points` curve samples.

    With s = T / points, x̂_k = c[0] + Σ_{τ=1}^{k·s−1} v̂[τ] is compared with c[k·s−1] for
    k = 1..points: 0.5 (MSE_x + MSE_z) per point (mean over the batch), summed over points.
    Convention (DESIGN.md §2.5): v[0] is ignored, as in `trajectory.integrate` and everywhere else in
    this package; the reference's sum also includes v̂[0] (whose input counterpart is a duplicate).
    Lengths are divided by `unit`.
    """
    t = curve_BxTx3.shape[1]
    if t % points:
        raise ValueError(f"curve_points={points} must divide T={t}")
    s = t // points
    idx = np.arange(1, points + 1) * s - 1
    pos = trajectory.integrate(curve_BxTx3[:, 0], root_vel_BxTx3)[:, idx]
    diff = (pos - curve_BxTx3[:, idx]) / unit  # B x points x 3
    mse_xz = jnp.mean(jnp.square(diff[..., (0, 2)]), axis=0)  # points x 2
    return jnp.sum(0.5 * jnp.sum(mse_xz, axis=-1))


def bone_loss(pose_BxTxR: jax.Array, bone_pairs: Sequence[tuple[int, int]], target_lengths,
              unit: float = 1.0) -> jax.Array:
    """MSE (over B x T x bones) between generated and target bone lengths, in `unit`s."""
    lengths = representation.bone_lengths(pose_BxTxR, bone_pairs)
    target = jnp.asarray(target_lengths, lengths.dtype)
    return jnp.mean(jnp.square((lengths - target) / unit))


# Soft contact: a toe counts as on the floor by sigmoid((contact height - height) / this).
CONTACT_SOFTNESS_M = 0.01


def world_joints(root_vel_BxTx3: jax.Array, pose_BxTxR: jax.Array) -> jax.Array:
    """World joint positions B x T x J x 3 (kept-joint order, root first) up to one constant per
    window: the root integrated from the origin (trajectory.integrate) plus each joint's root-relative row."""
    b, t, r = pose_BxTxR.shape
    root_BxTx3 = trajectory.integrate(jnp.zeros((b, 3), root_vel_BxTx3.dtype), root_vel_BxTx3)
    rows_BxTxJx3 = jnp.concatenate([jnp.zeros((b, t, 1, 3), pose_BxTxR.dtype), pose_BxTxR.reshape(b, t, r // 3, 3)],
                                   axis=2)
    return root_BxTx3[:, :, None, :] + rows_BxTxJx3


def foot_losses(root_vel_BxTx3: jax.Array, pose_BxTxR: jax.Array, toe_joints, contact_height_m: float,
                unit: float = 1.0) -> dict[str, jax.Array]:
    """Annotation-free foot terms on G's output, in `unit`s (squared), heights measured from each
    window's floor (its lowest toe position), so a body floating as a whole is not punished but
    one drifting up or hopping is.

    * floor: mean over samples of (height of the lower toe above the floor)²: a walk keeps a foot
      down (real walks: millimetres above their lowest toe).
    * skate: mean over steps and toes of c·|Δ(x, z)|², the horizontal step of each toe weighted by
      its soft contact c = sigmoid((contact height − height) / CONTACT_SOFTNESS_M) at the step's
      end: a toe on the floor stands still, and one that moves must lift (c has a gradient).
    Both reach the whole body, root included (docs/RESULTS.md §10 measures stopping the root's).
    """
    toes_BxTxKx3 = world_joints(root_vel_BxTx3, pose_BxTxR)[:, :, np.asarray(toe_joints)]
    h_BxTxK = toes_BxTxKx3[..., 1]
    h_BxTxK = h_BxTxK - jnp.min(h_BxTxK, axis=(1, 2), keepdims=True)
    lift_BxT = jnp.min(h_BxTxK, axis=2) / unit
    step_BxTm1xK = jnp.sum(jnp.square(jnp.diff(toes_BxTxKx3[..., ::2], axis=1)), axis=-1) / unit**2
    contact_BxTm1xK = jax.nn.sigmoid((contact_height_m - h_BxTxK[:, 1:]) / CONTACT_SOFTNESS_M)
    return {"floor": jnp.mean(jnp.square(lift_BxT)), "skate": jnp.mean(contact_BxTm1xK * step_BxTm1xK)}


# A window whose toes never part (a float, a glide) has step height 0: its log (and the square
# root's gradient) is taken as if its variance had this standard deviation added.
STEP_HEIGHT_FLOOR_M = 1e-3


def step_height_loss(root_vel_BxTx3: jax.Array, pose_BxTxR: jax.Array, labels_B: jax.Array, toe_joints,
                     step_height_m_C) -> jax.Array:
    """Mean over windows of (log h_b − log h*_c)²: h_b the standard deviation over the window of its
    left − right toe height (gait.step_amplitude_m's measure), h*_c the real clips' step height of
    the window's style (data.GaitTargets.step_height_m_C). In log, so that a shuffle 2 cm too high
    costs what a march 8 cm too high does; a ratio has no unit."""
    heights_BxTx2 = world_joints(root_vel_BxTx3, pose_BxTxR)[:, :, np.asarray(toe_joints), 1]
    diff_BxT = heights_BxTx2[..., 0] - heights_BxTx2[..., 1]
    var_B = jnp.mean(jnp.square(diff_BxT - jnp.mean(diff_BxT, axis=1, keepdims=True)), axis=1)
    target_B = jnp.log(jnp.asarray(step_height_m_C, jnp.float32))[labels_B]
    return jnp.mean(jnp.square(0.5 * jnp.log(var_B + STEP_HEIGHT_FLOOR_M**2) - target_B))


def root_jerk_excess(fake_vel_BxTx3: jax.Array, real_vel_BxTx3: jax.Array, unit: float = 1.0) -> jax.Array:
    """max(0, E‖Δ²v_fake‖² − E‖Δ²v_real‖²) in `unit`s², over every window and sample: the root's
    jerk (second difference of its velocity) may be as large as the real batch's, not larger."""
    def mean_sq(v_BxTx3):
        return jnp.mean(jnp.sum(jnp.square(jnp.diff(v_BxTx3, n=2, axis=1)), axis=-1))
    return jax.nn.relu(mean_sq(fake_vel_BxTx3) - jax.lax.stop_gradient(mean_sq(real_vel_BxTx3))) / unit**2


def joint_jerk_excess(fake_vel_BxTx3: jax.Array, fake_pose_BxTxR: jax.Array, real_vel_BxTx3: jax.Array,
                      real_pose_BxTxR: jax.Array, unit: float = 1.0) -> jax.Array:
    """Σ_j max(0, E‖Δ³x_fake,j‖² − E‖Δ³x_real,j‖²) in `unit`s², over the world joints x
    (world_joints, root included), each against the same joint of the real batch: pooled over
    joints, the joints smoother than the data would hide the others' excess (docs/RESULTS.md §19)."""
    def per_joint(vel_BxTx3, pose_BxTxR):
        jerk_BxTm3xJx3 = jnp.diff(world_joints(vel_BxTx3, pose_BxTxR), n=3, axis=1)
        return jnp.mean(jnp.sum(jnp.square(jerk_BxTm3xJx3), axis=-1), axis=(0, 1))
    excess_J = per_joint(fake_vel_BxTx3, fake_pose_BxTxR) - jax.lax.stop_gradient(
        per_joint(real_vel_BxTx3, real_pose_BxTxR))
    return jnp.sum(jax.nn.relu(excess_J)) / unit**2


def stride_loss(log_stride: jax.Array, labels_B: jax.Array, gait, step_m_BxT: jax.Array | None = None) -> jax.Array:
    """Mean squared error of G's log stride length (metres) against the data's for the requested
    styles (data.GaitTargets). `log_stride` B: one stride per style, against the style's measured
    stride. B x T (a stride that follows speed): at each sample's walked step `step_m_BxT` (metres
    per sample, samples 1.. only), against the data's stride–speed relation there, log stride_C +
    slope (log v − log speed_C), v = step x gait.sample_hz."""
    log_stride_C = jnp.log(jnp.asarray(gait.stride_m_C, jnp.float32))
    if log_stride.ndim == 1:
        return jnp.mean(jnp.square(log_stride - log_stride_C[labels_B]))
    log_speed_BxT = jnp.log(jnp.maximum(step_m_BxT[:, 1:] * gait.sample_hz, 1e-6))
    log_speed_C = jnp.log(jnp.asarray(gait.speed_mps_C, jnp.float32))
    target_BxT = (log_stride_C[labels_B][:, None]
                  + gait.stride_speed_slope * (log_speed_BxT - log_speed_C[labels_B][:, None]))
    return jnp.mean(jnp.square(log_stride[:, 1:] - target_BxT))


def reconstruction_loss(fake_vel_BxTx3, fake_pose_BxTxR, real_vel_BxTx3, real_pose_BxTxR, valid_BxT,
                        unit: float = 1.0) -> jax.Array:
    """Mean absolute difference (in `unit`s) of root velocity and pose rows between G's output and
    the real windows, over the samples where `valid_BxT`; 0 when none is."""
    diff_BxT = (jnp.sum(jnp.abs(fake_vel_BxTx3 - real_vel_BxTx3), -1)
                + jnp.sum(jnp.abs(fake_pose_BxTxR - real_pose_BxTxR), -1)) / (unit * (3 + real_pose_BxTxR.shape[-1]))
    w_BxT = valid_BxT.astype(diff_BxT.dtype)
    return jnp.sum(w_BxT * diff_BxT) / jnp.maximum(jnp.sum(w_BxT), 1.0)
