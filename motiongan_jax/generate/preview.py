"""Training previews: a few styles walking a fixed S-curve, as a GIF, by generation's own path (the
training loop calls it through its `preview` hook, so training never imports generation)."""

from __future__ import annotations

from pathlib import Path

import jax.numpy as jnp
import numpy as np

from motiongan_jax.data import curves
from motiongan_jax.generate import walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.model import state as model_state
from motiongan_jax.motion import trajectory


def preview_curve(T: int, spacing_m: float) -> np.ndarray:
    """The fixed preview curve: an S-curve with the training data's mean spacing per sample."""
    pts = curves.shape_curve("s_curve", length=spacing_m * (T - 1), num_points=200)
    xz = curves.resample_polyline(pts, num_points=T)
    return trajectory.on_floor(xz).astype(np.float32)


def write_preview(path: Path, state, layout, style_names, curve_Tx3: np.ndarray, num: int = 3) -> Path:
    """A few styles (z = 0) walking the preview curve, as a GIF: generate.py's own path (with G's
    moving average when the run keeps one)."""
    from motiongan_jax import viz

    state = model_state.inference_state(state)
    labels = np.linspace(0, len(style_names) - 1, min(num, len(style_names))).round().astype(np.int32)
    gen = walk.generate_motion(state, layout, curve_Tx3, model_apply.style_codes(state, jnp.asarray(labels)))
    return viz.animate_motions(list(gen.positions), layout.parents, [style_names[i] for i in labels], path,
                               curves=[curve_Tx3] * len(labels), joint_names=layout.joint_names)


def previewer(cfg, dataset):
    """The training loop's preview hook: `write(path, state)` for this run, on a curve with the
    training data's mean distance per sample (measured within clips)."""
    spacing = float(np.mean([np.linalg.norm(np.diff(c.root_Fx3[:, [0, 2]], axis=0), axis=-1).mean()
                             for c in dataset.train])) * cfg.data.frame_step
    curve = preview_curve(cfg.data.window_T, spacing)
    return lambda path, state: write_preview(path, state, dataset.layout, dataset.style_names, curve)
