"""Data-parallel training over 4 CPU devices equals the single-device step on the same batch."""

import os
import subprocess
import sys
import textwrap

SCRIPT = textwrap.dedent("""
    import jax, jax.numpy as jnp, numpy as np
    from motiongan_jax.train import parallel, step as step_lib
    from motiongan_jax.model import state as model_state
    from motiongan_jax.config import load_config, override
    from motiongan_jax.motion.representation import layout_from_parents

    assert jax.device_count() == 4, jax.devices()
    cfg = override(load_config({repo!r} + "/configs/tiny.py"), ["train.batch_size=8"])
    J = 5
    layout = layout_from_parents(tuple("abcde"), (-1, 0, 1, 0, 3), np.ones(J - 1) * 0.3)
    k = jax.random.split(jax.random.key(0), 4)
    T = cfg.data.window_T
    root = jnp.cumsum(0.05 + 0.01 * jax.random.normal(k[0], (8, T, 3)), axis=1)
    batch = {{"root_BxTx3": root, "pose_BxTxR": 0.3 * jax.random.normal(k[1], (8, T, 3 * (J - 1))),
             "curve_BxTx3": root.at[..., 1].set(0.0), "label_B": jax.random.randint(k[2], (8,), 0, 3)}}
    fn = step_lib.make_train_step(cfg, layout, 3)
    single = model_state.init_state(cfg, layout, 3, jax.random.key(1))
    mesh = parallel.data_mesh()
    sharded = parallel.put_state(model_state.init_state(cfg, layout, 3, jax.random.key(1)), mesh)
    one, many = jax.jit(fn), parallel.shard_step(fn, mesh, 8)
    sb = parallel.global_batch(batch, mesh)
    assert len(sb["pose_BxTxR"].sharding.device_set) == 4
    rel = 0.0
    for s in range(1):
        single, m1 = one(single, batch, jax.random.fold_in(k[3], s))
        sharded, m4 = many(sharded, sb, jax.random.fold_in(k[3], s))
        for name in ("d_total", "g_total", "g_adv", "g_cls", "g_curve", "g_bone", "d_cls"):
            rel = max(rel, abs(float(m1[name]) - float(m4[name])) / (abs(float(m1[name])) + 1e-6))
    # One step from the same state. Adam's first update is lr * sign(g) (up to eps), so a parameter
    # whose gradient is ~0 (a conv bias right before an instance norm) moves by +-lr in a direction
    # set by rounding: bound every difference by 2 lr, and require almost all parameters to agree.
    # (Over several steps such rounding-level differences grow: this GAN is chaotic in them.)
    bound = 2 * max(cfg.train.lr_g, cfg.train.lr_d) + 1e-6
    worst, loose, total = 0.0, 0, 0
    for a, b in zip(jax.tree.leaves((single.g_params, single.d_params)),
                    jax.tree.leaves((sharded.g_params, sharded.d_params))):
        d = np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))
        worst, loose, total = max(worst, float(d.max())), loose + int((d > 1e-5).sum()), total + d.size
    print("WORST", worst / bound, loose / total, rel)
""")


def test_sharded_step_equals_single_device(repo):
    # the caller's XLA_FLAGS (conftest's backend optimiser off, an instruction-set cap) come first
    flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count=4"
    env = {"XLA_FLAGS": flags.strip(), "JAX_PLATFORMS": "cpu", "PATH": "/usr/bin:/bin"}
    res = subprocess.run([sys.executable, "-c", SCRIPT.format(repo=str(repo))], capture_output=True, text=True,
                         timeout=600, env=env)
    assert res.returncode == 0, res.stderr[-3000:]
    line = [x for x in res.stdout.splitlines() if x.startswith("WORST")][0].split()
    worst, loose, rel = float(line[1]), float(line[2]), float(line[3])
    # same global batch, same keys: only the order of float additions differs
    assert worst <= 1.0, worst
    assert rel < 1e-4, rel
    assert loose < 0.05, loose
    print(f"parameters differing by more than 1e-5: {loose:.1%}; worst loss difference {rel:.2e}")
