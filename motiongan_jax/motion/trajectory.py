"""Motion geometry on the floor: velocities and their integral, turning about +y, headings, the
window frame, floor points. jnp, any leading batch shape (floor_path and on_floor keep numpy).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np


def velocity(x_BxTxD):
    """v[t] = x[t] - x[t-1] for t >= 1; v[0] = x[2] - x[1], the reference's reflection pad of the
    differences (DESIGN.md §2.5), so G sees exactly the reference's first input. Time is axis -2; T >= 3."""
    x = jnp.asarray(x_BxTxD)
    d = x[..., 1:, :] - x[..., :-1, :]
    return jnp.concatenate([d[..., 1:2, :], d], axis=-2)


def integrate(start_BxD, v_BxTxD):
    """p[0] = start, p[t] = p[t-1] + v[t]; v[0] is ignored (CONTRACTS.md)."""
    v = jnp.asarray(v_BxTxD)
    start = jnp.asarray(start_BxD, v.dtype)
    steps = jnp.cumsum(v[..., 1:, :], axis=-2)
    steps = jnp.concatenate([jnp.zeros_like(v[..., :1, :]), steps], axis=-2)
    return start[..., None, :] + steps


def rotate_y(x, theta):
    """Rotation by theta (radians) about the vertical (Y) axis through the origin.

    Row-vector convention, as the reference applied it to its augmentation:
    x' = x @ R with R = [[cos, 0, -sin], [0, 1, 0], [sin, 0, cos]], i.e.
    x' = cos*x + sin*z, z' = -sin*x + cos*z, y unchanged: the right-handed rotation by +theta
    about +Y (proper: det R = 1). x is (..., 3) xyz or (..., 2) floor (x, z) points. theta is a
    scalar or has x's leading dims, e.g. (B,) or (B, 1) for x (B, T, 3); missing trailing dims
    are added, then it broadcasts against x[..., 0].
    """
    x = jnp.asarray(x)
    if x.shape[-1] not in (2, 3):
        raise ValueError(f"rotate_y wants (..., 3) or (..., 2) points, got shape {x.shape}")
    theta = jnp.asarray(theta, x.dtype if jnp.issubdtype(x.dtype, jnp.floating) else jnp.float32)
    theta = theta.reshape(theta.shape + (1,) * max(x.ndim - 1 - theta.ndim, 0))
    c, s = jnp.cos(theta), jnp.sin(theta)
    px, pz = x[..., 0], x[..., -1]
    nx, nz = c * px + s * pz, -s * px + c * pz
    if x.shape[-1] == 2:
        return jnp.stack([nx, nz], axis=-1)
    return jnp.stack([nx, jnp.broadcast_to(x[..., 1], nx.shape), nz], axis=-1)


def rotate_rows_y(pose_xR, theta):
    """Pose rows (..., R), joint-major x, y, z triples, each turned by theta about +y as `rotate_y`
    turns a point; theta as there, with the rows' leading dims (or fewer)."""
    pose_xR = jnp.asarray(pose_xR)
    return rotate_y(pose_xR.reshape(pose_xR.shape[:-1] + (-1, 3)), theta).reshape(pose_xR.shape)


def heading(v_BxTx3):
    """Heading of floor velocities, radians about +y with 0 = +z: atan2(v_x, v_z), the angle that
    `rotate_y` turns +z into. A zero velocity gets heading 0."""
    v = jnp.asarray(v_BxTx3)
    return jnp.arctan2(v[..., 0], v[..., -1])


def window_frame(root_vel_BxTx3, pose_BxTxR):
    """Root velocity and pose rows turned about +y so that each window's travel, the sum of its
    root velocities after the first (v[0] duplicates v[1], `velocity`), points along +z: the
    evaluator's canonical frame. A window that does not move keeps its orientation (heading 0)."""
    theta_B = heading(jnp.sum(root_vel_BxTx3[:, 1:], axis=1))
    return rotate_y(root_vel_BxTx3, -theta_B), rotate_rows_y(pose_BxTxR, -theta_B)


# Binomial smoothing of the walking direction: the training curves carry 2% spatial jitter, i.e.
# about 2 degrees of heading noise per sample, which a body turned by the raw heading would shake with.
HEADING_TAPS = (1.0, 4.0, 6.0, 4.0, 1.0)


def smooth_heading(v_BxTx3, taps=HEADING_TAPS):
    """Heading (see `heading`) of the unit floor velocities averaged over time with `taps`
    (edges replicated), so the direction changes smoothly from sample to sample. Time is axis -2."""
    v = jnp.asarray(v_BxTx3)
    xz = jnp.stack([v[..., 0], v[..., -1]], axis=-1)
    unit = xz / jnp.maximum(jnp.linalg.norm(xz, axis=-1, keepdims=True), 1e-12)
    k = jnp.asarray(taps, v.dtype) / sum(taps)
    r = len(taps) // 2
    t = unit.shape[-2]
    idx = jnp.clip(jnp.arange(t)[:, None] + jnp.arange(-r, r + 1)[None, :], 0, t - 1)  # T x K
    avg = jnp.einsum("...tkc,k->...tc", unit[..., idx, :], k)
    return jnp.arctan2(avg[..., 0], avg[..., 1])


def floor_path(root_Fx3):
    """(x, z) of root positions (F, 3) -> (F, 2); works on numpy and jnp alike."""
    return root_Fx3[..., 0::2]


def on_floor(xz_x2):
    """Floor points (..., 2) as (x, 0, z) (..., 3), the inverse of `floor_path`; numpy stays
    numpy (its dtype kept), anything else becomes jnp."""
    xp = np if isinstance(xz_x2, np.ndarray) else jnp
    return xp.stack([xz_x2[..., 0], xp.zeros_like(xz_x2[..., 0]), xz_x2[..., 1]], axis=-1)
