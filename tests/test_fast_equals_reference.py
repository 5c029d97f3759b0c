"""The speed rewrites (docs/PERFORMANCE.md) compute the same function as the straightforward forms.

Each rewrite is checked against the plain version it replaces, in float32, forward and backward:

* conv.conv2d(impl="fast") (padding trick, width-group folding, matrix-product weight gradient)
  against lax.conv_general_dilated: relative error <= 1e-5 of the largest value;
* the weight gradient in each of its layouts, chunked and not, against XLA's;
* the polyphase "upsample x2 then tconv" against upsample_time2 followed by the correlation;
* ConvTranspose.upsampled (skip computed on one column + polyphase) against the tconv of
  upsample_time2(concat[tile(e), d]);
* the written-out AdaIN backward against autodiff of the formula;
* G and D with impl="fast" against impl="xla", forward and backward, at one size each (relative error of outputs
  <= 1e-4, of each gradient leaf <= 2e-3 of its largest entry: G's 14 instance norms amplify
  float32 rounding at these tiny sizes; at T 128 both impls were ~4e-6 from a float64 G). The
  training step runs nothing else that depends on `impl`, so it is not compared again as a whole;
* bf16 compute against float32 (tolerances at the tests), and that G runs once per step.
"""

from __future__ import annotations

import functools

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import FAST, compiled_call
from flax import nnx

from motiongan_jax.config import Config, DataConfig, ModelConfig, TrainConfig, validate
from motiongan_jax.model import state as model_state
from motiongan_jax.nn import Discriminator, Generator, conv, layers
from motiongan_jax.train import step as step_lib


