"""Walking a curve: G for given codes (in overlapping chunks when long), the root integrated, the
feet put on the floor.

Long curves in bounded memory. One G call takes at most CHUNK_T samples (and BATCH_SAMPLES
motions x samples). G instance-normalises over its whole time axis, so a curve up to CHUNK_T
goes through in one pass (the statistics span the whole curve, not a training window: DESIGN.md
§5.1); a longer one goes through in overlapping chunks of CHUNK_T samples, blended by
overlap-add: each chunk's weight is 0 within CHUNK_MARGIN samples of its ends (more than G's
receptive radius, about 100 samples at a time kernel of 5: the layers' half-widths times their strides, so
what a chunk's zero padding reaches is not used),
rises linearly over CHUNK_FADE samples, and the weights are normalised to sum 1. Each chunk's
statistics are its own 4.5 minutes instead of the whole walk's: tests/test_generate.py
bounds the difference to one pass on a curve that fits both ways. A G with a gait phase
(model.gait_phase) walks on one clock, G's own (model.apply.walked_phase): each chunk's phase
offset is the phase walked by its first sample, so the phase is one pass's, not restarted per chunk; the
root (a blended velocity, its height's difference with model.root_height) is integrated once
over the whole curve, so neither path nor height jumps at a seam. The straight extension past
the curve's end is walked after it and changes no sample's phase.

Root height. G predicts the root velocity (y included) and root-relative joints, never an
absolute height. The root is integrated from the curve's start (trajectory.integrate: p[0] = start,
p[t] = p[t-1] + v[t]), then each clip is lifted as a whole so that the 5th percentile over frames
of its lowest joint's height is 0: feet on the floor, robust to a few frames of dipping toes.
(The reference hard-coded a start height per style name, DESIGN.md §6.)
"""

from __future__ import annotations

import dataclasses
from typing import Callable, Sequence

import jax.numpy as jnp
import numpy as np

from motiongan_jax.generate import limits
from motiongan_jax.model import apply as model_apply
from motiongan_jax.motion import trajectory
from motiongan_jax.motion.representation import from_rows

