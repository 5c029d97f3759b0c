"""`bin/train.py --dry-run`: parameter counts and layer shapes, from abstract shapes only."""

from __future__ import annotations

import jax
from flax import nnx

from motiongan_jax import data, step as step_lib
from motiongan_jax.nn import count_params
from motiongan_jax.config import Config


def describe(cfg: Config) -> str:
    dataset = data.load_dataset(cfg.data)
    layout, num_styles = dataset.layout, dataset.num_styles
    g, d = nnx.eval_shape(lambda: step_lib.build_models(cfg, layout.num_rel_joints, num_styles, jax.random.key(0), layout))
    lines = [
        f"config {cfg.name}: data {dataset.data_dir} ({len(dataset.train)} train / {len(dataset.val)} val clips, "
        f"{num_styles} styles, {dataset.fps:g} fps)",
        f"skeleton: {layout.num_joints} kept joints -> {layout.num_rows} rows; window T = {cfg.data.window_T}, "
        f"batch {cfg.train.batch_size}",
        f"generator: {count_params(g):,} parameters",
        f"discriminator: {count_params(d):,} parameters (spectral-norm vectors not counted)",
        "",
        "parameter shapes:",
    ]
    for name, module in (("G", g), ("D", d)):
        for path, leaf in jax.tree_util.tree_flatten_with_path(nnx.state(module, nnx.Param))[0]:
            key = "/".join(str(getattr(p, "key", getattr(p, "name", p))) for p in path)
            lines.append(f"  {name} {key}: {tuple(leaf.shape)}")
    return "\n".join(lines)
