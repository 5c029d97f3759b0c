"""Networks: building blocks against hand/numpy references, shapes, parameter counts."""

from __future__ import annotations

import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import compiled, compiled_call
from flax import nnx

from motiongan_jax.nn import (
    Discriminator,
    Generator,
    SpectralNormState,
    count_params,
    init_split,
    layers,
)
from motiongan_jax.nn.discriminator import flatten_channel_major

TOP, T, B, C = 8, 16, 2, 4


def _build_g(num_joints, key):
    return Generator(num_joints, base_channels=TOP, time_kernel=5, w_dim=64, z_dim=64, num_styles=C, rngs=nnx.Rngs(key))


def _build_d(num_joints, key):
    return Discriminator(num_joints, num_styles=C, seq_len=T, base_channels=TOP, time_kernel=5, rngs=nnx.Rngs(key))


@pytest.fixture(scope="module")
def gen27():
    g_def, params = init_split(_build_g, (27,), jax.random.key(0), nnx.Param)

    def run(params, vel, labels, z):
        g = nnx.merge(g_def, params)
        w = g.style(labels, z)
        return g(vel, w), w

    vel16 = jax.random.normal(jax.random.key(1), (B, T, 3))
    labels = jnp.array([0, 1], jnp.int32)
    z = jax.random.normal(jax.random.key(2), (B, 64))
    return dict(params=params, fn16=compiled(run, params, vel16, labels, z), vel16=vel16, z=z, run=run)


# ---------------------------------------------------------------------------------------------
# Stateless ops


def test_reflect_pad_matches_numpy():
    x = np.arange(2 * 6 * 3 * 2, dtype=np.float32).reshape(2, 6, 3, 2)
    got = layers.reflect_pad(jnp.asarray(x), 2, 1)
    want = np.pad(x, ((0, 0), (2, 2), (1, 1), (0, 0)), mode="reflect")
    np.testing.assert_array_equal(np.asarray(got), want)


def test_upsample_hand_example_and_resize():
    x = jnp.array([0.0, 1.0, 2.0, 4.0]).reshape(1, 4, 1, 1)
    got = layers.upsample_time2(x).reshape(-1)
    # PyTorch bilinear (2, 1), align_corners=False: 3/4 own sample + 1/4 neighbour, edges clamped
    np.testing.assert_allclose(np.asarray(got), [0, 0.25, 0.75, 1.25, 1.75, 2.5, 3.5, 4.0], atol=1e-7)
    y = jax.random.normal(jax.random.key(0), (2, 6, 3, 4))
    ref = jax.image.resize(y, (2, 12, 3, 4), method="linear")
    np.testing.assert_allclose(np.asarray(layers.upsample_time2(y)), np.asarray(ref), atol=1e-6)


def test_pixel_norm_hand():
    got = layers.pixel_norm(jnp.array([[3.0, 4.0]]))
    # mean of squares 12.5
    np.testing.assert_allclose(np.asarray(got), [[3 / math.sqrt(12.5), 4 / math.sqrt(12.5)]], rtol=1e-6)


def test_adain_hand():
    ada = layers.AdaIN(1, 1, rngs=nnx.Rngs(0))
    ada.scale.kernel.set_value(jnp.array([[2.0]]))
    ada.scale.bias.set_value(jnp.array([0.5]))
    ada.shift.kernel.set_value(jnp.array([[-1.0]]))
    ada.shift.bias.set_value(jnp.array([0.25]))
    h = jnp.array([[0.0, 2.0], [4.0, 6.0]]).reshape(1, 2, 2, 1)  # T = 2, W = 2
    out = ada(h, jnp.array([[1.0]]))
    # normalised over T and W together: mean 3, biased var 5; s = 2.5 (not 1 + s), b = -0.75
    want = 2.5 * np.array([-3.0, -1.0, 1.0, 3.0]) / math.sqrt(5.0) - 0.75
    np.testing.assert_allclose(np.asarray(out).reshape(-1), want, rtol=1e-6)


def test_adain_init_ranges():
    ada = layers.AdaIN(512, 64, rngs=nnx.Rngs(0))
    for p in (ada.scale.kernel, ada.scale.bias):
        v = np.asarray(p[...])
        assert np.abs(v).max() <= 1 / 8 and np.abs(v).max() > 0.12  # U(-1/8, 1/8)
    np.testing.assert_array_equal(np.asarray(ada.shift.bias[...]), 0.0)
    assert abs(float(jnp.std(ada.shift.kernel[...])) - 0.02) < 2e-3