def _rel(a, b, scale=None) -> float:
    """max |a - b| relative to max |b| (or to `scale`)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    scale = np.max(np.abs(b)) if scale is None else scale
    return float(np.max(np.abs(a - b)) / max(scale, 1e-30))


def _xla(x, k, stride, padding):
    return jax.lax.conv_general_dilated(x, k, stride, padding, dimension_numbers=("NHWC", "HWIO", "NHWC"))


CONV_CASES = [  # (x shape, kernel shape, stride, padding)
    ((2, 12, 11, 6), (5, 3, 6, 4), (1, 1), ((0, 0), (0, 0))),  # G's 5x3 convs (pre-padded)
    ((2, 10, 4, 6), (5, 1, 6, 9), (1, 1), ((2, 2), (0, 0))),  # tconv as a zero-padded correlation
    ((2, 12, 9, 2), (5, 3, 2, 4), (2, 3), ((0, 0), (0, 0))),  # D's convs: folded width groups
    ((2, 12, 10, 2), (5, 3, 2, 4), (2, 3), ((0, 0), (0, 0))),  # ... with an unused last column
    ((2, 12, 7, 4), (5, 7, 4, 3), (1, 1), ((0, 0), (0, 0))),  # c_traj: kernel spans the width
    ((2, 13, 1, 4), (5, 1, 4, 6), (2, 1), ((0, 0), (0, 0))),  # encoder: stride 2 in time
    ((1, 9, 5, 3), (4, 1, 3, 5), (1, 1), ((0, 0), (0, 0))),  # polyphase kernels (4 taps)
]


@pytest.mark.parametrize("xs,ks,stride,padding", CONV_CASES)
def test_conv2d_fast_equals_lax_conv_forward_and_backward(xs, ks, stride, padding):
    x = jax.random.normal(jax.random.key(0), xs)
    k = jax.random.normal(jax.random.key(1), ks)
    y_ref, vjp_ref = jax.vjp(lambda a, b: _xla(a, b, stride, padding), x, k)
    y, vjp = jax.vjp(lambda a, b: conv.conv2d(a, b, stride, padding, impl="fast"), x, k)
    chex.assert_equal_shape([y, y_ref])
    assert _rel(y, y_ref) < 1e-5
    dy = jax.random.normal(jax.random.key(2), y.shape)
    for got, want in zip(vjp(dy), vjp_ref(dy)):
        assert _rel(got, want) < 1e-5
    y_xla = conv.conv2d(x, k, stride, padding, impl="xla")
    np.testing.assert_array_equal(np.asarray(y_xla), np.asarray(y_ref))


def test_valid_forward_padding_trick_is_exact():
    """A VALID conv run with one extra zero row of time padding (output row dropped) gives the
    same bits: the extra row only adds an output row."""
    x = jax.random.normal(jax.random.key(0), (2, 12, 11, 6))
    k = jax.random.normal(jax.random.key(1), (5, 3, 6, 8))
    assert 5 * 3 * 8 > conv._NARROW_OUTPUT  # (not the heads' output-side path)
    np.testing.assert_array_equal(np.asarray(conv._forward(x, k, (1, 1), ((0, 0), (0, 0)))),
                                  np.asarray(_xla(x, k, (1, 1), "VALID")))


@pytest.mark.parametrize("xs,ks,stride", [((3, 12, 11, 4), (5, 3, 4, 6), (1, 1)),
                                          ((2, 13, 8, 4), (5, 2, 4, 3), (1, 2)),
                                          ((2, 13, 7, 4), (5, 2, 4, 3), (2, 1)),
                                          ((3, 12, 9, 4), (5, 3, 4, 6), (2, 3))])
def test_weight_grad_every_layout_and_chunking(xs, ks, stride, monkeypatch):
    x = jax.random.normal(jax.random.key(0), xs)
    k = jax.random.normal(jax.random.key(1), ks)
    y, vjp = jax.vjp(lambda k_: _xla(x, k_, stride, "VALID"), k)
    dy = jax.random.normal(jax.random.key(2), y.shape)
    (want,) = vjp(dy)
    kt, kw = ks[:2]
    for tx in (True, False):
        for wx in (True, False):
            if (stride[0] > 1 and not tx) or (stride[1] > 1 and not wx):
                continue
            a, b = conv._weight_grad_matrices(x, dy, kt, kw, stride, (tx, wx))
            g = jax.lax.dot_general(a, b, (((0, 1, 2), (0, 1, 2)), ((), ())))
            got = conv._weight_grad_finish(g, kt, kw, ks[2], ks[3], (tx, wx))
            assert _rel(got, want) < 1e-5, (tx, wx)
    whole = conv.weight_grad(x, dy, kt, kw, stride)
    monkeypatch.setattr(conv, "_CHUNK_BYTES", 1)  # one sample per scan step
    chunked = conv.weight_grad(x, dy, kt, kw, stride)
    assert _rel(whole, want) < 1e-5 and _rel(chunked, want) < 1e-5


def _upsample_then_correlate(x, taps):
    kt = len(taps)
    k = jnp.stack(taps)[:, None]
    return _xla(layers.upsample_time2(x), k, (1, 1), ((kt - 1 - kt // 2, kt // 2), (0, 0)))


@pytest.mark.parametrize("kt", [3, 5, 7])
@pytest.mark.parametrize("t", [1, 2, 3, 8])
def test_polyphase_equals_upsample_then_correlate(kt, t):
    x = jax.random.normal(jax.random.key(0), (2, t, 3, 4))
    taps = list(jax.random.normal(jax.random.key(1), (kt, 4, 5)))
    got = layers.upsampled_tconv(x, taps)
    want = _upsample_then_correlate(x, taps)
    chex.assert_shape(got, (2, 2 * t, 3, 5))
    assert _rel(got, want) < 1e-5
    # and its gradients
    dy = jax.random.normal(jax.random.key(2), want.shape)
    g = jax.vjp(layers.upsampled_tconv, x, taps)[1](dy)
    g_ref = jax.vjp(_upsample_then_correlate, x, taps)[1](dy)
    # (with t = 1 the outer taps never meet data: their exact gradient is 0)
    scale = max(float(jnp.max(jnp.abs(leaf))) for leaf in jax.tree.leaves(g_ref))
    for a, b in zip(jax.tree.leaves(g), jax.tree.leaves(g_ref)):
        assert _rel(a, b, scale) < 1e-5


def test_phase_coefficients_by_hand():
    """kt = 5: even outputs read x[i-2..i+1], odd ones x[i-1..i+2] (derived in layers.py)."""
    A, lo, shift = layers._upsample_phase_coeffs(5)
    assert (lo, shift) == (-2, 1)
    np.testing.assert_allclose(A[0], [[0.25, 0, 0, 0, 0], [0.75, 0.75, 0.25, 0, 0],
                                      [0, 0.25, 0.75, 0.75, 0.25], [0, 0, 0, 0.25, 0.75]])
    np.testing.assert_allclose(A[1], [[0.75, 0.25, 0, 0, 0], [0.25, 0.75, 0.75, 0.25, 0],
                                      [0, 0, 0.25, 0.75, 0.75], [0, 0, 0, 0, 0.25]])
    assert A.sum() == 10.0  # each of the 5 taps reads two upsampled samples per phase


@pytest.mark.parametrize("with_skip", [True, False])
@pytest.mark.parametrize("min_rows", [0, 10 ** 9])  # polyphase, and the small-input path
def test_tconv_upsampled_equals_tile_concat_upsample(with_skip, min_rows, monkeypatch):
    monkeypatch.setattr(layers, "POLYPHASE_MIN_ROWS", min_rows)
    ce, cd, cout = (3, 4, 2) if with_skip else (0, 4, 2)
    tc = layers.ConvTranspose(ce + cd, cout, (5, 3), rngs=nnx.Rngs(0))
    tc.bias.set_value(jnp.array([0.5, -1.0]))
    d = jax.random.normal(jax.random.key(1), (2, 6, 9, cd))
    e = jax.random.normal(jax.random.key(2), (2, 6, 1, ce)) if with_skip else None

    def plain(d, e):
        x = d if e is None else jnp.concatenate([jnp.broadcast_to(e, (*e.shape[:2], d.shape[2], ce)), d], -1)
        return tc(layers.upsample_time2(x))

    got, want = tc.upsampled(d, e), plain(d, e)
    chex.assert_shape(got, (2, 12, 27, cout))
    assert _rel(got, want) < 1e-5
    dy = jax.random.normal(jax.random.key(3), want.shape)
    for a, b in zip(jax.vjp(tc.upsampled, d, e)[1](dy), jax.vjp(plain, d, e)[1](dy)):
        if a is not None:
            assert _rel(a, b) < 1e-5


def test_modulated_instance_norm_equals_formula_and_its_autodiff():
    h = 3.0 + jax.random.normal(jax.random.key(0), (2, 7, 5, 4))
    s = jax.random.normal(jax.random.key(1), (2, 4))
    b = jax.random.normal(jax.random.key(2), (2, 4))

    def formula(h, s, b):
        return layers.instance_norm(h) * s[:, None, None, :] + b[:, None, None, :]

    y, vjp = jax.vjp(layers.modulated_instance_norm, h, s, b)
    y_ref, vjp_ref = jax.vjp(formula, h, s, b)
    np.testing.assert_array_equal(np.asarray(y), np.asarray(y_ref))
    dy = jax.random.normal(jax.random.key(3), y.shape)
    for got, want in zip(vjp(dy), vjp_ref(dy)):
        assert _rel(got, want) < 1e-5


# ---------------------------------------------------------------------------------------------
# Whole networks and the training step


def _pair(build):
    return [build(impl) for impl in ("fast", "xla")]


def _leaf_rel(a_tree, b_tree) -> float:
    return max(_rel(a, b) for a, b in zip(jax.tree.leaves(a_tree), jax.tree.leaves(b_tree)))


def test_generator_fast_equals_straightforward():
    """At one size: the layouts each layer meets are the op-level tests' above."""
    num_joints, T = 20, 32
    fast, plain = _pair(lambda impl: Generator(num_joints, base_channels=8, w_dim=16, z_dim=16, num_styles=3, impl=impl,
                                               rngs=nnx.Rngs(0)))
    vel = 0.1 * jax.random.normal(jax.random.key(1), (2, T, 3))
    labels, z = jnp.array([0, 2]), jax.random.normal(jax.random.key(2), (2, 16))

    def run(g):
        """G's outputs and the parameter gradient for one random cotangent, as one compiled program
        (the fast optimiser level: it changes compile time, not what is computed)."""
        graphdef, params = nnx.split(g, nnx.Param)

        def f(params):
            m = nnx.merge(graphdef, params)
            return m(vel, m.style(labels, z))

        def fwd_bwd(params, cot):
            out, vjp = jax.vjp(f, params)
            return out, vjp(cot)[0]

        cot = jax.tree.map(lambda o: jax.random.normal(jax.random.key(3), o.shape), jax.eval_shape(f, params))
        return jax.jit(fwd_bwd).lower(params, cot).compile(compiler_options=FAST)(params, cot)

    (out_f, g_f), (out_p, g_p) = run(fast), run(plain)
    for a, b in zip(out_f, out_p):
        assert _rel(a, b) < 1e-4
    assert _leaf_rel(g_f, g_p) < 2e-3


