"""The style evaluator: a small temporal CNN that scores generated motion (evaluation protocol).

It is not the discriminator (scoring with D's own class head would be circular). It reads
root-relative joint positions only, turned so that the window's travel direction (root chord,
first to last sample, on the floor) points along +z, and normalised with training-set
statistics; so it sees the body, not the path or the speed the curve dictates. It is trained only
on real training windows (the training pipeline's sampler, with its FPS augmentation), with a
fixed seed, and saved as one .npz plus a JSON sidecar carrying a SHA-256 checksum of the weights
and statistics; loading recomputes and compares it.

    conv k×R -> 64, LeakyReLU(0.2)              T
    conv k, stride 2, 64 -> 128, LeakyReLU      T/2
    conv k, stride 2, 128 -> 128, LeakyReLU     T/4
    mean over time -> features (128)            (FMD, diversity, multimodality use these)
    dense 128 -> C                               logits

The speed-free variant (`EvaluatorConfig.speed_free`, bin/train_evaluator.py --speed-free) has
the same layers with kernel 1 and stride 1: each frame's pose is scored alone and the window's
features are the mean over its frames. It sees which poses a walk passes through, not how fast:
no travel speed (the root enters only through the heading), no cadence and no joint speed can be
read off an unordered set of root-relative poses. A generator that follows a curve cannot choose
its speed, so this one does not credit a style for the speed the curve dictates.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
from pathlib import Path
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx

from motiongan_jax import atomic
from motiongan_jax.data import curves
from motiongan_jax.motion import trajectory

FORMAT_VERSION = 1


class EvaluatorError(ValueError):
    """A missing, corrupt or incompatible evaluator file."""


@dataclasses.dataclass(frozen=True)
class EvaluatorConfig:
    channels: tuple[int, int, int] = (64, 128, 128)
    kernel: int = 5
    steps: int = 1500
    batch_size: int = 64
    lr: float = 1e-3
    seed: int = 0
    speed_free: bool = False  # per-frame poses, averaged: no time order (module doc)


# ---------------------------------------------------------------------------------------------
# Input canonicalisation
# ---------------------------------------------------------------------------------------------


def canonical_pose(root_NxTx3: jax.Array, pose_NxTxR: jax.Array) -> jax.Array:
    """Root-relative rows turned about +y so that every window walks along +z: D's window frame
    (`trajectory.window_frame`) of the root's velocity."""
    return trajectory.window_frame(trajectory.velocity(root_NxTx3), jnp.asarray(pose_NxTxR))[1]


# ---------------------------------------------------------------------------------------------
# The network
# ---------------------------------------------------------------------------------------------


class StyleClassifier(nnx.Module):
    def __init__(self, num_rows: int, num_styles: int, cfg: EvaluatorConfig, *, rngs: nnx.Rngs):
        c1, c2, c3 = cfg.channels
        k, s = (1, 1) if cfg.speed_free else (cfg.kernel, 2)
        self.conv1 = nnx.Conv(num_rows, c1, (k,), padding="SAME", rngs=rngs)
        self.conv2 = nnx.Conv(c1, c2, (k,), strides=(s,), padding="SAME", rngs=rngs)
        self.conv3 = nnx.Conv(c2, c3, (k,), strides=(s,), padding="SAME", rngs=rngs)
        self.head = nnx.Linear(c3, num_styles, rngs=rngs)

    def features(self, x_NxTxR: jax.Array) -> jax.Array:
        h = jax.nn.leaky_relu(self.conv1(x_NxTxR), 0.2)
        h = jax.nn.leaky_relu(self.conv2(h), 0.2)
        h = jax.nn.leaky_relu(self.conv3(h), 0.2)
        return jnp.mean(h, axis=1)

    def __call__(self, x_NxTxR: jax.Array) -> tuple[jax.Array, jax.Array]:
        f = self.features(x_NxTxR)
        return self.head(f), f


@dataclasses.dataclass(frozen=True, eq=False)
class Evaluator:
    graphdef: nnx.GraphDef
    params: nnx.State
    mean_R: np.ndarray
    std_R: np.ndarray
    meta: dict  # style_names, joint_names, window_T, frame_step, fps, accuracy, files, ...

    @property
    def style_names(self) -> tuple[str, ...]:
        return tuple(self.meta["style_names"])

    @property
    def checksum(self) -> str:
        return checksum(self.params, self.mean_R, self.std_R)


def _inputs(root_NxTx3, pose_NxTxR, mean_R, std_R):
    return (canonical_pose(root_NxTx3, pose_NxTxR) - mean_R) / std_R


@functools.partial(jax.jit, static_argnums=0)
def _apply(graphdef, params, mean_R, std_R, root_NxTx3, pose_NxTxR):
    model = nnx.merge(graphdef, params)
    return model(_inputs(root_NxTx3, pose_NxTxR, mean_R, std_R))