# ---------------------------------------------------------------------------------------------
# Convolutions against explicit loops (PyTorch definitions)


def _torch_conv_ref(x_nhwc, w_torch, stride):
    """Cross-correlation, weight (out, in, kt, kw), no padding."""
    b, t, w, cin = x_nhwc.shape
    cout, _, kt, kw = w_torch.shape
    to, wo = (t - kt) // stride[0] + 1, (w - kw) // stride[1] + 1
    y = np.zeros((b, to, wo, cout))
    for i in range(to):
        for j in range(wo):
            patch = x_nhwc[:, i * stride[0]: i * stride[0] + kt, j * stride[1]: j * stride[1] + kw, :]
            y[:, i, j] = np.einsum("bhwc,ochw->bo", patch, w_torch)
    return y


def test_conv_reflect_stride_matches_loop():
    conv = layers.Conv(2, 3, (5, 3), (2, 3), rngs=nnx.Rngs(0))
    conv.bias.set_value(jnp.array([0.1, -0.2, 0.3]))
    x = np.asarray(jax.random.normal(jax.random.key(1), (2, 8, 9, 2)))
    w_torch = np.asarray(conv.kernel[...]).transpose(3, 2, 0, 1)
    want = _torch_conv_ref(np.pad(x, ((0, 0), (2, 2), (0, 0), (0, 0)), mode="reflect"), w_torch, (2, 3))
    want += np.array([0.1, -0.2, 0.3])
    got = conv(jnp.asarray(x))
    chex.assert_shape(got, (2, 4, 3, 3))
    np.testing.assert_allclose(np.asarray(got), want, atol=1e-5)


def test_tconv_matches_loop_and_conv_transpose():
    tconv = layers.ConvTranspose(3, 2, (5, 3), rngs=nnx.Rngs(0))
    tconv.bias.set_value(jnp.array([0.5, -1.0]))
    x = np.asarray(jax.random.normal(jax.random.key(1), (2, 6, 2, 3)))
    w_torch = np.asarray(tconv.kernel[...]).transpose(2, 3, 0, 1)  # (in, out, kt, kw)
    b, t, w, _ = x.shape
    full = np.zeros((b, t + 4, 3 * w, 2))  # ConvTranspose2d, stride (1, 3), no padding
    for ti in range(t):
        for wi in range(w):
            for dt in range(5):
                for a in range(3):
                    full[:, ti + dt, 3 * wi + a] += x[:, ti, wi] @ w_torch[:, :, dt, a]
    want = full[:, 2:-2] + np.array([0.5, -1.0])
    got = tconv(jnp.asarray(x))
    chex.assert_shape(got, (2, 6, 6, 2))
    np.testing.assert_allclose(np.asarray(got), want, atol=1e-5)
    # the same layer as lax.conv_transpose of the PyTorch weight, cropped (DESIGN.md §3.1)
    ref = jax.lax.conv_transpose(jnp.asarray(x), jnp.asarray(w_torch.transpose(2, 3, 1, 0)), (1, 3),
                                 "VALID", dimension_numbers=("NHWC", "HWIO", "NHWC"),
                                 transpose_kernel=True)[:, 2:-2] + jnp.array([0.5, -1.0])
    np.testing.assert_allclose(np.asarray(got), np.asarray(ref), atol=1e-5)


# ---------------------------------------------------------------------------------------------
# Spectral norm


def _sn_conv_with_spectrum():
    """An SN conv whose (out, in·kt·kw) torch-order matrix has singular values 3, 1.5, 1, 0.5."""
    conv = layers.Conv(2, 4, (5, 3), (2, 3), spectral_norm=True, rngs=nnx.Rngs(3))
    rng = np.random.default_rng(0)
    u, _ = np.linalg.qr(rng.normal(size=(4, 4)))
    v, _ = np.linalg.qr(rng.normal(size=(30, 4)))
    w_mat = (u * np.array([3.0, 1.5, 1.0, 0.5])) @ v.T
    conv.kernel.set_value(jnp.asarray(w_mat.reshape(4, 2, 5, 3).transpose(2, 3, 1, 0), jnp.float32))
    return conv, w_mat, u[:, 0], v[:, 0]


