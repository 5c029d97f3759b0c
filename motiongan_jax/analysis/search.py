"""Style search: the style of a motion as a mix of the model's known styles (DESIGN.md §5.3).

The motion is cut into WINDOWS windows of the model's T spread over it (analysis.clips), each
with its noise-free curve and its measured gait phase. Every known style's code w_c = LT(c, z = 0)
is first scored as it is (the screen); the KEEP best start a search over mixes
w = Σ_c a_c w_c, a = softmax(logits), by Adam on the logits in one jitted scan, all starts at once.
The mix is what the style language writes as "A:0.6,B:0.3,..." (generate.styles), so a found
style walks anywhere, from the command line or the page. Nothing touches the model's state.

The loss (LOSSES), in units of its value at the best known style as it is (a loss under 1 fits
better than every known style):
- "phase", for a G with a gait clock (LOSS): G walks each window at the window's measured gait
  phase (`G(curve, w, phase_BxT=...)`, as the training's reconstruction term does) and is compared
  sample for sample (0.01 MSE of root velocity + MSE of pose rows) over the samples where the phase
  is measured, so that a walker out of step with the clip is not punished for it;
- "stats", for a G without one (the paper's, NO_CLOCK_LOSS): phase-free statistics of each window
  in its walker's frame, G on its own timing (the mean and spread of every pose row, the speed of
  every row, the spread of the vertical root speed).
docs/RESULTS.md §24 measures the search on held-out real clips and on G's own walks.
"""

from __future__ import annotations

import dataclasses
import functools
import time
from typing import Sequence

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax

from motiongan_jax.analysis.clips import MotionWindows
from motiongan_jax.analysis.style_space import AnalysisError
from motiongan_jax.data import curves
from motiongan_jax.generate import walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.motion import trajectory
from motiongan_jax.motion.representation import LENGTH_UNIT_M, RowLayout

LOSSES = ("phase", "stats")  # the module doc
LOSS = "phase"  # for a G with a gait clock (search_loss)
NO_CLOCK_LOSS = "stats"  # for one without (the paper's G): it has no phase to walk at
WINDOWS = 4  # windows of the model's T per motion, spread over it
KEEP = 2  # the best styles of the screen each start a search
STEPS = 30
LR = 0.2  # Adam's peak rate on the mix's logits
VEL_WEIGHT = 0.01  # the reference's weight of root velocity against pose rows
START_WEIGHT = 0.9  # a start's mix: this much of its style, the rest shared by the others


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


def window_stats(root_vel_BxTx3, pose_BxTxR, length_unit: float = LENGTH_UNIT_M):
    """B x (3R + 1) phase-free statistics of each window in its walker's frame
    (`trajectory.window_frame`), in `length_unit`s: every pose row's mean and standard deviation
    over time, its speed (root mean square per sample, ×4), and the standard deviation of the
    vertical root velocity (×4)."""
    rv, pose = trajectory.window_frame(root_vel_BxTx3, pose_BxTxR)
    sd = lambda x, axis: jnp.sqrt(jnp.var(x, axis) + 1e-12)  # noqa: E731  (finite gradient at 0)
    speed = jnp.sqrt(jnp.mean(jnp.square(jnp.diff(pose, axis=1)), 1) + 1e-12)
    return jnp.concatenate([jnp.mean(pose, 1), sd(pose, 1), 4 * speed, 4 * sd(rv[:, 1:, 1], 1)[:, None]],
                           -1) / length_unit


def window_losses(loss: str, root_vel_BxTx3, pose_BxTxR, target_vel_BxTx3, target_pose_BxTxR, valid_BxT,
                  length_unit: float = LENGTH_UNIT_M):
    """The search's loss (LOSSES) of each of B windows: "stats" compares `window_stats`; "phase"
    compares sample for sample (VEL_WEIGHT · MSE of root velocity + MSE of pose rows, in
    `length_unit`s) over the samples `valid_BxT` marks. v[0] is left out: it is a reflected
    duplicate, not a step (trajectory.velocity)."""
    if loss == "stats":
        d = window_stats(root_vel_BxTx3, pose_BxTxR, length_unit) - window_stats(
            target_vel_BxTx3, target_pose_BxTxR, length_unit)
        return jnp.mean(jnp.square(d), -1)
    per_t = (VEL_WEIGHT * jnp.mean(jnp.square(root_vel_BxTx3 - target_vel_BxTx3), -1)
             + jnp.mean(jnp.square(pose_BxTxR - target_pose_BxTxR), -1)) / length_unit**2
    use = valid_BxT.at[:, 0].set(False).astype(per_t.dtype)
    return jnp.sum(use * per_t, 1) / jnp.maximum(jnp.sum(use, 1), 1.0)