def test_discriminator_fast_equals_straightforward():
    fast, plain = _pair(lambda impl: Discriminator(20, num_styles=4, seq_len=16, base_channels=8, impl=impl,
                                                   rngs=nnx.Rngs(0)))
    root = jax.random.normal(jax.random.key(1), (2, 16, 3))
    pose = jax.random.normal(jax.random.key(2), (2, 16, 60))
    cot = (jnp.ones(2), jnp.ones((2, 4)))

    def run(d):
        """D's outputs and the gradient for `cot` of its parameters and inputs, compiled as G's are."""
        graphdef, params, rest = nnx.split(d, nnx.Param, ...)

        def f(params, root, pose):
            m = nnx.merge(graphdef, params, rest, copy=True)
            return m(root, pose, update_stats=True)

        def fwd_bwd(params, root, pose):
            out, vjp = jax.vjp(f, params, root, pose)
            return out, vjp(cot)

        return jax.jit(fwd_bwd).lower(params, root, pose).compile(compiler_options=FAST)(params, root, pose)

    (out_f, g_f), (out_p, g_p) = run(fast), run(plain)
    for a, b in zip(out_f, out_p):
        assert _rel(a, b) < 1e-5
    assert _leaf_rel(g_f, g_p) < 1e-4


def _curvy_batch(B, T, R, key):
    """Curved, noisy input curves. (A noise-free straight line at constant speed makes G's
    encoder features constant in time, so its instance norms divide rounding noise by
    sqrt(1e-8): any two summation orders then disagree wildly, in the reference too.)"""
    k1, k2, k3 = jax.random.split(key, 3)
    t = jnp.arange(T, dtype=jnp.float32)[None, :, None]
    curve = (0.05 * t * jnp.array([[[1.0, 0.0, 0.3]], [[0.2, 0.0, -1.0]]])[:B]
             + jnp.sin(0.2 * t) * jnp.array([0.3, 0.0, 0.1])
             + 0.01 * jax.random.normal(k1, (B, T, 3)) * jnp.array([1.0, 0.0, 1.0]))
    root = curve + jnp.array([0.0, 0.9, 0.0]) + 0.01 * jax.random.normal(k2, (B, T, 3))
    return {"root_BxTx3": root, "pose_BxTxR": 0.3 * jax.random.normal(k3, (B, T, R)),
            "curve_BxTx3": curve, "label_B": jnp.array([1, 3], jnp.int32)[:B]}