def test_spectral_norm_converges_to_largest_singular_value():
    conv, w_mat, u1, v1 = _sn_conv_with_spectrum()
    kernel0 = np.asarray(conv.kernel[...]).copy()
    x = jnp.ones((1, 8, 9, 2))
    for _ in range(50):
        conv(x, update_stats=True)
    sigma_svd = float(jnp.linalg.svd(jnp.asarray(w_mat), compute_uv=False)[0])
    np.testing.assert_allclose(sigma_svd, 3.0, rtol=1e-6)
    w_eff = np.asarray(conv.weight())
    np.testing.assert_allclose(w_eff, kernel0 / sigma_svd, rtol=1e-5, atol=1e-7)
    np.testing.assert_array_equal(np.asarray(conv.kernel[...]), kernel0)  # raw weight untouched
    # v lives in PyTorch's (in, kt, kw) order: it matches the top right singular vector
    assert abs(abs(float(np.dot(np.asarray(conv.sn.v[...]), v1))) - 1) < 1e-5
    assert abs(abs(float(np.dot(np.asarray(conv.sn.u[...]), u1))) - 1) < 1e-5


def test_spectral_norm_iterates_once_per_update_call():
    conv, w_mat, _, _ = _sn_conv_with_spectrum()
    u0, v0 = np.asarray(conv.sn.u[...]), np.asarray(conv.sn.v[...])
    x = jnp.ones((1, 8, 9, 2))
    y_eval = conv(x, update_stats=False)
    np.testing.assert_array_equal(np.asarray(conv.sn.u[...]), u0)
    np.testing.assert_array_equal(np.asarray(conv.sn.v[...]), v0)
    v1 = w_mat.T @ u0
    v1 /= np.linalg.norm(v1)
    u1 = w_mat @ v1
    u1 /= np.linalg.norm(u1)
    y_train = conv(x, update_stats=True)
    np.testing.assert_allclose(np.asarray(conv.sn.v[...]), v1, atol=1e-6)
    np.testing.assert_allclose(np.asarray(conv.sn.u[...]), u1, atol=1e-6)
    assert not np.allclose(np.asarray(y_eval), np.asarray(y_train))


def test_spectral_norm_no_gradient_into_u_v():
    conv, _, _, _ = _sn_conv_with_spectrum()
    graphdef, params, sn = nnx.split(conv, nnx.Param, SpectralNormState)
    x = jax.random.normal(jax.random.key(0), (1, 8, 9, 2))

    def f(params, sn):
        m = nnx.merge(graphdef, params, sn, copy=True)
        return jnp.sum(m(x, update_stats=True) ** 2)

    g_params, g_sn = jax.grad(f, argnums=(0, 1))(params, sn)
    for leaf in jax.tree_util.tree_leaves(g_sn):
        np.testing.assert_array_equal(np.asarray(leaf), 0.0)
    assert float(jnp.abs(g_params["kernel"][...]).sum()) > 0
    # dσ/dM = u vᵀ for the weight matrix M, as in PyTorch (u, v are constants)
    w = jnp.asarray(np.random.default_rng(1).normal(size=(4, 30)), jnp.float32)
    sn_mod = conv.sn
    grad_w = jax.grad(lambda w: sn_mod(w, update_stats=False))(w)
    np.testing.assert_allclose(np.asarray(grad_w), np.outer(sn_mod.u[...], sn_mod.v[...]), atol=1e-6)


# ---------------------------------------------------------------------------------------------
# Networks


def test_flatten_is_channel_major():
    x = (100 * jnp.arange(3)[None, None, None, :] + jnp.arange(4)[None, :, None, None]).astype(jnp.float32)
    x = jnp.broadcast_to(x, (2, 4, 1, 3))
    flat = flatten_channel_major(x)
    np.testing.assert_array_equal(np.asarray(flat[0]), [0, 1, 2, 3, 100, 101, 102, 103, 200, 201, 202, 203])


@pytest.mark.parametrize("num_styles,g_count,d_count",
                         [(28, 16_156_164, 2_702_173), (29, 16_156_228, 2_706_270)])
