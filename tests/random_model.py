"""A checkpoint with seeded random parameters, shared by the tests that only read checkpoints."""

import types

import jax
import numpy as np

from motiongan_jax import checkpoint, representation, synthetic
from motiongan_jax import step as step_lib
from motiongan_jax import train as train_lib


def random_run(cfg, wd, step: int = 4, seed: int = 0):
    """A checkpoint of `cfg` with seeded random parameters, saved as training saves one
    (jax.eval_shape of init_state gives the structure without compiling the initialisers)."""
    layout = representation.layout_from_skeleton(synthetic.cmu_skeleton(), synthetic.UNITS_TO_M)
    styles = tuple(sorted(synthetic.STYLES))
    dataset = types.SimpleNamespace(style_names=styles, layout=layout, fps=60.0, data_dir="<test>")
    like = jax.eval_shape(lambda: step_lib.init_state(cfg, layout, len(styles), jax.random.key(0)))
    rng = np.random.default_rng(seed)
    state = jax.tree.map(lambda s: rng.normal(0, 0.3, s.shape).astype(s.dtype)
                         if np.issubdtype(s.dtype, np.floating) else np.zeros(s.shape, s.dtype), like)
    checkpoint.save(checkpoint.manager(wd / "checkpoints"), step, state, train_lib.run_meta(cfg, dataset))
    return wd
