"""The protocol's streaming part (DESIGN.md §7): held-out paths walked as a live stream.

Each of the first `Settings.stream_curves` like-for-like paths (own_paths.curves_of: a held-out
clip's root path at its own speed) is walked in its clip's style twice with the same style code and
gait phase: whole-path (walk.generate_motion) and by a `generate.stream.Walker` that knows the path
only `lookahead` samples ahead, as a live caller would feed it (`stream_walk`). Both walks get the
same gait, skate, smoothness and style rows; the stream's rows should be the whole walk's.

Seams: a stream joins its advances at chunk boundaries. Per step of each walk: the horizontal speed
of a toe on the floor, the joints' squared third difference (jerk) and the gait phase's deviation
from its median step. Each is averaged over the steps that touch a boundary and over the others;
the ratio seam / rest is 1 where the boundaries cannot be seen. The whole-path walk, cut at the
same samples, is the control.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax.evaluation import clip_metrics, own_paths
from motiongan_jax.generate import stream, styles, walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.motion import gait, trajectory

ROW_KEYS = ("support", "lower_foot_height_m", "skate_ratio", "alternation", "step_frequency_hz",
            "step_amplitude_m", "jerk_mps3")
SEAM_KEYS = ("toe_speed", "jerk", "phase")


def stream_walk(state, layout, curve_Lx3, w_D, rate: float, phase0: float = 0.0, *, step: int = stream.MAX_STEP,
                lookahead: int = stream.LOOKAHEAD) -> tuple[stream.Samples, list[int]]:
    """A walk of the curve by a stream that is fed the path `lookahead` + `step` samples ahead of
    what it has walked and advances `step` samples at a time (the rest flushed at the path's end).
    Returns the samples joined (index0 0) and the sample indices where an advance began (after 0)."""
    pts = np.asarray(curve_Lx3, np.float64)[:, [0, 2]]
    L = len(pts)
    head = pts[1] - pts[0]
    walker = stream.Walker(state, layout, w_D, rate, start_xz=pts[0], heading_xz=head,
                           speed_m_per_s=float(np.linalg.norm(head) * rate), phase0=phase0,
                           lookahead=lookahead, max_step=step)
    fed = 1
    parts = []
    while walker.emitted < L:
        want = min(L, walker.emitted + lookahead + step)
        if want > fed:
            walker.feed_points(pts[fed:want])
            fed = want
        parts.append(walker.advance(step, flush=fed == L))
    starts = [p.index0 for p in parts[1:] if len(p.positions)]
    cat = stream.Samples(0, np.concatenate([p.positions for p in parts]),
                         np.concatenate([p.root_velocity for p in parts]), np.concatenate([p.pose for p in parts]),
                         np.concatenate([p.curve for p in parts]),
                         None if parts[0].phase is None else np.concatenate([p.phase for p in parts]),
                         np.concatenate([p.floor_shift_m for p in parts]))
    return cat, starts


def seam_steps(starts, num_steps: int, span: int) -> np.ndarray:
    """Bool (num_steps,): the steps (t → t + span) that reach across a boundary b (t < b <= t + span)."""
    at = np.zeros(num_steps, bool)
    for b in starts:
        at[max(0, b - span):min(num_steps, b)] = True
    return at


def seam_values(joints_LxJx3, phase_L, feet, rate: float, contact_height_m: float, starts) -> dict:
    """Per SEAM_KEYS, (values at the seams, values elsewhere), pooled over the walk's steps."""
    toes = joints_LxJx3[:, list(feet)]
    h_LxK = gait.toe_heights(toes)
    speed_Lm1xK = np.linalg.norm(np.diff(toes[..., [0, 2]], axis=0), axis=-1) * rate
    contact = (h_LxK[:-1] < contact_height_m) & (h_LxK[1:] < contact_height_m)
    at1 = seam_steps(starts, len(joints_LxJx3) - 1, 1)[:, None] & np.ones_like(contact)
    jerk_Lm3 = np.mean(np.sum(np.square(np.diff(joints_LxJx3, n=3, axis=0)), -1), -1) * rate**6
    at3 = seam_steps(starts, len(jerk_Lm3), 3)
    out = {"toe_speed": (speed_Lm1xK[contact & at1], speed_Lm1xK[contact & ~at1]),
           "jerk": (jerk_Lm3[at3], jerk_Lm3[~at3])}
    if phase_L is not None:
        d = np.diff(np.asarray(phase_L, np.float64))
        dev = np.abs(d - np.median(d))
        at = seam_steps(starts, len(d), 1)
        out["phase"] = (dev[at], dev[~at])
    return out


def _ratio(pairs) -> float:
    """mean(seam) / mean(rest) pooled over walks; nan without values on either side."""
    seam = np.concatenate([p[0] for p in pairs]) if pairs else np.zeros(0)
    rest = np.concatenate([p[1] for p in pairs]) if pairs else np.zeros(0)
    if not seam.size or not rest.size or np.mean(rest) <= 0:
        return float("nan")
    return float(np.mean(seam) / np.mean(rest))


def stream_block(ctx, seed: int) -> dict:
    """One seed: the first `stream_curves` like-for-like paths walked whole and streamed (one draw
    each, the same w and phase); the mean of every ROW_KEYS row and the evaluator's top-1 for both,
    and the seam ratios of both."""
    s = ctx.settings
    curves = ctx.realism_curves[: s.stream_curves]
    if not curves:
        return {}
    T = ctx.cfg.data.window_T
    Z = model_apply.z_dim(ctx.state)
    key = jax.random.key(90_000 + seed)
    rows = {"whole": [], "stream": []}
    wins = {"whole": [], "stream": []}
    seams = {"whole": {k: [] for k in SEAM_KEYS}, "stream": {k: [] for k in SEAM_KEYS}}
    labels = []
    gait_clock = model_apply.has_gait_phase(ctx.state)
    for ci, c in enumerate(curves):
        clip = next(v for v in ctx.val_clips if v.source == c.source)
        style = ctx.style_names.index(clip.label.style)
        k_z, k_p = jax.random.split(jax.random.fold_in(key, ci))
        w = np.asarray(styles.latent_codes(ctx.state, np.array([style], np.int32),
                                           jax.random.normal(k_z, (1, Z), jnp.float32)))
        phase0 = float(jax.random.uniform(k_p, (), maxval=2 * np.pi)) if gait_clock else 0.0
        whole = walk.generate_motion(ctx.state, ctx.layout, c.curve_Lx3, w, np.array([phase0]) if gait_clock else None)
        streamed, starts = stream_walk(ctx.state, ctx.layout, c.curve_Lx3, w[0], ctx.sample_rate, phase0)
        vel = trajectory.velocity(c.curve_Lx3[None].astype(np.float32))
        whole_phase = model_apply.walked_phase(ctx.state, vel, w, np.array([phase0]))[0] if gait_clock else None
        for name, joints, phase in (("whole", whole.positions[0], whole_phase),
                                    ("stream", streamed.positions, streamed.phase)):
            rows[name].append(clip_metrics.motion_metrics(joints, None, ctx.layout, ctx.feet, ctx.sample_rate,
                                                          ctx.contact_height_m))
            n = len(joints) // T
            wins[name].append(joints[: n * T].reshape(n, T, *joints.shape[1:]))
            for k, v in seam_values(joints, phase, ctx.feet, ctx.sample_rate, ctx.contact_height_m, starts).items():
                seams[name][k].append(v)
        labels += [style] * (len(whole.positions[0]) // T)
    labels = np.asarray(labels, np.int32)
    out = {"curves": len(curves)}
    for name in ("whole", "stream"):
        for k in ROW_KEYS:
            v = np.asarray([r[k] for r in rows[name]], np.float64)
            out[f"{name}_{k}"] = float(np.mean(v[np.isfinite(v)])) if np.isfinite(v).any() else float("nan")
        out[f"{name}_sra_top1"] = own_paths.style_accuracy(ctx.ev, np.concatenate(wins[name]), labels,
                                                            len(ctx.style_names))[0]
        for k in SEAM_KEYS:
            out[f"{name}_seam_{k}_ratio"] = _ratio(seams[name][k])
    diffs = [abs(out[f"stream_{k}"] - out[f"whole_{k}"]) / abs(out[f"whole_{k}"])
             for k in ROW_KEYS + ("sra_top1",) if np.isfinite(out[f"whole_{k}"]) and out[f"whole_{k}"] != 0]
    out["stream_max_rel_diff"] = float(max(diffs)) if diffs else float("nan")
    return out
