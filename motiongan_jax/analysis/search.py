"""Style search. Recover a code for an unlabelled motion: cut it into the model's windows
(analysis.clips), then minimise a reconstruction loss through G over w alone with optax Adam (linear
warm-up that starts below the peak rate, then cosine decay), from several starts at once, in
one jitted scan. Unlike the reference there is no D in the loop (its terms were detached there
and had no effect), motion and curve cover the same frames, and nothing touches the model's
state: the parameters enter the jitted function as inputs and are never written. One code is
fitted to all windows together (the reference fitted each window separately).

Windows of 64+ samples (`T=`, `--search-T`) give the search a smooth loss; shorter ones a rough
one (docs/RESULTS.md §11).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import Sequence

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax

from motiongan_jax.analysis.clips import MotionWindows
from motiongan_jax.analysis.style_space import AnalysisError, StyleCodes
from motiongan_jax.data import curves
from motiongan_jax.generate import walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.motion import trajectory
from motiongan_jax.motion.representation import LENGTH_UNIT_M, RowLayout


def search_schedule(peak_lr: float, steps: int, warmup: int):
    """Linear warm-up peak·(i+1)/warmup for updates i < warmup (the first update runs at
    peak/warmup, not at the full rate), then cosine decay from peak towards 0."""
    warmup = max(int(warmup), 0)

    def schedule(count):
        c = jnp.asarray(count, jnp.float32)
        warm = peak_lr * (c + 1.0) / max(warmup, 1)
        t = jnp.clip((c - warmup) / max(steps - warmup, 1), 0.0, 1.0)
        return jnp.where(c < warmup, warm, 0.5 * peak_lr * (1.0 + jnp.cos(jnp.pi * t)))

    return schedule


def _window_losses(root_vel_NxTx3, pose_NxTxR, u_NxTx3, target_pose_NxTxR, vel_weight, length_unit):
    lv = jnp.mean(jnp.square(root_vel_NxTx3[:, 1:] - u_NxTx3[:, 1:]), axis=(1, 2))
    lp = jnp.mean(jnp.square(pose_NxTxR - target_pose_NxTxR), axis=(1, 2))
    return (vel_weight * lv + lp) / length_unit**2


def reconstruction_loss(root_vel_NxTx3, pose_NxTxR, target: MotionWindows, *, vel_weight: float = 0.01,
                        length_unit: float = LENGTH_UNIT_M):
    """vel_weight · MSE(v̂, u) + MSE(P̂, P) per window, lengths in `length_unit` (the losses' CMU
    unit), as in the reference's search. v[0] is left out: it is a reflected duplicate, not a
    step (trajectory.velocity)."""
    return _window_losses(root_vel_NxTx3, pose_NxTxR, trajectory.velocity(target.root_NxTx3),
                          target.pose_NxTxR, vel_weight, length_unit)


@functools.partial(jax.jit, static_argnames=("steps", "warmup", "record_every"))
def _search_scan(gstate, vel_NxTx3, u_NxTx3, pose_NxTxR, u0_SxD, center_D, scale_D, lr, vel_weight,
                 length_unit, *, steps: int, warmup: int, record_every: int):
    S, N = u0_SxD.shape[0], vel_NxTx3.shape[0]
    tx = optax.adam(search_schedule(lr, steps, warmup), b1=0.5, b2=0.999)
    vel, u, pose_t = (jnp.tile(a, (S, 1, 1)) for a in (vel_NxTx3, u_NxTx3, pose_NxTxR))

    def losses_S(p_SxD):
        w = center_D + scale_D * p_SxD
        rv, pose = model_apply.g_apply(gstate, vel, jnp.repeat(w, N, axis=0))
        return jnp.mean(_window_losses(rv, pose, u, pose_t, vel_weight, length_unit).reshape(S, N), axis=1)

    def total(p):
        l_S = losses_S(p)
        # The starts are independent: the sum's gradient wrt row s is start s's own gradient, and
        # Adam is elementwise, so this equals S separate optimisations.
        return jnp.sum(l_S), l_S

    def body(carry, _):
        p, opt = carry
        (_, l_S), grad = jax.value_and_grad(total, has_aux=True)(p)
        updates, opt = tx.update(grad, opt, p)
        return (optax.apply_updates(p, updates), opt), l_S

    (p, _), hist = jax.lax.scan(body, (u0_SxD, tx.init(u0_SxD)), None, length=steps)
    return center_D + scale_D * p, losses_S(p), hist[::record_every]


@dataclasses.dataclass(frozen=True)
class SearchResult:
    w_D: np.ndarray  # the best start's code
    loss: float  # its final reconstruction loss
    best_start: int
    start_names: tuple[str, ...]
    w_SxD: np.ndarray  # every start's final code
    initial_loss_S: np.ndarray
    final_loss_S: np.ndarray
    history_HxS: np.ndarray  # loss before update 0, record_every, 2·record_every, ...
    record_every: int


def code_scale(codes: StyleCodes) -> tuple[jax.Array, jax.Array]:
    """(centre, per-dimension spread) of the labelled codes: the search's coordinates."""
    X, _ = codes.flat_samples
    sd = jnp.std(X, axis=0)
    floor = jnp.maximum(jnp.max(sd) * 1e-3, 1e-12)
    return jnp.mean(X, axis=0), jnp.where(sd > floor, sd, floor)


