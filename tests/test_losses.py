"""Losses: hand-computed values, PyTorch's BCE clamp and gradient, zero-loss invariants."""

from __future__ import annotations

import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from motiongan_jax.motion import representation, trajectory
from motiongan_jax.train import losses


def test_bce_prob_hand():
    p = jnp.array([0.8, 0.3])
    got = float(losses.bce_prob(p, 0.9))
    want = -0.5 * ((0.9 * math.log(0.8) + 0.1 * math.log(0.2)) + (0.9 * math.log(0.3) + 0.1 * math.log(0.7)))
    assert abs(got - want) < 1e-6
    assert abs(got - 0.740508) < 1e-5  # (0.361774 + 1.119243) / 2


def test_bce_log_clamp_at_minus_100():
    # log 0 is clamped to -100, as in PyTorch: BCE(0, 1) = 100, BCE(1, 0.9) = 0.1 * 100
    np.testing.assert_allclose(float(losses.bce_prob(jnp.array([0.0]), 1.0)), 100.0)
    np.testing.assert_allclose(float(losses.bce_prob(jnp.array([1.0]), 0.9)), 10.0, rtol=1e-6)
    # saturated sigmoid in the reference's probability form
    np.testing.assert_allclose(float(losses.adversarial_loss(jnp.array([200.0]), 0.1, "bce_prob")), 90.0, rtol=1e-6)


def test_bce_gradient_is_pytorchs():
    p = jnp.array([0.8, 0.3, 1.0])
    grad = np.asarray(jax.grad(lambda p: losses.bce_prob(p, 0.9))(p))
    # (p - t) / max(p (1 - p), 1e-12) / N, not zeroed by the clamp at p = 1
    want = np.array([(0.8 - 0.9) / (0.8 * 0.2), (0.3 - 0.9) / (0.3 * 0.7), 0.1 / 1e-12]) / 3
    np.testing.assert_allclose(grad, want, rtol=1e-5)


def test_prob_and_logit_adversarial_agree_away_from_saturation():
    logits = jnp.linspace(-6.0, 6.0, 25)
    for target in (losses.REAL_TARGET, losses.FAKE_TARGET):
        a = losses.adversarial_loss(logits, target, "bce_prob")
        b = losses.adversarial_loss(logits, target, "bce_logit")
        np.testing.assert_allclose(float(a), float(b), rtol=1e-5)
        ga = jax.grad(lambda x: losses.adversarial_loss(x, target, "bce_prob"))(logits)
        gb = jax.grad(lambda x: losses.adversarial_loss(x, target, "bce_logit"))(logits)
        np.testing.assert_allclose(np.asarray(ga), np.asarray(gb), rtol=1e-4, atol=1e-7)


def test_class_loss_hand():
    logits = jnp.array([[0.0, 0.0, math.log(2.0)]])  # softmax = (1/4, 1/4, 1/2)
    label = jnp.array([2])
    prob = float(losses.class_loss(logits, label, "bce_prob"))
    # BCE on softmax probabilities against one-hot, averaged over the 3 elements: not a CE
    assert abs(prob - (-(2 * math.log(0.75) + math.log(0.5)) / 3)) < 1e-6
    logit = float(losses.class_loss(logits, label, "bce_logit"))
    assert abs(logit - math.log(2.0)) < 1e-6
    with pytest.raises(ValueError, match="gan loss"):
        losses.class_loss(logits, label, "hinge")


def test_curve_loss_zero_when_velocity_integrates_to_curve():
    c = jax.random.normal(jax.random.key(0), (3, 16, 3)) * 2.0
    v = trajectory.velocity(c).at[:, 0].set(123.0)  # v[0] is ignored by the convention
    assert float(losses.curve_loss(v, c, 4, 0.056444)) < 1e-6


def test_curve_loss_hand():
    t = jnp.arange(8.0)
    c = jnp.stack([t, jnp.full_like(t, 5.0), -t], -1)[None]  # x = t, y ignored, z = -t
    v = jnp.zeros_like(c)
    # points at k·s - 1 = 3 and 7; x̂ = c[0] = 0: 0.5 (9 + 9) + 0.5 (49 + 49) = 58
    assert abs(float(losses.curve_loss(v, c, 2)) - 58.0) < 1e-5
    assert abs(float(losses.curve_loss(v, c, 2, unit=2.0)) - 58.0 / 4) < 1e-5