def classify(ev: Evaluator, root_NxTx3, pose_NxTxR, batch: int = 256) -> tuple[np.ndarray, np.ndarray]:
    """(logits N x C, features N x F) of windows given as world roots (only the heading is used)
    and root-relative rows, metres. T should be the evaluator's window length."""
    root = np.asarray(root_NxTx3, np.float32)
    pose = np.asarray(pose_NxTxR, np.float32)
    if root.ndim != 3 or pose.ndim != 3 or root.shape[:2] != pose.shape[:2]:
        raise EvaluatorError(f"windows must be N x T x 3 and N x T x R, got {root.shape} and {pose.shape}")
    if pose.shape[2] != len(ev.mean_R):
        raise EvaluatorError(f"the evaluator reads {len(ev.mean_R)} pose rows, got {pose.shape[2]}")
    logits, feats = [], []
    for i in range(0, len(root), batch):
        r, p = root[i:i + batch], pose[i:i + batch]
        n = len(r)
        # padded to a multiple of 64 rows so that a few compiled shapes serve every call
        pad = -n % 64
        if pad:
            r = np.concatenate([r, np.repeat(r[-1:], pad, 0)])
            p = np.concatenate([p, np.repeat(p[-1:], pad, 0)])
        lo, fe = _apply(ev.graphdef, ev.params, ev.mean_R, ev.std_R, r, p)
        logits.append(np.asarray(lo)[:n])
        feats.append(np.asarray(fe)[:n])
    if not logits:
        return np.zeros((0, len(ev.style_names)), np.float32), np.zeros((0, 0), np.float32)
    return np.concatenate(logits), np.concatenate(feats)


# ---------------------------------------------------------------------------------------------
# Training
# ---------------------------------------------------------------------------------------------


def _stats(sample: Callable, key, count: int = 8):
    poses = [np.asarray(canonical_pose(b["root_BxTx3"], b["pose_BxTxR"])) for b in
             (sample(key, i) for i in range(count))]
    p = np.concatenate(poses).reshape(-1, poses[0].shape[-1])
    # a floor on the spread keeps near-constant rows (e.g. a fixed end site) from blowing up
    return p.mean(0).astype(np.float32), np.maximum(p.std(0), 1e-3).astype(np.float32)


def train(sample_batch: Callable, num_rows: int, style_names: Sequence[str], ecfg: EvaluatorConfig,
          *, log: Callable[[str], None] | None = None, meta: dict | None = None) -> Evaluator:
    """Trains the evaluator on batches from `sample_batch(key, step) -> Batch` (real training
    windows; see data.make_sample_batch). Deterministic given ecfg.seed."""
    key = jax.random.key(ecfg.seed)
    k_init, k_data, k_stats = jax.random.split(key, 3)
    mean_R, std_R = _stats(sample_batch, k_stats)
    model = StyleClassifier(num_rows, len(style_names), ecfg, rngs=nnx.Rngs(k_init))
    graphdef, params = nnx.split(model, nnx.Param)
    tx = optax.adam(ecfg.lr)
    opt = tx.init(params)

    @jax.jit
    def step(params, opt, batch):
        def loss_fn(p):
            logits, _ = nnx.merge(graphdef, p)(_inputs(batch["root_BxTx3"], batch["pose_BxTxR"], mean_R, std_R))
            loss = jnp.mean(optax.softmax_cross_entropy_with_integer_labels(logits, batch["label_B"]))
            return loss, jnp.mean(jnp.argmax(logits, -1) == batch["label_B"])

        (loss, acc), grads = jax.value_and_grad(loss_fn, has_aux=True)(params)
        updates, opt = tx.update(grads, opt, params)
        return optax.apply_updates(params, updates), opt, loss, acc

    for i in range(ecfg.steps):
        params, opt, loss, acc = step(params, opt, sample_batch(k_data, i))
        if log and (i + 1) % max(ecfg.steps // 10, 1) == 0:
            log(f"evaluator step {i + 1}/{ecfg.steps}: loss {float(loss):.4f}, batch accuracy {float(acc):.3f}")
    full_meta = {"format_version": FORMAT_VERSION, "style_names": list(style_names),
                 "config": dataclasses.asdict(ecfg), **(meta or {})}
    return Evaluator(graphdef, params, mean_R, std_R, full_meta)


# ---------------------------------------------------------------------------------------------
# Saving and loading (checksummed)
# ---------------------------------------------------------------------------------------------


def _flat(params) -> dict[str, np.ndarray]:
    flat = {}

    def walk(prefix, node):
        if isinstance(node, dict):
            for k in sorted(node, key=str):
                walk(f"{prefix}/{k}" if prefix else str(k), node[k])
        else:
            flat[prefix] = np.asarray(node, np.float32)

    walk("", nnx.to_pure_dict(params) if not isinstance(params, dict) else params)
    return flat


def checksum(params, mean_R, std_R) -> str:
    """SHA-256 over every weight (sorted by name, float32 little-endian) and the statistics."""
    h = hashlib.sha256()
    for name, arr in sorted(_flat(params).items()):
        h.update(name.encode())
        h.update(np.ascontiguousarray(arr, "<f4").tobytes())
    for arr in (mean_R, std_R):
        h.update(np.ascontiguousarray(arr, "<f4").tobytes())
    return h.hexdigest()


def save(ev: Evaluator, path: str | Path) -> tuple[Path, Path]:
    """Writes PATH (.npz: weights and statistics) and PATH with .json (meta and checksum), each
    atomically. Returns both paths."""
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_suffix(".npz")
    arrays = {f"param:{k}": v for k, v in _flat(ev.params).items()}
    arrays["mean_R"], arrays["std_R"] = ev.mean_R, ev.std_R
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic.atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays)
    side = path.with_suffix(".json")
    atomic.write_json(side, {**ev.meta, "checksum": ev.checksum}, indent=2)
    return path, side