def search_starts(codes: StyleCodes, num_random: int = 4, key: jax.Array | None = None
                  ) -> tuple[jax.Array, tuple[str, ...]]:
    """Every style centroid, plus num_random draws N(centre, spread²) of `code_scale` (from `key`,
    default key 1). Returns (starts S x D, their names)."""
    names = [f"centroid:{s}" for s in codes.style_names]
    starts = [codes.centroids_CxD]
    if num_random > 0:
        centre, spread = code_scale(codes)
        eps = jax.random.normal(jax.random.key(1) if key is None else key, (num_random, centre.shape[0]))
        starts.append(centre + eps * spread)
        names += [f"random:{i}" for i in range(num_random)]
    return jnp.concatenate(starts, axis=0).astype(jnp.float32), tuple(names)


def style_search(state, target: MotionWindows, starts_SxD, start_names: Sequence[str] | None = None, *,
                 center_D=None, scale_D=None, steps: int = 200, lr: float = 0.1, warmup: int = 20,
                 vel_weight: float = 0.01, length_unit: float = LENGTH_UNIT_M,
                 record_every: int = 10) -> SearchResult:
    """Fit one code w to all of the target's windows, from every start at once (one jitted scan).

    Adam (β 0.5, 0.999, as in the reference) runs on p with w = center + scale · p, so `lr` is in
    units of `scale` per step whatever the size of the codes (pass `code_scale(codes)`; default 0
    and 1: plain w). Loss: `reconstruction_loss`, averaged over windows. The state is read, never
    written; D is not involved.
    """
    w0 = jnp.asarray(starts_SxD, jnp.float32)
    chex.assert_rank(w0, 2)
    S, D = w0.shape
    names = tuple(start_names) if start_names is not None else tuple(f"start:{i}" for i in range(S))
    if len(names) != S:
        raise ValueError(f"{S} starts but {len(names)} names")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    center = jnp.zeros((D,), jnp.float32) if center_D is None else jnp.asarray(center_D, jnp.float32)
    scale = jnp.ones((D,), jnp.float32) if scale_D is None else jnp.asarray(scale_D, jnp.float32)
    chex.assert_shape([center, scale], (D,))
    # numpy in: one jit cache entry whatever device computation made the inputs
    host = lambda x: np.asarray(x, np.float32)  # noqa: E731
    w, final, hist = _search_scan(model_apply.generator_state(state), host(trajectory.velocity(target.curve_NxTx3)),
                                  host(trajectory.velocity(target.root_NxTx3)), host(target.pose_NxTxR),
                                  host((w0 - center) / scale), host(center), host(scale), host(lr),
                                  host(vel_weight), host(length_unit), steps=int(steps),
                                  warmup=int(warmup), record_every=int(record_every))
    final, hist, w = np.asarray(final), np.asarray(hist), np.array(w)
    if not np.isfinite(final).any():
        raise AnalysisError(f"style search diverged from every start (final losses {final}); lower lr")
    # a start that Adam left worse than it found it keeps its code as it was: never worse than the start
    worse = ~(final <= hist[0])
    w[worse], final = np.asarray(w0, np.float32)[worse], np.where(worse, hist[0], final)
    best = int(np.nanargmin(final))
    return SearchResult(w[best], float(final[best]), best, names, w, hist[0], final, hist, int(record_every))