STEP_T = 32
STEP_CFG = validate(Config(data=DataConfig(frame_nums=STEP_T, frame_step=1), model=ModelConfig(base_channels=8),
                           train=TrainConfig(batch_size=2)))


@functools.lru_cache(maxsize=None)
def _one_step(impl: str, dtype: str):
    """(new state, metrics) of one train step at a small config from fixed inputs; each
    (impl, dtype) compiled once per process."""
    from test_step import LAYOUT, C  # the step tests' skeleton stand-in (27 joints)

    batch, key = _curvy_batch(2, STEP_T, LAYOUT.num_rows, jax.random.key(42)), jax.random.key(7)
    state = model_state.init_state(STEP_CFG, LAYOUT, C, jax.random.key(0), impl=impl, dtype=dtype)
    step = jax.jit(step_lib.make_train_step(STEP_CFG, LAYOUT, C)).lower(state, batch, key).compile(
        compiler_options=FAST)
    return step(state, batch, key)


# ---------------------------------------------------------------------------------------------
# bf16 compute (mixed precision: float32 parameters, statistics and optimizer state)


def _rms_rel(a, b) -> float:
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return float(np.sqrt(np.mean((a - b) ** 2) / np.mean(b ** 2)))


def test_bf16_layers_close_to_float32():
    """One layer at a time, bf16 activations and kernels (float32 accumulation) against float32:
    relative RMS error <= 1e-2 (bf16 keeps 8 significant bits, ~4e-3)."""
    x = jax.random.normal(jax.random.key(0), (2, 16, 9, 32))
    conv_ = layers.Conv(32, 16, (5, 3), pad_w=1, rngs=nnx.Rngs(1))
    tconv = layers.ConvTranspose(64, 16, (5, 3), rngs=nnx.Rngs(2))
    e = jax.random.normal(jax.random.key(3), (2, 16, 1, 32))
    s, b = jax.random.normal(jax.random.key(4), (2, 32)), jax.random.normal(jax.random.key(5), (2, 32))
    for f in (conv_, lambda v: tconv.upsampled(v, e.astype(v.dtype)),
              lambda v: layers.modulated_instance_norm(v, s, b)):
        y32, y16 = f(x), f(x.astype(jnp.bfloat16))
        assert y16.dtype == jnp.bfloat16
        assert _rms_rel(y16, y32) < 1e-2


