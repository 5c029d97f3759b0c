"""D's judgement of real windows and of altered copies (a statue, no steps, floating): whether D
can tell a gait at all.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import scipy.special
from scipy.ndimage import gaussian_filter1d

from motiongan_jax.model import apply as model_apply
from motiongan_jax.motion import trajectory

PROBE_WINDOWS = 128  # real training windows the probe judges
PROBE_SMOOTHING_SAMPLES = 2.0  # Gaussian sigma of the "no steps" window
PROBE_FLOAT_M = 0.3  # how far the "floating" window's root rises over the window


@jax.jit
def _d_logit(state, vel_BxTx3, pose_BxTxR, labels_B):
    # compiled once for the five inputs (op by op, D's dispatch costs more than its compile)
    return model_apply.discriminator(state)(vel_BxTx3, pose_BxTxR, update_stats=False, labels_B=labels_B)[0]


def discriminator_probe(state, batch: dict, key) -> dict:
    """Can the trained D teach a gait? Its verdict on real training windows and on the same windows
    turned into a statue gliding along the root (every frame the window's mean pose), smoothed along
    time (no steps: Gaussian over PROBE_SMOOTHING_SAMPLES samples), floating (the root rising
    PROBE_FLOAT_M over the window), and on G's output for their curves and labels (z and the gait
    phase drawn as in training; G's parameters are the state's). Per input: the mean sigmoid of
    the real/fake logit, and the share judged real (logit > 0). A D that judges a glide or a float
    as real as a walk gives G no gradient toward planted feet or the floor."""
    root, pose, labels = (np.asarray(batch[k]) for k in ("root_BxTx3", "pose_BxTxR", "label_B"))
    B, T, _ = root.shape
    vel = np.asarray(trajectory.velocity(jnp.asarray(root)))
    floating = vel.copy()
    floating[:, 1:, 1] += PROBE_FLOAT_M / (T - 1)
    floating[:, 0, 1] = floating[:, 1, 1]
    k_z, k_phase = jax.random.split(key)  # each key used once: the offsets are not a function of z
    z = jax.random.normal(k_z, (B, model_apply.z_dim(state)), jnp.float32)
    offset = (jax.random.uniform(k_phase, (B,), jnp.float32, 0.0, 2 * np.pi)
              if model_apply.has_gait_phase(state) else None)
    w = model_apply.style_codes(state, jnp.asarray(labels), z)
    curve_vel = trajectory.velocity(jnp.asarray(batch["curve_BxTx3"]))
    fake_vel, fake_pose = model_apply.apply_code(state, curve_vel, w, offset)
    inputs = {
        "real windows": (vel, pose),
        "statue gliding along the root": (vel, np.broadcast_to(pose.mean(1, keepdims=True), pose.shape)),
        f"pose smoothed along time (sigma {PROBE_SMOOTHING_SAMPLES:g} samples)":
            (vel, gaussian_filter1d(pose, PROBE_SMOOTHING_SAMPLES, axis=1, mode="nearest")),
        f"root rising {PROBE_FLOAT_M:g} m over the window": (floating, pose),
        "G's output for the same curves and labels": (np.asarray(fake_vel), np.asarray(fake_pose)),
    }
    out = {}
    for name, (v, p) in inputs.items():
        logit = np.asarray(_d_logit(state, np.asarray(v, np.float32), np.asarray(p, np.float32), labels), np.float64)
        out[name] = {"p_real": float(np.mean(scipy.special.expit(logit))), "judged_real": float(np.mean(logit > 0))}
    return out