def start_losses(state, target: MotionWindows, w_SxD, *, vel_weight: float = 0.01,
                 length_unit: float = LENGTH_UNIT_M) -> np.ndarray:
    """The reconstruction loss of each code as it is (G forward only, one start at a time, with
    the same compiled forward as `reconstruct`)."""
    return np.array([float(jnp.mean(reconstruction_loss(*reconstruct(state, target, w), target,
                                                         vel_weight=vel_weight, length_unit=length_unit)))
                     for w in jnp.asarray(w_SxD, jnp.float32)])


def search_motion(state, codes: StyleCodes, target: MotionWindows, *, num_random: int = 4,
                  keep: int | None = 4, steps: int = 200, lr: float = 0.1, warmup: int = 20,
                  vel_weight: float = 0.01, length_unit: float = LENGTH_UNIT_M, nearest: int = 3,
                  key: jax.Array | None = None) -> dict:
    """Style search as the CLI runs it: starts = every centroid + `num_random` draws
    (`search_starts`); the `keep` with the lowest loss as they are are optimised (None: all) in
    the codes' own coordinates (`code_scale`); the best result's nearest labelled styles.

    Returns {"result": SearchResult, "screen": {start name: loss as is}, "nearest": [[name,
    distance], ...], "nearest_scaled": the same distances in units of the codes' spread}.
    """
    starts, names = search_starts(codes, num_random, key)
    screen = start_losses(state, target, starts, vel_weight=vel_weight, length_unit=length_unit)
    order = np.argsort(screen, kind="stable")
    if keep is not None:
        order = order[: max(1, int(keep))]
    centre, spread = code_scale(codes)
    res = style_search(state, target, starts[order], [names[i] for i in order], center_D=centre,
                       scale_D=spread, steps=steps, lr=lr, warmup=warmup, vel_weight=vel_weight,
                       length_unit=length_unit)
    near = nearest_to(res.w_D, codes, k=nearest)
    scale = float(jnp.sqrt(jnp.mean(jnp.square(spread))))
    return {"result": res, "screen": {n: float(v) for n, v in zip(names, screen)}, "nearest": near,
            "nearest_scaled": [[n, d / scale] for n, d in near]}


def nearest_to(w_D, codes: StyleCodes, k: int = 3) -> list[list]:
    """The k labelled styles whose centroids are nearest to w: [[name, distance], ...]."""
    d = np.asarray(jnp.linalg.norm(codes.centroids_CxD - jnp.asarray(w_D)[None], axis=-1))
    order = np.argsort(d, kind="stable")[:k]
    return [[codes.style_names[i], float(d[i])] for i in order]


def reconstruct(state, target: MotionWindows, w_D):
    """G's (root_vel, pose) for every window of the target with one code w."""
    N = target.curve_NxTx3.shape[0]
    # numpy in: the same jit cache entry whether w comes from numpy or from a device computation
    w = np.broadcast_to(np.asarray(w_D, np.float32), (N, np.shape(w_D)[-1]))
    return model_apply.apply_code(state, trajectory.velocity(target.curve_NxTx3), w)


def generate_along(state, layout: RowLayout, w_D, curve_xz_Px2, *, spacing_m: float,
                   start_height_m: float) -> dict:
    """Walk with code w along a floor curve: the curve is resampled every `spacing_m` metres (the
    speed, e.g. the searched clip's `spacing_m`) and walked whole by `walk.generate_motion`
    (padded for G, in chunks when long, a gait phase from offset 0); the root starts at the
    curve's start at `start_height_m` (G predicts velocities only) in place of generate's floor
    shift. Returns numpy arrays: positions_TxJx3, root_Tx3, pose_TxR, curve_Tx3."""
    xz = curves.resample_polyline(curve_xz_Px2, spacing=float(spacing_m))
    if len(xz) < 2:
        raise AnalysisError(f"the curve gives {len(xz)} sample at {spacing_m:.3g} m per sample; a walk "
                            f"needs at least 2 (draw a longer curve)")
    curve = trajectory.on_floor(xz).astype(np.float32)
    gen = walk.generate_motion(state, layout, curve, np.reshape(np.asarray(w_D, np.float32), (1, -1)))
    positions = gen.positions[0].copy()
    positions[..., 1] += float(start_height_m) - gen.floor_shift_m[0]
    return {"positions_TxJx3": positions, "root_Tx3": positions[:, 0].copy(), "pose_TxR": gen.pose[0],
            "curve_Tx3": curve}