def test_parameter_counts_paper_shapes(num_styles, g_count, d_count):
    g = nnx.eval_shape(lambda: Generator(27, base_channels=64, time_kernel=5, w_dim=64, z_dim=64, num_styles=num_styles,
                                         rngs=nnx.Rngs(0)))
    d = nnx.eval_shape(lambda: Discriminator(27, num_styles=num_styles, seq_len=128, base_channels=64, time_kernel=5,
                                             rngs=nnx.Rngs(0)))
    assert count_params(g) == g_count
    assert count_params(d) == d_count
    assert count_params(g.latent) == 64 * num_styles + 128 * 64 + 64 + 4 * (64 * 64 + 64)
    assert sum(count_params(getattr(g, n).adain) for n in Generator.BLOCKS) == 482_560
    # spectral-norm vectors are state, not parameters: one (u, v) pair per D layer
    assert len(jax.tree_util.tree_leaves(nnx.state(d, SpectralNormState))) == 12


def test_generator_shapes_and_full_convolution(gen27):
    (root, pose), w = gen27["fn16"](gen27["params"], gen27["vel16"], jnp.array([0, 1]), gen27["z"])
    chex.assert_shape(root, (B, T, 3))
    chex.assert_shape(pose, (B, T, 81))
    chex.assert_shape(w, (B, 64))
    chex.assert_tree_all_finite((root, pose))
    vel32 = jax.random.normal(jax.random.key(5), (B, 32, 3))
    (root32, pose32), _ = compiled(gen27["run"], gen27["params"], vel32, jnp.array([0, 1]), gen27["z"])(
        gen27["params"], vel32, jnp.array([0, 1]), gen27["z"])
    chex.assert_shape(root32, (B, 32, 3))
    chex.assert_shape(pose32, (B, 32, 81))
    chex.assert_tree_all_finite((root32, pose32))


def test_style_label_changes_output_at_init(gen27):
    fn, params, vel, z = gen27["fn16"], gen27["params"], gen27["vel16"], gen27["z"]
    (r0, p0), w0 = fn(params, vel, jnp.array([0, 0]), z)
    (r1, p1), w1 = fn(params, vel, jnp.array([1, 1]), z)
    # The faithful init keeps w tiny (|w| ~ 1e-5, DESIGN.md §3.3) ...
    assert 1e-7 < float(jnp.mean(jnp.abs(w0))) < 1e-4
    # ... yet the label still moves the pose by a few percent (~4e-2 measured), 1e5 x float32
    # rounding: the 14 AdaINs compound it.
    rel = float(jnp.linalg.norm(p1 - p0) / jnp.linalg.norm(p0))
    assert rel > 1e-3, rel
    assert float(jnp.linalg.norm(r1 - r0)) > 0