MIN_T = 16
# How: one G call holds at most CHUNK_T samples of one motion and BATCH_SAMPLES in all
CHUNK_T = 4096
CHUNK_MARGIN = 128
CHUNK_FADE = 256
CHUNK_OVERLAP = 2 * CHUNK_MARGIN + CHUNK_FADE
BATCH_SAMPLES = 8_192
FLOOR_PERCENTILE = 5.0
def padded_length(num_samples: int) -> int:
    """The T that G runs on for a curve of `num_samples`: the next multiple of 8, at least MIN_T."""
    return max(MIN_T, -(-int(num_samples) // 8) * 8)


@dataclasses.dataclass(frozen=True, eq=False)
class Generated:
    positions: np.ndarray  # (B, T, J, 3) float64 metres, Y up, after the floor shift
    root_velocity: np.ndarray  # (B, T, 3) G's raw root velocity (m per sample)
    pose: np.ndarray  # (B, T, R) G's raw root-relative rows
    curve: np.ndarray  # (T, 3) the input curve
    w: np.ndarray  # (B, w_dim)
    floor_shift_m: np.ndarray  # (B,) added to every height


def sample_rate(meta: dict, cfg) -> float:
    """Network samples per second: source fps / data.frame_step."""
    return float(meta["fps"]) / int(cfg.data.frame_step)


def floor_shift(positions_BxTxJx3: np.ndarray, percentile: float = FLOOR_PERCENTILE) -> np.ndarray:
    """(B,) heights to add so that the `percentile` of each clip's lowest-joint height is 0."""
    lowest = np.asarray(positions_BxTxJx3)[..., 1].min(axis=-1)  # (B, T)
    return -np.percentile(lowest, percentile, axis=-1)


def generate_motion(state, layout, curve_Mx3, w_BxD, phase_offset_B=None, *, chunk_T: int = CHUNK_T,
                    progress: Callable[[int, int], None] | None = None) -> Generated:
    """Runs G on one curve for a batch of style codes; integrates the root from the curve start
    and puts each clip's feet on the floor (module doc). The motion has the curve's M samples:
    G runs on the curve extended straight to padded_length(M), in overlapping chunks of
    `chunk_T` samples when longer (module doc). A G with a gait phase starts each walk at
    `phase_offset_B` (radians; default 0: the left foot highest). `progress(done, total)` is
    called after each G call. GenerateError beyond MAX_CURVE_SAMPLES or MAX_TOTAL_SAMPLES,
    before G runs."""
    curve = np.asarray(curve_Mx3, np.float32)
    if curve.ndim != 2 or curve.shape[1] != 3 or curve.shape[0] < 2:
        raise limits.GenerateError(f"curve must be (M, 3) with M >= 2 samples, got shape {curve.shape}")
    if not np.isfinite(curve).all():
        raise limits.GenerateError("curve has non-finite values")
    w = np.asarray(w_BxD, np.float32)
    if w.ndim != 2 or len(w) == 0:
        raise limits.GenerateError(f"style codes must be (B, w_dim) with B >= 1, got shape {w.shape}")
    M, B = curve.shape[0], w.shape[0]
    if M > limits.MAX_CURVE_SAMPLES:
        raise limits.GenerateError(f"curve: {M:,} samples are more than the limit of {limits.MAX_CURVE_SAMPLES:,} "
                                   f"(generate.limits.MAX_CURVE_SAMPLES)")
    if B * M > limits.MAX_TOTAL_SAMPLES:
        raise limits.GenerateError(f"{B} motions x {M:,} samples = {B * M:,} are more than the limit of "
                                   f"{limits.MAX_TOTAL_SAMPLES:,} (generate.limits.MAX_TOTAL_SAMPLES): "
                                   f"ask for fewer styles or noise draws at once, or a shorter curve")
    if model_apply.has_gait_phase(state):
        phase = np.zeros(B) if phase_offset_B is None else np.asarray(phase_offset_B, np.float64)
        if phase.shape != (B,) or not np.isfinite(phase).all():
            raise limits.GenerateError(f"phase offsets must be {B} finite numbers (radians), one per motion, "
                                       f"got shape {phase.shape}")
    elif phase_offset_B is not None:
        raise limits.GenerateError("a phase offset was given, but this model has no gait phase")
    else:
        phase = None
    vel_Tx3 = trajectory.velocity(jnp.asarray(extend_straight(curve, padded_length(M) - M))[None])[0]
    root_vel, pose = _g_outputs(state, vel_Tx3, w, phase, chunk_T, progress)
    root_vel, pose = root_vel[:, :M], pose[:, :M]
    start = np.broadcast_to(curve[0].astype(np.float64) * np.array([1.0, 0.0, 1.0]), (B, 3))
    # trajectory.integrate's convention (p[0] = start, p[t] = p[t-1] + v[t], v[0] unused), in float64
    root = start[:, None, :] + np.concatenate([np.zeros((B, 1, 3)), np.cumsum(root_vel[:, 1:], axis=1)], 1)
    joints = np.asarray(from_rows(root, pose, layout), np.float64)
    if not np.isfinite(joints).all():
        raise limits.GenerateError("the generator produced non-finite positions (a broken checkpoint?)")
    shift = floor_shift(joints)
    joints[..., 1] += shift[:, None, None]
    return Generated(joints, root_vel, pose, curve, w, shift)


def extend_straight(curve_Mx3: np.ndarray, n: int) -> np.ndarray:
    """The curve with n more samples straight on along its last step (equal spacing: at its
    spacing)."""
    if n == 0:
        return curve_Mx3
    d = curve_Mx3[-1] - curve_Mx3[-2]
    return np.concatenate([curve_Mx3, curve_Mx3[-1] + d * np.arange(1, n + 1, dtype=curve_Mx3.dtype)[:, None]])


def chunk_starts(T: int, chunk_T: int) -> list[int]:
    """Start samples of the chunks G runs on for a T-sample input: [0] when T <= chunk_T, else
    evenly spread multiples of 8 from 0 to T - chunk_T, consecutive ones overlapping by at least
    CHUNK_OVERLAP (so G's downsampling grid is the one-pass grid)."""
    if T <= chunk_T:
        return [0]
    if chunk_T % 8 or chunk_T < 2 * CHUNK_OVERLAP:
        raise limits.GenerateError(f"chunk_T must be a multiple of 8 and >= {2 * CHUNK_OVERLAP}, got {chunk_T}")
    n = 1 + -(-(T - chunk_T) // (chunk_T - CHUNK_OVERLAP))
    while True:
        starts = [8 * round(i * (T - chunk_T) / (8 * (n - 1))) for i in range(n)]
        if all(b - a <= chunk_T - CHUNK_OVERLAP for a, b in zip(starts, starts[1:])):
            return starts
        n += 1


def chunk_weights(starts: Sequence[int], chunk_T: int) -> list[np.ndarray]:
    """Overlap-add weights (chunk_T,) of each chunk: 0 within CHUNK_MARGIN samples of an end that
    meets another chunk, a linear rise over CHUNK_FADE samples, 1 elsewhere (the curve's own
    ends keep weight 1, as in one pass)."""
    t = np.arange(chunk_T, dtype=np.float64)
    rise = np.clip((t - CHUNK_MARGIN + 0.5) / CHUNK_FADE, 0.0, 1.0)
    out = []
    for i in range(len(starts)):
        wt = np.ones(chunk_T)
        if i > 0:
            wt = wt * rise
        if i < len(starts) - 1:
            wt = wt * rise[::-1]
        out.append(wt)
    return out


def _g_outputs(state, vel_Tx3, w_BxD: np.ndarray, phase_B: np.ndarray | None, chunk_T: int,
               progress) -> tuple[np.ndarray, np.ndarray]:
    """(root_vel (B, T, 3), pose (B, T, R)) float64 of G on one velocity curve for every style
    code: in groups of motions and overlapping time chunks so that no call exceeds chunk_T samples
    of a motion or BATCH_SAMPLES in all; one call (the same computation as ever) when it fits.
    `phase_B`: the gait-phase offsets at the curve's first sample (None: G has no gait phase)."""
    T, B = int(vel_Tx3.shape[0]), len(w_BxD)
    L = min(T, chunk_T)
    starts = chunk_starts(T, L)
    weights = chunk_weights(starts, L)
    group = min(B, max(1, BATCH_SAMPLES // L))
    if phase_B is not None and len(starts) > 1:
        # one clock for the whole curve, G's own (model.apply.walked_phase): each chunk starts at
        # the phase its first sample is walked at, so the phase is one pass's, not restarted per chunk
        phase_BxT = np.mod(model_apply.walked_phase(state, np.broadcast_to(np.asarray(vel_Tx3), (B, T, 3)), w_BxD,
                                                    phase_B), 2 * np.pi)
    total, done = -(-B // group) * len(starts), 0
    root = pose = None
    norm_T = np.zeros(T)
    for s, wt in zip(starts, weights):
        norm_T[s:s + L] += wt
    for g0 in range(0, B, group):
        idx = np.minimum(np.arange(g0, g0 + group), B - 1)  # the last group padded: one compile
        keep = min(group, B - g0)
        wg = jnp.asarray(w_BxD[idx])
        for s, wt in zip(starts, weights):
            phase = None
            if phase_B is not None:
                phase = phase_B[idx] if s == 0 else phase_BxT[idx, s]
            r, p = model_apply.apply_code(state, jnp.broadcast_to(vel_Tx3[s:s + L], (group, L, 3)), wg, phase)
            r = np.asarray(r, np.float64)[:keep]
            p = np.asarray(p, np.float64)[:keep]
            if root is None:
                root, pose = np.zeros((B, T, 3)), np.zeros((B, T, p.shape[-1]))
            if len(starts) == 1:  # one pass: G's outputs as they are
                root[g0:g0 + keep], pose[g0:g0 + keep] = r, p
            else:
                root[g0:g0 + keep, s:s + L] += wt[:, None] * r
                pose[g0:g0 + keep, s:s + L] += wt[:, None] * p
            done += 1
            if progress is not None:
                progress(done, total)
    if len(starts) > 1:
        root /= norm_T[:, None]
        pose /= norm_T[:, None]
    return root, pose