def test_bf16_generator_tracks_float32():
    """G at initialisation amplifies small relative changes ~30x (14 instance norms on random
    weights): merely rounding its float32 input to bf16 moves the outputs by 3% RMS here. bf16
    compute throughout may move them by at most 4x that (measured 2.5x: 7.6% vs 3.0%)."""
    g32, g16 = (Generator(27, base_channels=8, w_dim=16, z_dim=16, num_styles=3, compute_dtype=d, rngs=nnx.Rngs(0))
                for d in ("float32", "bfloat16"))
    vel = 0.1 * jax.random.normal(jax.random.key(1), (2, 64, 3))
    w = g32.style(jnp.array([0, 1]), jax.random.normal(jax.random.key(2), (2, 16)))
    out32, out16 = compiled_call(g32, vel, w), compiled_call(g16, vel, w)
    rounded = compiled_call(g32, vel.astype(jnp.bfloat16).astype(jnp.float32), w)
    for a, b, r in zip(out16, out32, rounded):
        assert a.dtype == jnp.float32
        assert _rms_rel(a, b) < min(0.3, 4 * _rms_rel(r, b))


def test_bf16_train_step_keeps_float32_state():
    metrics = {}
    for dtype in ("bfloat16", "float32"):
        new, metrics[dtype] = _one_step("fast", dtype)
        leaves = jax.tree.leaves((new.g_params, new.d_params, new.opt_g_state, new.opt_d_state, new.d_sn_state))
        assert {leaf.dtype for leaf in leaves if jnp.issubdtype(leaf.dtype, jnp.floating)} == {jnp.dtype(jnp.float32)}
        chex.assert_tree_all_finite(new)
    for name in ("d_adv", "d_cls", "g_adv", "g_cls", "g_curve", "g_bone"):
        a, b = float(metrics["bfloat16"][name]), float(metrics["float32"][name])
        assert abs(a - b) <= 0.05 * abs(b), (name, a, b)


def test_step_runs_g_once_and_d_three_times(monkeypatch):
    """DESIGN.md §4.2: one G forward serves both updates (its VJP is kept, G is not re-run for the G
    update) and D runs three times (fake and real for D, fake for G). Counted while tracing."""
    from test_step import CFG, LAYOUT, C, _batch

    calls = {"G": 0, "D": 0}
    g_call, d_call = Generator.network, Discriminator.__call__

    def counting_g(self, *a, **k):  # the paper's network, which the walker's forward also runs once
        calls["G"] += 1
        return g_call(self, *a, **k)

    def counting_d(self, *a, **k):
        calls["D"] += 1
        return d_call(self, *a, **k)

    monkeypatch.setattr(Generator, "network", counting_g)
    monkeypatch.setattr(Discriminator, "__call__", counting_d)
    state = jax.eval_shape(lambda: model_state.init_state(CFG, LAYOUT, C, jax.random.key(0)))
    jax.eval_shape(step_lib.make_train_step(CFG, LAYOUT, C), state, _batch(), jax.random.key(1))
    assert calls == {"G": 1, "D": 3}