@functools.partial(jax.jit, static_argnames=("loss", "keep", "steps"))
def _search(g, codes_CxD, vel_NxTx3, tv_NxTx3, tp_NxTxR, phase_NxT, valid_NxT, lr, *, loss: str, keep: int,
            steps: int):
    C, N = codes_CxD.shape[0], vel_NxTx3.shape[0]

    def tile(a, k):
        return jnp.tile(a, (k,) + (1,) * (a.ndim - 1))

    def mean_loss(w_KxD):
        """(K,): the loss of each code, averaged over the windows."""
        k = w_KxD.shape[0]
        vel, w = tile(vel_NxTx3, k), jnp.repeat(w_KxD, N, axis=0)
        if loss == "phase":  # G at the windows' measured phase
            rv, pose = model_apply.g_apply(g, vel, w, None, tile(phase_NxT, k))
        else:  # G on its own timing
            rv, pose = model_apply.g_apply(g, vel, w)
        per = window_losses(loss, rv, pose, tile(tv_NxTx3, k), tile(tp_NxTxR, k), tile(valid_NxT, k))
        return jnp.mean(per.reshape(k, N), 1)

    # in units of the best known style's loss as it is: a loss under 1 fits better than every one
    raw_C = mean_loss(codes_CxD)
    scale = jnp.maximum(jnp.min(raw_C), 1e-8 * jnp.max(raw_C) + 1e-30)
    screen_C = raw_C / scale
    _, top_K = jax.lax.top_k(-screen_C, keep)
    rest = (1.0 - START_WEIGHT) / max(C - 1, 1)
    logits0 = jnp.log(jnp.where(jnp.arange(C)[None] == top_K[:, None], START_WEIGHT, rest))

    def losses(logits_KxC):
        return mean_loss(jax.nn.softmax(logits_KxC, -1) @ codes_CxD) / scale

    tx = optax.adam(search_schedule(lr, steps, max(steps // 10, 1)), b1=0.5, b2=0.999)

    def body(carry, _):
        logits, opt = carry
        (_, l_K), grad = jax.value_and_grad(lambda x: (jnp.sum(losses(x)), losses(x)), has_aux=True)(logits)
        # the starts are independent: the sum's gradient wrt row k is start k's own, Adam is elementwise
        updates, opt = tx.update(grad, opt, logits)
        return (optax.apply_updates(logits, updates), opt), (l_K, logits)

    # every step's loss and the mix it was computed at: each start keeps its best step (no G call
    # after the scan, so the program compiles G's forward and backward once each)
    _, (history_SxK, logits_SxKxC) = jax.lax.scan(body, (logits0, tx.init(logits0)), None, length=steps)
    best_K = jnp.argmin(history_SxK, axis=0)
    logits_KxC = jnp.take_along_axis(logits_SxKxC, best_K[None, :, None], axis=0)[0]
    return screen_C, top_K, jax.nn.softmax(logits_KxC, -1), jnp.min(history_SxK, axis=0), history_SxK


@dataclasses.dataclass(frozen=True)
class StyleFound:
    """A motion's style as a mix of the known styles."""
    style_names: tuple[str, ...]
    loss_kind: str  # the search's loss (LOSSES)
    weights_C: np.ndarray  # the mix (sums to 1)
    w_D: np.ndarray  # its code, Σ weights_C · codes_CxD
    loss: float  # its search loss (the lowest of any step of any start)
    screen_C: np.ndarray  # every known style's loss as it is
    nearest: list  # [[name, distance], ...]: the known styles' codes nearest to w, nearest first
    starts: tuple[str, ...]  # the styles the searches started from, best screened first
    final_loss_K: np.ndarray  # each start's lowest loss
    history_KxS: np.ndarray  # each start's loss before every update
    seconds: float  # the search's wall-clock time (compiling included when it compiled)

    def mix(self, at_least: float = 0.005, digits: int = 3) -> list[list]:
        """[[name, weight], ...] by decreasing weight, the weights of at least `at_least`, rounded
        to `digits` decimals and renormalised: the style as the style language writes a mix."""
        order = [int(i) for i in np.argsort(-self.weights_C, kind="stable") if self.weights_C[i] >= at_least]
        total = float(np.sum(self.weights_C[order]))
        weights = [round(float(self.weights_C[i]) / total, digits) for i in order]
        # the largest takes what rounding left over, so the weights sum to 1 and the style language,
        # which renormalises a mix, reads back these same weights (0.843 + 2 x 0.078 would read as 0.844)
        weights[0] = round(1.0 - sum(weights[1:]), digits)
        return [[self.style_names[i], w] for i, w in zip(order, weights)]

    def mix_text(self) -> str:
        """The found style for --style and the page: "A:0.62,B:0.31,C:0.07"."""
        return ",".join(f"{n}:{a:g}" for n, a in self.mix())


def search_style(model, codes_CxD, style_names: Sequence[str], target: MotionWindows, *, loss: str | None = None,
                 keep: int = KEEP, steps: int = STEPS, lr: float = LR,
                 length_unit: float = LENGTH_UNIT_M) -> StyleFound:
    """The style of `target` (windows with their measured gait phase: `clips.windows_from_rows` with
    a layout and fps) as a mix of `codes_CxD` (the known styles' codes, z = 0:
    `style_space.label_codes(...).zero_CxD`). See the module's doc; `loss` defaults to
    `search_loss(model)`."""
    if loss is None:
        loss = search_loss(model)
    if loss not in LOSSES:
        raise ValueError(f"loss must be one of {LOSSES}, got {loss!r}")
    codes = np.asarray(codes_CxD, np.float32)
    chex.assert_rank(codes, 2)
    C = codes.shape[0]
    if len(style_names) != C:
        raise ValueError(f"{C} codes but {len(style_names)} style names")
    if steps < 1:
        raise ValueError(f"steps must be >= 1, got {steps}")
    if target.phase_NxT is None:
        raise ValueError("the target has no gait phase: cut it with a layout and fps (clips.windows_from_rows)")
    valid = np.asarray(target.phase_valid_NxT, bool)
    if loss == "phase" and not model_apply.has_gait_phase(model):
        raise ValueError("the loss 'phase' walks G at a measured phase, but this G has no gait clock")
    if loss == "phase" and valid[:, 1:].sum() == 0:
        raise AnalysisError(f"{target.source or 'the motion'}: no steps found (its toes do not alternate), "
                            "so it has no walking style to recover")
    keep = max(1, min(int(keep), C))
    host = lambda x: np.asarray(x, np.float32)  # noqa: E731  (numpy in: one compiled program per shape)
    t0 = time.perf_counter()
    screen, top, weights, final, history = _search(
        model_apply.generator_state(model), codes, host(trajectory.velocity(target.curve_NxTx3)),
        host(trajectory.velocity(target.root_NxTx3)), host(target.pose_NxTxR), host(target.phase_NxT), valid,
        host(lr), loss=loss, keep=keep, steps=int(steps))
    final = np.asarray(final)
    seconds = time.perf_counter() - t0
    if not np.isfinite(final).any():
        raise AnalysisError(f"style search diverged from every start (final losses {final})")
    best = int(np.nanargmin(final))
    a = np.asarray(weights, np.float64)[best]
    w = (a @ codes.astype(np.float64)).astype(np.float32)
    return StyleFound(tuple(style_names), loss, a, w, float(final[best]), np.asarray(screen),
                      nearest_to(w, codes, style_names, k=C), tuple(style_names[int(i)] for i in np.asarray(top)),
                      final, np.asarray(history).T, seconds)


def search_loss(model) -> str:
    """The search's loss for this model: LOSS when its G keeps a gait clock, else NO_CLOCK_LOSS."""
    return LOSS if model_apply.has_gait_phase(model) else NO_CLOCK_LOSS


def nearest_to(w_D, codes_CxD, style_names: Sequence[str], k: int = 3) -> list[list]:
    """The k known styles whose codes are nearest to w: [[name, distance], ...]."""
    d = np.linalg.norm(np.asarray(codes_CxD, np.float64) - np.asarray(w_D, np.float64)[None], axis=-1)
    order = np.argsort(d, kind="stable")[:k]
    return [[style_names[i], float(d[i])] for i in order]


def reconstruct(model, target: MotionWindows, w_D, loss: str | None = None):
    """G's (root_vel, pose) for every window of the target with one code w, walked as the search
    walks it: at the windows' measured phase under the "phase" loss, else on G's own timing."""
    loss = search_loss(model) if loss is None else loss
    N = target.curve_NxTx3.shape[0]
    w = np.broadcast_to(np.asarray(w_D, np.float32), (N, np.shape(w_D)[-1]))
    vel = trajectory.velocity(target.curve_NxTx3)
    if loss == "phase":
        return model_apply.apply_code(model, vel, w, phase_BxT=target.phase_NxT)
    return model_apply.apply_code(model, vel, w)


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