def _chain_pose(lengths, T=5, B=2):
    """Joints 1..J on a bent chain from the root; bone k joins k-1 and k."""
    rng = np.random.default_rng(0)
    dirs = rng.normal(size=(B, T, len(lengths), 3))
    dirs /= np.linalg.norm(dirs, axis=-1, keepdims=True)
    pos = np.cumsum(dirs * np.asarray(lengths)[:, None], axis=2)
    return jnp.asarray(pos.reshape(B, T, -1), jnp.float32)


def test_bone_loss_zero_at_target_lengths_and_hand():
    lengths = np.array([0.1, 0.4, 0.25, 0.3])
    pairs = [(0, 1), (1, 2), (2, 3), (3, 4)]
    pose = _chain_pose(lengths)
    np.testing.assert_allclose(np.asarray(representation.bone_lengths(pose, pairs)),
                               np.broadcast_to(lengths, (2, 5, 4)), rtol=1e-5)
    assert float(losses.bone_loss(pose, pairs, lengths, 0.056444)) < 1e-9
    # one bone 0.1 too long everywhere: MSE over 4 bones = 0.01 / 4, in units of 0.05
    target = lengths.copy()
    target[2] -= 0.1
    np.testing.assert_allclose(float(losses.bone_loss(pose, pairs, target, 0.05)), 0.01 / 4 / 0.0025, rtol=1e-4)


def test_bone_loss_gradient_finite_at_zero_length():
    pose = jnp.zeros((1, 2, 6))
    g = jax.grad(lambda p: losses.bone_loss(p, [(0, 1), (1, 2)], [0.1, 0.2]))(pose)
    assert bool(jnp.all(jnp.isfinite(g)))


# ---------------------------------------------------------------------------------------------
# Gait terms

def _toes_as_output(toes_BxTx2x3):
    """G-style outputs (root velocity, rows) whose world toes (joints 1 and 2) are `toes`: the root
    stays at the origin, so the rows are the toes themselves."""
    b, t = toes_BxTx2x3.shape[:2]
    return jnp.zeros((b, t, 3)), jnp.asarray(toes_BxTx2x3.reshape(b, t, 6), jnp.float32)