def _unflatten(flat: dict[str, np.ndarray]) -> dict:
    tree: dict = {}
    for name, arr in flat.items():
        node = tree
        parts = name.split("/")
        for p in parts[:-1]:
            node = node.setdefault(int(p) if p.isdigit() else p, {})
        node[int(parts[-1]) if parts[-1].isdigit() else parts[-1]] = jnp.asarray(arr)
    return tree


def load(path: str | Path) -> Evaluator:
    """Loads and verifies an evaluator; a missing file, wrong format or checksum mismatch raises
    EvaluatorError naming the problem."""
    path = Path(path)
    if path.suffix != ".npz":
        path = path.with_suffix(".npz")
    side = path.with_suffix(".json")
    for p in (path, side):
        if not p.is_file():
            raise EvaluatorError(f"{p}: no such file (train one with bin/train_evaluator.py)")
    try:
        meta = json.loads(side.read_text())
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError) as err:
        raise EvaluatorError(f"{path}: cannot read the evaluator ({err})") from None
    if meta.get("format_version") != FORMAT_VERSION:
        raise EvaluatorError(f"{side}: format version {meta.get('format_version')}, this code reads {FORMAT_VERSION}")
    ecfg = EvaluatorConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in meta["config"].items()})
    mean_R, std_R = arrays.pop("mean_R"), arrays.pop("std_R")
    flat = {k[len("param:"):]: v for k, v in arrays.items() if k.startswith("param:")}
    model = nnx.eval_shape(lambda: StyleClassifier(len(mean_R), len(meta["style_names"]), ecfg, rngs=nnx.Rngs(0)))
    graphdef, abstract = nnx.split(model, nnx.Param)
    tree = _unflatten(flat)
    try:
        nnx.replace_by_pure_dict(abstract, tree)
    except (KeyError, ValueError, TypeError) as err:
        raise EvaluatorError(f"{path}: weights do not fit the evaluator network ({err})") from None
    ev = Evaluator(graphdef, abstract, mean_R.astype(np.float32), std_R.astype(np.float32), meta)
    if ev.checksum != meta.get("checksum"):
        raise EvaluatorError(f"{path}: checksum mismatch (file {ev.checksum[:12]}…, recorded "
                             f"{str(meta.get('checksum'))[:12]}…): the weights were changed or damaged")
    return ev


# ---------------------------------------------------------------------------------------------
# Real windows (held-out data)
# ---------------------------------------------------------------------------------------------


def clip_windows(root_Fx3, pose_FxR, T: int, frame_step: int, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """Every window of T samples `frame_step` frames apart, starting every `stride` frames."""
    frames = curves.window_indices(len(root_Fx3), T, frame_step, stride)
    return np.asarray(root_Fx3, np.float32)[frames], np.asarray(pose_FxR, np.float32)[frames]


def real_windows(clips, style_names: Sequence[str], T: int, frame_step: int, stride: int | None = None):
    """(root N x T x 3, pose N x T x R, labels N, clip index N) of a list of data.Clip."""
    stride = stride or max(T * frame_step // 2, 1)
    index = {s: i for i, s in enumerate(style_names)}
    roots, poses, labels, owner = [], [], [], []
    for c, clip in enumerate(clips):
        r, p = clip_windows(clip.root_Fx3, clip.pose_FxR, T, frame_step, stride)
        roots.append(r)
        poses.append(p)
        labels.append(np.full(len(r), index[clip.label.style], np.int32))
        owner.append(np.full(len(r), c, np.int32))
    return np.concatenate(roots), np.concatenate(poses), np.concatenate(labels), np.concatenate(owner)