def test_generator_and_discriminator_20_joints():
    g_def, g_params = init_split(_build_g, (20,), jax.random.key(0), nnx.Param)
    d_def, d_params, d_sn = init_split(_build_d, (20,), jax.random.key(1), nnx.Param, SpectralNormState)

    def run(g_params, d_params, d_sn, vel, labels, z):
        g = nnx.merge(g_def, g_params)
        root, pose = g(vel, g.style(labels, z))
        d = nnx.merge(d_def, d_params, d_sn, copy=True)
        adv, cls = d(root, pose, update_stats=True)
        feats = d.features(root, pose)
        return root, pose, adv, cls, feats, d._input(root, pose), nnx.state(d, SpectralNormState)

    args = (g_params, d_params, d_sn, jax.random.normal(jax.random.key(2), (B, T, 3)),
            jnp.array([0, 3]), jnp.zeros((B, 64)))
    root, pose, adv, cls, feats, d_in, sn_after = compiled(run, *args)(*args)
    chex.assert_shape(root, (B, T, 3))
    chex.assert_shape(pose, (B, T, 60))
    chex.assert_shape(adv, (B,))
    chex.assert_shape(cls, (B, C))
    chex.assert_shape(feats, (B, T // 4, 9, 2 * TOP))
    chex.assert_tree_all_finite((root, pose, adv, cls, feats))
    # rows 60..80 of both channels are zero padding; channel 0 tiles the root velocity per joint
    chex.assert_shape(d_in, (B, T, 81, 2))
    np.testing.assert_array_equal(np.asarray(d_in[:, :, 60:]), 0.0)
    np.testing.assert_array_equal(np.asarray(d_in[:, :, 57:60, 0]), np.asarray(root))
    np.testing.assert_array_equal(np.asarray(d_in[:, :, :60, 1]), np.asarray(pose))
    # the state passed in is not mutated by the call
    assert not np.allclose(np.asarray(sn_after["c0_0"]["sn"]["u"][...]), np.asarray(d_sn["c0_0"]["sn"]["u"][...]))
    # c_traj's kernel spans the 3J rows
    assert g_params["c_traj"]["kernel"].shape == (5, 60, TOP, 3)


def test_discriminator_rejects_other_lengths():
    d = nnx.eval_shape(lambda: _build_d(27, jax.random.key(0)))
    with pytest.raises(ValueError, match="T=16"):
        d._input(jnp.zeros((1, 32, 3)), jnp.zeros((1, 32, 81)))
    with pytest.raises(ValueError, match="num_rel_joints"):
        Generator(28, base_channels=4, num_styles=2, rngs=nnx.Rngs(0))


def test_latent_transform_pixel_norm_is_scale_invariant(gen27):
    g = nnx.merge(nnx.split(nnx.eval_shape(lambda: _build_g(27, jax.random.key(0))), nnx.Param)[0],
                  gen27["params"])
    e = g.latent.embedding(jnp.array([0, 2]))
    z = gen27["z"]
    w = jax.jit(g.latent.from_embedding)(e, z)
    w_scaled = jax.jit(g.latent.from_embedding)(3.0 * e, 3.0 * z)
    np.testing.assert_allclose(np.asarray(w), np.asarray(w_scaled), rtol=1e-4, atol=1e-12)
    chex.assert_shape(g.latent.embed[...], (C, 64))


def test_latent_init_sets_the_scale_of_w():
    from motiongan_jax.nn.latent import LatentTransform

    labels, z = jnp.arange(4) % 3, jax.random.normal(jax.random.key(1), (4, 16))
    paper = LatentTransform(3, z_dim=16, w_dim=16, rngs=nnx.Rngs(0))(labels, z)
    torch = LatentTransform(3, z_dim=16, w_dim=16, init="torch_default", rngs=nnx.Rngs(0))(labels, z)
    rms = lambda w: float(jnp.sqrt(jnp.mean(w ** 2)))  # noqa: E731
    assert rms(paper) < 1e-3 < 1e-2 < rms(torch)
    with pytest.raises(ValueError, match="latent init"):
        LatentTransform(3, z_dim=16, w_dim=16, init="bogus", rngs=nnx.Rngs(0))


def test_networks_take_metres_and_work_in_their_length_unit():
    """G(length_unit=u) on metres equals G(length_unit=1) on lengths in u, scaled back by u."""
    u = 0.056444
    g1 = Generator(27, base_channels=4, w_dim=8, z_dim=8, num_styles=3, rngs=nnx.Rngs(0))
    gu = Generator(27, base_channels=4, w_dim=8, z_dim=8, num_styles=3, length_unit=u, rngs=nnx.Rngs(0))
    vel = 0.05 * jax.random.normal(jax.random.key(2), (2, 16, 3))
    w = g1.style(jnp.array([0, 1]), jnp.zeros((2, 8)))
    r1, p1 = compiled_call(g1, vel / u, w)
    ru, pu = compiled_call(gu, vel, w)
    np.testing.assert_allclose(ru, r1 * u, rtol=1e-5, atol=1e-9)
    np.testing.assert_allclose(pu, p1 * u, rtol=1e-5, atol=1e-9)
    d1 = Discriminator(27, num_styles=3, seq_len=16, base_channels=4, rngs=nnx.Rngs(1))
    du = Discriminator(27, num_styles=3, seq_len=16, base_channels=4, length_unit=u, rngs=nnx.Rngs(1))
    a1, c1 = compiled_call(d1, r1, p1, update_stats=False)
    au, cu = compiled_call(du, ru, pu, update_stats=False)
    np.testing.assert_allclose(au, a1, rtol=1e-4, atol=1e-6)
    np.testing.assert_allclose(cu, c1, rtol=1e-4, atol=1e-6)