def test_foot_losses_by_hand():
    T, unit, contact = 12, 0.05, 0.02
    # a planted left toe and a right toe 0.3 m up swinging 0.1 m per sample: the lower toe is on
    # the floor (no floor term), the planted toe does not move, the swinging one is far above the
    # contact height (its weight sigmoid(-0.28 / 0.01) ~ 7e-13): both terms ~0
    toes = np.zeros((1, T, 2, 3))
    toes[0, :, 1, 1] = 0.3
    toes[0, :, 1, 2] = 0.1 * np.arange(T)
    out = losses.foot_losses(*_toes_as_output(toes), (1, 2), contact, unit)
    assert float(out["floor"]) == 0.0 and float(out["skate"]) < 1e-9
    # a glider, both toes on the floor sliding 0.04 m per sample: contact weight sigmoid(2) at
    # height 0, so skate = sigmoid(2) (0.04 / 0.05)² for every step and toe; floor still 0
    glide = np.zeros((1, T, 2, 3))
    glide[0, :, :, 2] = 0.04 * np.arange(T)[:, None]
    out = losses.foot_losses(*_toes_as_output(glide), (1, 2), contact, unit)
    assert float(out["floor"]) == 0.0
    assert float(out["skate"]) == pytest.approx(1 / (1 + math.exp(-2)) * 0.64, rel=1e-5)
    # a hopper, both toes 0 m for the first half, 0.1 m for the second (heights are measured from
    # the window's own lowest toe, so a whole-body offset changes nothing): the lower toe is
    # 0.1 m up in half the samples
    hop = np.zeros((2, T, 2, 3))
    hop[:, T // 2:, :, 1] = 0.1
    hop[1, ..., 1] += 0.7
    out = losses.foot_losses(*_toes_as_output(hop), (1, 2), contact, unit)
    assert float(out["floor"]) == pytest.approx(0.5 * (0.1 / unit) ** 2, rel=1e-5)
    # with the root carrying the glide instead of the rows, the same skate (world toes are root +
    # rows, the root integrated from the origin)
    vel = jnp.zeros((1, T, 3)).at[:, :, 2].set(0.04)
    rows = jnp.zeros((1, T, 6))
    assert float(losses.foot_losses(vel, rows, (1, 2), contact, unit)["skate"]) == pytest.approx(
        1 / (1 + math.exp(-2)) * 0.64, rel=1e-5)
    # the whole body is asked to plant the feet: the root's velocity gets a gradient too
    g_vel, g_rows = jax.grad(lambda v, r: losses.foot_losses(v, r, (1, 2), contact, unit)["skate"],
                             argnums=(0, 1))(vel, rows)
    assert float(jnp.abs(g_vel).max()) > 0.0 and float(jnp.abs(g_rows).max()) > 0.0


def test_skate_term_pays_for_lifting_a_moving_toe():
    # the soft contact has a gradient: raising a sliding toe lowers the term, and so does slowing it
    T = 8
    glide = np.zeros((1, T, 2, 3))
    glide[0, :, :, 2] = 0.04 * np.arange(T)[:, None]
    glide[0, :, 0, 1] = 0.01  # the left toe slightly up: the right one is the floor
    vel, rows = _toes_as_output(glide)
    g = jax.grad(lambda r: losses.foot_losses(vel, r, (1, 2), 0.02, 0.05)["skate"])(rows)
    g = np.asarray(g).reshape(1, T, 2, 3)
    assert np.all(g[0, 1:, 0, 1] < 0)  # up lowers it
    assert np.all(g[0, 1:-1, :, 2] == pytest.approx(0.0, abs=1e-6))  # a steady slide: inner steps cancel


def _gait_targets(**kw):
    from motiongan_jax.data.gait_stats import GaitTargets

    return GaitTargets(**{"stride_m_C": (1.0, 1.0), "speed_mps_C": (1.0, 2.0), "step_height_m_C": (0.05, 0.05),
                          "stride_speed_slope": 0.5,
                          "sample_hz": 10.0, "contact_height_m": 0.02, "toe_joints": (1, 2), **kw})


def test_stride_loss_by_hand():
    log_stride = jnp.log(jnp.array([1.0, 0.5, 2.0]))
    got = float(losses.stride_loss(log_stride, jnp.array([0, 1, 1]), _gait_targets()))
    assert got == pytest.approx((0.0 + math.log(2) ** 2 + math.log(2) ** 2) / 3, rel=1e-6)


def test_stride_loss_that_follows_speed_by_hand():
    """B x T strides against the data's relation at each sample's speed: style 0 (1 m at 1 m/s)
    at 4 m/s asks for 1 m x 4^0.5 = 2 m, style 1 (1 m at 2 m/s) at 0.5 m/s asks for 0.5 m; sample
    0 (not walked) is left out."""
    step_BxT = jnp.array([[0.0, 0.4, 0.4], [0.0, 0.05, 0.05]])  # m per sample at 10 Hz: 4 and 0.5 m/s
    exact = jnp.log(jnp.array([[9.0, 2.0, 2.0], [9.0, 0.5, 0.5]]))
    assert float(losses.stride_loss(exact, jnp.array([0, 1]), _gait_targets(), step_BxT)) == pytest.approx(0, abs=1e-12)
    off = exact.at[0, 2].add(0.3).at[1, 1].add(-0.1)
    got = float(losses.stride_loss(off, jnp.array([0, 1]), _gait_targets(), step_BxT))
    assert got == pytest.approx((0.3**2 + 0.1**2) / 4, rel=1e-5)


def test_step_height_loss_by_hand_and_against_gait_measure():
    """Two windows, toes 1 and 2 (kept-joint order, root 0) of pose rows: window 0 lifts its toes in
    turn by ±a (left − right = 2a·sin, standard deviation √2·a), window 1 keeps them level (0: the
    floor's 1 mm). Each against its style's target by hand, and the same measure as the protocol's
    gait.step_amplitude_m."""
    from motiongan_jax.motion import gait

    T, a = 32, 0.03
    s_T = np.sin(2 * np.pi * np.arange(T) / 16)  # two whole cycles: mean 0, mean square 1/2
    pose = np.zeros((2, T, 6), np.float32)
    pose[0, :, 1], pose[0, :, 4] = a * s_T, -a * s_T  # toe 1's y, toe 2's y
    vel = jnp.zeros((2, T, 3))
    std0 = np.sqrt(2) * a
    assert gait.step_amplitude_m(np.stack([pose[0, :, 1], pose[0, :, 4]], 1)) == pytest.approx(std0, rel=1e-5)
    targets = (0.05, 0.02)
    got = float(losses.step_height_loss(vel, jnp.asarray(pose), jnp.array([0, 1]), (1, 2), targets))
    want = ((0.5 * np.log(std0**2 + 1e-6) - np.log(0.05)) ** 2 + (0.5 * np.log(1e-6) - np.log(0.02)) ** 2) / 2
    assert got == pytest.approx(want, rel=1e-5)
    # on target: 0, whatever the root does (heights are differences of two toes)
    exact = float(losses.step_height_loss(jnp.ones((2, T, 3)), jnp.asarray(pose[:1]), jnp.array([0]), (1, 2),
                                          (np.sqrt(std0**2 + 1e-6),)))
    assert exact == pytest.approx(0.0, abs=1e-9)
    # a finite gradient where the toes never part (the square root is never taken at 0)
    g = jax.grad(lambda p: losses.step_height_loss(vel[1:], p, jnp.array([0]), (1, 2), (0.05,)))(jnp.asarray(pose[1:]))
    assert np.all(np.isfinite(np.asarray(g)))


def test_reconstruction_loss_by_hand_and_mask():
    B, T, R = 2, 4, 6
    vel, pose = jnp.zeros((B, T, 3)), jnp.zeros((B, T, R))
    real_pose = pose.at[0, 1, 2].set(0.9)  # one row off by 0.9 m in one sample
    valid = jnp.ones((B, T), bool)
    got = float(losses.reconstruction_loss(vel, pose, vel, real_pose, valid, unit=0.3))
    assert got == pytest.approx(0.9 / 0.3 / (3 + R) / (B * T), rel=1e-6)
    # samples without a measured phase do not count
    assert float(losses.reconstruction_loss(vel, pose, vel, real_pose, valid.at[0, 1].set(False), 0.3)) == 0.0
    assert float(losses.reconstruction_loss(vel, pose, vel, real_pose, jnp.zeros((B, T), bool), 0.3)) == 0.0


def test_root_jerk_excess_by_hand():
    # Real: constant velocity (no jerk). Fake: x velocity alternating +a, -a: its second
    # difference is ±4a at every one of the T - 2 inner samples, so E‖Δ²v‖² = 16 a².
    t, a, unit = 10, 0.3, 0.5
    real_BxTx3 = jnp.tile(jnp.array([0.1, 0.0, 0.2]), (2, t, 1))
    sign_T = jnp.where(jnp.arange(t) % 2 == 0, 1.0, -1.0)
    fake_BxTx3 = real_BxTx3.at[..., 0].add(a * sign_T)
    assert float(losses.root_jerk_excess(fake_BxTx3, real_BxTx3, unit)) == pytest.approx(16 * a**2 / unit**2, rel=1e-5)
    # Only the excess over the real batch is paid for: a fake as jerky as the real costs nothing,
    # and a smoother one gets no push toward more jerk.
    assert float(losses.root_jerk_excess(fake_BxTx3, fake_BxTx3)) == 0.0
    assert float(losses.root_jerk_excess(real_BxTx3, fake_BxTx3)) == 0.0
    g_BxTx3 = jax.grad(lambda f: losses.root_jerk_excess(f, fake_BxTx3))(real_BxTx3)
    np.testing.assert_array_equal(np.asarray(g_BxTx3), 0.0)
    # No gradient reaches the real windows.
    g_real = jax.grad(lambda r: losses.root_jerk_excess(fake_BxTx3, r))(real_BxTx3)
    np.testing.assert_array_equal(np.asarray(g_real), 0.0)
    # A gradient step lowers it (the fake is pushed toward smoothness).
    g = jax.grad(lambda f: losses.root_jerk_excess(f, real_BxTx3))(fake_BxTx3)
    smoother = fake_BxTx3 - 0.01 * g
    assert float(losses.root_jerk_excess(smoother, real_BxTx3)) < float(losses.root_jerk_excess(fake_BxTx3, real_BxTx3))


def test_world_joints_and_joint_jerk_excess_by_hand():
    # Two joints beside the root. The root moves at a constant velocity (v[0] is ignored); in the
    # fake, joint 1's x row alternates +a, -a about its rest row: its third difference is ±8a at each
    # of the T - 3 samples, so E‖Δ³x‖² = 64 a² for that joint and 0 for the others. (Binary
    # fractions throughout, so that the sums are exact and the other joints' jerk exactly 0.)
    b, t, a, unit = 2, 9, 0.0625, 0.5
    vel_BxTx3 = jnp.tile(jnp.array([0.125, 0.0, 0.25]), (b, t, 1)).at[:, 0].set(7.0)
    rest_R = jnp.array([0.0, 0.5, 0.0, 0.125, -0.875, 0.0])
    real_pose_BxTxR = jnp.tile(rest_R, (b, t, 1))
    sign_T = jnp.where(jnp.arange(t) % 2 == 0, 1.0, -1.0)
    fake_pose_BxTxR = real_pose_BxTxR.at[..., 0].add(a * sign_T)
    x_BxTxJx3 = losses.world_joints(vel_BxTx3, real_pose_BxTxR)
    chex.assert_shape(x_BxTxJx3, (b, t, 3, 3))
    root_T = 0.25 * jnp.arange(t)  # z of the root: 0.25 per sample from the origin
    np.testing.assert_allclose(np.asarray(x_BxTxJx3[0, :, 0, 2]), np.asarray(root_T), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(x_BxTxJx3[1, :, 2, 1]), -0.875, rtol=1e-6)  # root y 0 + row y
    got = float(losses.joint_jerk_excess(vel_BxTx3, fake_pose_BxTxR, vel_BxTx3, real_pose_BxTxR, unit))
    assert got == pytest.approx(64 * a**2 / unit**2, rel=1e-4)
    # Each joint is held to its own real counterpart: a real batch jerky in joint 2 does not excuse
    # the fake's jerk in joint 1, though pooled over joints the real one would be the jerkier.
    real_jerky_pose = real_pose_BxTxR.at[..., 3].add(2 * a * sign_T)
    got = float(losses.joint_jerk_excess(vel_BxTx3, fake_pose_BxTxR, vel_BxTx3, real_jerky_pose, unit))
    assert got == pytest.approx(64 * a**2 / unit**2, rel=1e-4)
    # only the excess counts, no gradient reaches the real batch, and a gradient step lowers it
    assert float(losses.joint_jerk_excess(vel_BxTx3, real_pose_BxTxR, vel_BxTx3, fake_pose_BxTxR)) == 0.0
    g_real = jax.grad(lambda p: losses.joint_jerk_excess(vel_BxTx3, fake_pose_BxTxR, vel_BxTx3, p))(real_pose_BxTxR)
    np.testing.assert_array_equal(np.asarray(g_real), 0.0)
    g = jax.grad(lambda p: losses.joint_jerk_excess(vel_BxTx3, p, vel_BxTx3, real_pose_BxTxR))(fake_pose_BxTxR)
    assert float(jnp.abs(g[..., 1:]).max()) == 0.0  # only the jerky joint's x row is pushed
    smoother = fake_pose_BxTxR - 0.01 * g
    assert (float(losses.joint_jerk_excess(vel_BxTx3, smoother, vel_BxTx3, real_pose_BxTxR))
            < float(losses.joint_jerk_excess(vel_BxTx3, fake_pose_BxTxR, vel_BxTx3, real_pose_BxTxR)))
    # the root is a joint too: a root shaking along x is paid for like any other joint
    shaky_vel = vel_BxTx3.at[..., 0].add(a * sign_T)  # Δ³ of the integrated root = Δ² of v = ±4a
    got = float(losses.joint_jerk_excess(shaky_vel, real_pose_BxTxR, vel_BxTx3, real_pose_BxTxR, unit))
    assert got == pytest.approx(3 * 16 * a**2 / unit**2, rel=1e-4)  # the root moves all three joints
