"""The learned style space: codes, PCA, distances, blending, a linear probe, and style search.

docs/DESIGN.md §5.2 (analysis) and §5.3 (style search), with the reference's bugs fixed (§6).
All numerics are jnp; plots live in `viz.py`, files are written by `analysis_report.py`.

Style codes. w = LT(label, z) (`generate.latent_codes`): `label_codes` gives, for every label,
w at z = 0 (what the inference tools use) and K codes from z ~ N(0, I), whose mean is the
style's *centroid*.

Blending. The AdaIN scale and bias of every layer are affine in w (s = A_s w + a_s,
b = A_b w + a_b), so blending codes with weights that sum to 1 (`interpolate`, `mix`) gives
exactly the generator output of blending each AdaIN's (s, b) with the same weights (the
reference's AdaIN-space method). `generator_apply_adain` runs G with per-layer (s, b) so the two
can be compared; `arithmetic` (Σ ±w, weights need not sum to 1) has no such twin.

Linear probe. Least squares with an intercept from codes to known quantities (the embedded
dataset's gait parameters), scored by the cross-validated R² of each target
(leave-one-group-out or K-fold), optionally on the training fold's leading principal components
so that a few points in a wide code space still give a well-posed fit.

Style search. Recover a code for an unlabelled motion: cut it into the model's windows (its T,
its frame step, the noise-free curve of each window, aligned with the motion exactly as in
training), then minimise a reconstruction loss through G over w alone with optax Adam (linear
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
import json
import math
from pathlib import Path
from typing import NamedTuple, Sequence

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import nnx

from motiongan_jax import curves, generate, step as step_lib
from motiongan_jax.nn.layers import AdaIN
from motiongan_jax.representation import LENGTH_UNIT_M, RowLayout, from_rows, to_rows


class AnalysisError(ValueError):
    """A problem with analysis inputs (a motion that does not fit the model, a short clip, ...)."""


# ---------------------------------------------------------------------------------------------
# Style codes
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class StyleCodes:
    style_names: tuple[str, ...]
    zero_CxD: jax.Array  # w = LT(label, z = 0)
    samples_CxKxD: jax.Array  # w = LT(label, z_k), z_k ~ N(0, I)

    @property
    def centroids_CxD(self) -> jax.Array:
        return jnp.mean(self.samples_CxKxD, axis=1)

    @property
    def flat_samples(self) -> tuple[jax.Array, jax.Array]:
        """(samples (C·K) x D, their labels (C·K,))."""
        C, K, D = self.samples_CxKxD.shape
        return self.samples_CxKxD.reshape(C * K, D), jnp.repeat(jnp.arange(C, dtype=jnp.int32), K)


def label_codes(state, style_names: Sequence[str], k: int = 10, key: jax.Array | None = None) -> StyleCodes:
    """w at z = 0 and K codes per label (z ~ N(0, I) from `key`, default key 0)."""
    C = len(style_names)
    if C < 1 or k < 1:
        raise ValueError(f"need at least one style and k >= 1 (got {C} styles, k={k})")
    Z = step_lib.generator_z_dim(state)
    labels = jnp.arange(C, dtype=jnp.int32)
    zero = generate.latent_codes(state, labels, jnp.zeros((C, Z), jnp.float32))
    rep = jnp.repeat(labels, k)
    z = jax.random.normal(jax.random.key(0) if key is None else key, (C * k, Z), jnp.float32)
    samples = generate.latent_codes(state, rep, z).reshape(C, k, -1)
    chex.assert_shape(samples, (C, k, zero.shape[-1]))
    return StyleCodes(tuple(style_names), zero, samples)


# ---------------------------------------------------------------------------------------------
# PCA and distances
# ---------------------------------------------------------------------------------------------


class PCA(NamedTuple):
    mean_D: jax.Array
    components_KxD: jax.Array  # orthonormal rows, by decreasing variance
    singular_values_K: jax.Array
    explained_variance_K: jax.Array  # variance along each component (ddof = 1, like sklearn)
    explained_variance_ratio_K: jax.Array  # of the total variance; sums to <= 1


def pca(X_NxD, num_components: int | None = None) -> PCA:
    """PCA by `jnp.linalg.svd` of the centred data. Signs are fixed: the largest-magnitude entry of
    each component is positive. num_components defaults to min(N, D)."""
    X = jnp.asarray(X_NxD, jnp.float32)
    chex.assert_rank(X, 2)
    N, D = X.shape
    k = min(N, D) if num_components is None else int(num_components)
    if not 1 <= k <= min(N, D):
        raise ValueError(f"num_components must be in 1..{min(N, D)} for {N} points in {D}-D, got {k}")
    return _pca(X, k)


@functools.partial(jax.jit, static_argnames="k")
def _pca(X, k: int) -> PCA:
    N = X.shape[0]
    mean = jnp.mean(X, axis=0)
    Xc = X - mean
    _, S, Vt = jnp.linalg.svd(Xc, full_matrices=False)
    pivot = jnp.take_along_axis(Vt, jnp.argmax(jnp.abs(Vt), axis=1)[:, None], axis=1)[:, 0]
    Vt = Vt * jnp.where(pivot < 0, -1.0, 1.0)[:, None]
    var = jnp.square(S) / max(N - 1, 1)
    total = jnp.sum(var)
    ratio = jnp.where(total > 0, var / jnp.where(total > 0, total, 1.0), 0.0)
    return PCA(mean, Vt[:k], S[:k], var[:k], ratio[:k])


def pca_transform(p: PCA, X_NxD) -> jax.Array:
    return (jnp.asarray(X_NxD, jnp.float32) - p.mean_D) @ p.components_KxD.T


def pairwise_distances(X_CxD) -> jax.Array:
    """Euclidean distances between rows, C x C (exact zeros on the diagonal)."""
    X = jnp.asarray(X_CxD, jnp.float32)
    chex.assert_rank(X, 2)
    return jnp.sqrt(jnp.sum(jnp.square(X[:, None, :] - X[None, :, :]), axis=-1))


def nearest_styles(dist_CxC, style_names: Sequence[str], k: int = 3) -> list[dict]:
    """For each style, its k nearest other styles: [{"style", "nearest": [[name, distance], ...]}]."""
    d = np.asarray(dist_CxC, np.float64)
    C = len(style_names)
    chex.assert_shape(d, (C, C))
    out = []
    for i, name in enumerate(style_names):
        others = [j for j in np.argsort(d[i], kind="stable") if j != i][:k]
        out.append({"style": name, "nearest": [[style_names[j], float(d[i, j])] for j in others]})
    return out


def nearest_markdown(nearest: list[dict], title: str = "Nearest styles (Euclidean distance between "
                     "w centroids)") -> str:
    """The paper's Table 1 as Markdown: one row per style, its nearest styles with distances."""
    k = max((len(r["nearest"]) for r in nearest), default=0)
    ordinal = ["1st", "2nd", "3rd"] + [f"{i}th" for i in range(4, k + 1)]
    lines = [f"# {title}", "", "| style | " + " | ".join(ordinal[:k]) + " |",
             "|---|" + "---|" * k]
    for r in nearest:
        cells = [f"{n} ({d:.3g})" for n, d in r["nearest"]] + [""] * (k - len(r["nearest"]))
        lines.append(f"| {r['style']} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


# ---------------------------------------------------------------------------------------------
# Blending in w and in AdaIN space
# ---------------------------------------------------------------------------------------------


def interpolate(w_a, w_b, alpha):
    """(1 - α) w_a + α w_b. α may be an array (e.g. linspace): the result gets its shape + (D,)."""
    a = jnp.asarray(alpha, jnp.float32)[..., None]
    return (1.0 - a) * jnp.asarray(w_a) + a * jnp.asarray(w_b)


def mix(ws, weights, *, normalize: bool = False):
    """Σ_i weights_i ws_i over the first axis of ws (N x ... x D); normalize divides the weights by
    their sum first. Weights summing to 1 make it a blend (the same output as blending AdaINs)."""
    ws = jnp.asarray(ws, jnp.float32)
    wts = jnp.asarray(weights, jnp.float32)
    chex.assert_shape(wts, (ws.shape[0],))
    if normalize:
        wts = wts / jnp.sum(wts)
    return jnp.tensordot(wts, ws, axes=1)


def arithmetic(terms: Sequence[tuple]):
    """Σ sign · w over (sign, w) terms; sign is +1/-1 (or "+"/"-"), e.g. [("+", a), ("-", b), ("+", c)]."""
    if not terms:
        raise ValueError("arithmetic needs at least one (sign, w) term")
    total = None
    for sign, w in terms:
        s = {"+": 1.0, "-": -1.0}.get(sign, sign) if isinstance(sign, str) else float(sign)
        if s not in (1.0, -1.0):
            raise ValueError(f"sign must be +1/-1 or '+'/'-', got {sign!r}")
        term = s * jnp.asarray(w, jnp.float32)
        total = term if total is None else total + term
    return total


def adain_styles(state, w_BxD) -> dict[str, tuple[jax.Array, jax.Array]]:
    """(s, b) of every AdaIN layer of G for the codes w, keyed by block name."""
    return step_lib.generator(state).adain_styles(jnp.asarray(w_BxD, jnp.float32))


def blend_adain(styles: Sequence[dict], weights) -> dict[str, tuple[jax.Array, jax.Array]]:
    """Σ_i weights_i (s_i, b_i), layer by layer (the reference's AdaIN-space blending)."""
    wts = [float(x) for x in np.asarray(weights, np.float64).reshape(-1)]
    if len(wts) != len(styles):
        raise ValueError(f"{len(styles)} style dicts but {len(wts)} weights")
    return jax.tree.map(lambda *leaves: sum(w * x for w, x in zip(wts, leaves)), *styles)


class _FixedAdaIN(AdaIN):
    """An AdaIN whose (s, b) are given instead of computed from w. It inherits AdaIN.__call__, so
    the normalisation and modulation are exactly the real layer's; only `style` is replaced."""

    def __init__(self, s_BxC: jax.Array, b_BxC: jax.Array):  # no parameters: AdaIN.__init__ not run
        self.s_BxC = nnx.data(s_BxC)
        self.b_BxC = nnx.data(b_BxC)

    def style(self, w_BxD):
        del w_BxD
        return self.s_BxC, self.b_BxC


def generator_apply_adain(state, curve_vel_BxTx3, adain: dict, w_BxD=None):
    """(root_vel, pose) from G with the given (s_BxC, b_BxC) in the named AdaIN layers.

    Layers not in `adain` use `w_BxD` (required then). Works on a private copy of G: the AdaIN
    modules of that copy are swapped for fixed ones (nn/generator.py has no override hook).
    """
    g = step_lib.generator(state)
    unknown = set(adain) - set(g.BLOCKS)
    if unknown:
        raise ValueError(f"unknown AdaIN block(s) {sorted(unknown)}; G has {g.BLOCKS}")
    missing = [n for n in g.BLOCKS if n not in adain]
    if missing and w_BxD is None:
        raise ValueError(f"no (s, b) for {missing} and no w_BxD to compute them")
    B = curve_vel_BxTx3.shape[0]
    for name, (s, b) in adain.items():
        block = getattr(g, name)
        C = block.adain.scale.kernel.shape[-1]
        chex.assert_shape([s, b], (B, C))
        block.adain = _FixedAdaIN(jnp.asarray(s, jnp.float32), jnp.asarray(b, jnp.float32))
    w = jnp.zeros((B, g.w_dim), jnp.float32) if w_BxD is None else jnp.asarray(w_BxD, jnp.float32)
    return g(curve_vel_BxTx3, w)


# ---------------------------------------------------------------------------------------------
# Linear probe
# ---------------------------------------------------------------------------------------------


class ProbeResult(NamedTuple):
    r2_P: np.ndarray  # cross-validated R² per target (pooled out-of-fold predictions)
    r2_train_P: np.ndarray  # in-sample R² of the fit on all points (same feature reduction)
    pred_NxP: np.ndarray  # out-of-fold predictions
    num_folds: int
    components: int | None  # features used per fold (None: the raw codes)


@jax.jit
def _r2(Y, P):
    ss_res = jnp.sum(jnp.square(Y - P), axis=0)
    ss_tot = jnp.sum(jnp.square(Y - jnp.mean(Y, axis=0)), axis=0)
    return jnp.where(ss_tot > 0, 1.0 - ss_res / jnp.where(ss_tot > 0, ss_tot, 1.0), jnp.nan)


@functools.partial(jax.jit, static_argnames="k")
def _fit_predict(X_tr, Y_tr, X_te, k: int | None):
    mean = jnp.mean(X_tr, axis=0)
    if k is None:
        F_tr, F_te = X_tr - mean, X_te - mean
    else:
        basis = pca(X_tr, min(k, *X_tr.shape)).components_KxD
        F_tr, F_te = (X_tr - mean) @ basis.T, (X_te - mean) @ basis.T
    # Unit-variance features: codes can be tiny (|w| ~ 1e-5 early in training), and lstsq's
    # relative cut-off would otherwise drop them against the intercept column.
    sd = jnp.std(F_tr, axis=0)
    sd = jnp.where(sd > 0, sd, 1.0)
    F_tr, F_te = F_tr / sd, F_te / sd
    A = jnp.concatenate([jnp.ones((F_tr.shape[0], 1), F_tr.dtype), F_tr], axis=1)
    coef, *_ = jnp.linalg.lstsq(A, Y_tr)
    return coef[0] + F_te @ coef[1:]


def linear_probe(X_NxD, Y_NxP, *, groups_N=None, folds: int = 5, components: int | str | None = "auto",
                 key: jax.Array | None = None) -> ProbeResult:
    """Cross-validated least squares with an intercept from X to each column of Y.

    groups_N: leave-one-group-out (e.g. one style at a time: its points never train the map that
      predicts them); else K-fold (`folds`) over a permutation from `key` (default key 0).
    components: fit on that many leading principal components of the training fold's X;
      "auto" = min(D, (n_train - 1) // 2) with n_train the number of distinct training groups
      (points without groups): at least two independent points per fitted coefficient; None =
      the raw codes (min-norm lstsq). Features are scaled to unit variance on the training fold.
    """
    X = jnp.asarray(X_NxD, jnp.float32)
    Y = jnp.asarray(Y_NxP, jnp.float32)
    chex.assert_rank([X, Y], 2)
    N, D = X.shape
    chex.assert_shape(Y, (N, None))
    if groups_N is not None:
        g = np.asarray(groups_N)
        chex.assert_shape(g, (N,))
        _, fold = np.unique(g, return_inverse=True)
        num_folds = int(fold.max()) + 1
        if num_folds < 3:
            raise ValueError(f"leave-one-group-out needs >= 3 groups, got {num_folds}")
    else:
        num_folds = int(folds)
        if not 2 <= num_folds <= N:
            raise ValueError(f"folds must be in 2..{N}, got {folds}")
        perm = np.asarray(jax.random.permutation(jax.random.key(0) if key is None else key, N))
        fold = np.empty(N, np.int64)
        fold[perm] = np.arange(N) % num_folds
    groups = fold if groups_N is not None else np.arange(N)

    def k_for(train_mask):
        if components is None:
            return None
        if components == "auto":
            n_eff = len(np.unique(groups[train_mask]))
            return max(1, min(D, (n_eff - 1) // 2))
        return max(1, min(int(components), D))

    # Fold bookkeeping on the host; every fit is one jitted jnp function (compiled once per shape).
    Xh, Yh = np.asarray(X), np.asarray(Y)
    pred = np.zeros_like(Yh)
    ks = []
    for f in range(num_folds):
        te = fold == f
        k = k_for(~te)
        ks.append(k)
        pred[te] = np.asarray(_fit_predict(Xh[~te], Yh[~te], Xh[te], k))
    k_all = k_for(np.ones(N, bool))
    r2_train = _r2(Yh, _fit_predict(Xh, Yh, Xh, k_all))
    return ProbeResult(np.asarray(_r2(Yh, jnp.asarray(pred))), np.asarray(r2_train), pred, num_folds,
                       None if ks[0] is None else int(min(ks)))


def gait_parameters(meta: dict, cfg) -> dict | None:
    """Ground-truth gait parameters of the embedded dataset, or None for other data.

    {"param_names": [...], "style_YxP": (C, P) per label, "clips": {clip_name: (P,)}}: the
    GaitParams fields plus the derived speed (m/s = stride_length · cadence / 2). Read from the
    dataset's styles.json when it is at meta["data_dir"]; otherwise, for a run on the default
    embedded dataset, the per-style values come from `synthetic.STYLES` (no clips)."""
    from motiongan_jax import synthetic

    styles = list(meta["style_names"])
    manifest = None
    data_dir = meta.get("data_dir")
    if data_dir and (Path(data_dir) / "styles.json").is_file():
        try:
            manifest = json.loads((Path(data_dir) / "styles.json").read_text())
        except (OSError, json.JSONDecodeError):
            manifest = None
        if manifest is not None and manifest.get("generator") != "motiongan_jax.synthetic":
            return None
    names = list(synthetic.PARAM_NAMES)
    if manifest is not None:
        table = manifest.get("styles", {})
        clips = manifest.get("clips", {})
    elif cfg.data.data_dir is None and cfg.data.label_rule == "synthetic":
        table = {s: p.to_dict() for s, p in synthetic.STYLES.items()}
        clips = {}
    else:
        return None
    if any(s not in table for s in styles):
        return None

    def row(v: dict) -> list[float]:  # the parameters, then the derived walking speed
        return [float(v[n]) for n in names] + [float(v["stride_length"]) * float(v["cadence"]) / 2.0]

    Y = np.array([row(table[s]) for s in styles], np.float64)
    return {"param_names": names + ["speed"], "style_YxP": Y,
            "clips": {c: np.array(row(v), np.float64) for c, v in clips.items()}}


def probe_report(codes: StyleCodes, gait: dict) -> dict:
    """R² per gait parameter of two probes: per style (centroids, leave-one-out) and per w sample
    (leave-one-style-out). Targets are standardised (R² does not change) for conditioning."""
    Y = np.asarray(gait["style_YxP"], np.float64)
    sd = Y.std(axis=0)
    Yn = (Y - Y.mean(axis=0)) / np.where(sd > 0, sd, 1.0)
    X_s, labels = codes.flat_samples
    C = len(codes.style_names)
    per_style = linear_probe(codes.centroids_CxD, Yn, groups_N=np.arange(C))
    per_sample = linear_probe(X_s, Yn[np.asarray(labels)], groups_N=np.asarray(labels))
    names = gait["param_names"]

    def table(res: ProbeResult) -> dict:
        return {"r2_cv": {n: _num(v) for n, v in zip(names, res.r2_P)},
                "r2_train": {n: _num(v) for n, v in zip(names, res.r2_train_P)},
                "mean_r2_cv": _num(np.nanmean(res.r2_P)), "folds": res.num_folds,
                "components": res.components}

    return {"per_style": {"points": C, "cv": "leave-one-style-out", **table(per_style)},
            "per_sample": {"points": int(X_s.shape[0]), "cv": "leave-one-style-out", **table(per_sample)}}


def _num(x) -> float | None:
    x = float(x)
    return x if math.isfinite(x) else None


# ---------------------------------------------------------------------------------------------
# Style search: targets
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class MotionWindows:
    """A motion cut into the model's windows, float32 metres. Window n covers source frames
    start_frames[n] + frame_step · t, t < T; its curve is the noise-free training curve of exactly
    those frames (point 0 = the root's floor position at the first frame)."""
    root_NxTx3: jax.Array
    pose_NxTxR: jax.Array
    curve_NxTx3: jax.Array
    start_frames: np.ndarray
    frame_step: int
    source: str = ""

    @property
    def spacing_m(self) -> float:
        """Mean curve length per network sample (the motion's speed per sample)."""
        d = jnp.linalg.norm(jnp.diff(self.curve_NxTx3, axis=1), axis=-1)
        return float(jnp.mean(d))


_clean_curves = jax.jit(functools.partial(curves.window_curves, noise=0.0, key=None),
                        static_argnames=("T", "interval"))


def windows_from_rows(root_Fx3, pose_FxR, *, T: int, frame_step: int, interval: int,
                      max_windows: int | None = None, source: str = "") -> MotionWindows:
    """Non-overlapping windows (each T samples, frame_step apart; the next starts T·frame_step
    frames later) with their noise-free curves (`curves.window_curves`, as in training)."""
    root = np.asarray(root_Fx3, np.float32)
    pose = np.asarray(pose_FxR, np.float32)
    F = len(root)
    span = (T - 1) * frame_step + 1
    frames = curves.window_indices(F, T, frame_step, max_windows=max_windows)
    if len(frames) == 0:
        raise AnalysisError(f"{source or 'motion'}: {F} frames is shorter than one window "
                            f"({T} samples x step {frame_step} = {span} frames)")
    starts, count = frames[:, 0], len(frames)
    path_frames = starts[:, None] + np.arange(span)[None, :]
    xz = _clean_curves(root[path_frames][..., [0, 2]], np.full(count, span, np.int32), T=int(T),
                       interval=int(interval))
    curve = curves.on_floor(xz)
    return MotionWindows(jnp.asarray(root[frames]), jnp.asarray(pose[frames]), curve.astype(jnp.float32),
                         starts, int(frame_step), source)


def load_motion(path, meta: dict, cfg, layout: RowLayout, *, units_to_m: float | None = None,
                clip: int = 0) -> tuple[np.ndarray, np.ndarray, float]:
    """(root_Fx3, pose_FxR, fps) in metres of a BVH file or an .npz of world positions.

    BVH: preprocessed as in training (data.preprocess_clip with the run's units and start
    offset; no cache). Its kept joints must be the model's. npz: `positions` (F x J x 3, metres),
    either the model's kept joints in order or a full skeleton with `joint_names` (e.g. the
    output of bin/prepare_data.py; `clip_start`/`clip_length` select clip `clip`); `fps`
    defaults to the run's.
    """
    from motiongan_jax import data

    path = Path(path)
    if not path.is_file():
        raise AnalysisError(f"{path}: no such file")
    names = tuple(layout.joint_names)
    if path.suffix.lower() == ".bvh":
        units = data.units_for(cfg.data) if units_to_m is None else float(units_to_m)
        c = data.preprocess_clip(path, data.FileLabel(style="?", trial=0), units, cfg.data.start_offset,
                                 use_cache=False)
        if tuple(c.layout.joint_names) != names:
            raise AnalysisError(f"{path}: its skeleton keeps joints {c.layout.joint_names}, the model "
                                f"needs {names}")
        return np.asarray(c.root_Fx3, np.float64), np.asarray(c.pose_FxR, np.float64), float(c.fps)
    if path.suffix.lower() != ".npz":
        raise AnalysisError(f"{path}: expected a .bvh or an .npz of world positions")
    try:
        with np.load(path, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
    except (OSError, ValueError) as err:
        raise AnalysisError(f"{path}: cannot read ({err})") from None
    if "positions" not in arrays:
        raise AnalysisError(f"{path}: no 'positions' array (has {sorted(arrays)})")
    pos = np.asarray(arrays["positions"], np.float64)
    if "clip_start" in arrays and "clip_length" in arrays:
        starts, lengths = arrays["clip_start"], arrays["clip_length"]
        if not 0 <= clip < len(starts):
            raise AnalysisError(f"{path}: clip {clip} out of range (0..{len(starts) - 1})")
        pos = pos[int(starts[clip]): int(starts[clip]) + int(lengths[clip])]
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise AnalysisError(f"{path}: positions must be (frames, joints, 3), got {pos.shape}")
    if "joint_names" in arrays:
        file_names = [str(s) for s in arrays["joint_names"]]
        missing = [n for n in names if n not in file_names]
        if missing:
            raise AnalysisError(f"{path}: joints {missing} of the model are not in its joint_names")
        pos = pos[:, [file_names.index(n) for n in names]]
    elif pos.shape[1] != len(names):
        raise AnalysisError(f"{path}: {pos.shape[1]} joints without joint_names; the model has "
                            f"{len(names)} ({', '.join(names)})")
    if not np.isfinite(pos).all():
        raise AnalysisError(f"{path}: positions contain NaN or inf")
    kept = dataclasses.replace(layout, source_index=tuple(range(len(names))))
    root, pose = to_rows(pos, kept)
    fps = float(arrays["fps"]) if "fps" in arrays else float(meta.get("fps", 0) or 0)
    if not fps > 0:
        raise AnalysisError(f"{path}: no fps in the file and none in the run's metadata")
    return root, pose, fps


def motion_windows(path, meta: dict, cfg, layout: RowLayout, *, max_windows: int | None = 8,
                   units_to_m: float | None = None, clip: int = 0, T: int | None = None) -> MotionWindows:
    """`load_motion` + `windows_from_rows` with the model's T (or `T`, a multiple of 8: G is
    convolutional in time), frame step and spline interval, the last two scaled by the clip's
    fps over the training fps (so a 120 fps clip is sampled at the training's rate too)."""
    T = cfg.data.window_T if T is None else int(T)
    if T < 16 or T % 8:
        raise AnalysisError(f"window length T must be a multiple of 8 and >= 16, got {T}")
    root, pose, fps = load_motion(path, meta, cfg, layout, units_to_m=units_to_m, clip=clip)
    ratio = fps / float(meta.get("fps") or fps)
    step = max(1, int(round(cfg.data.frame_step * ratio)))
    interval = max(2, int(round(cfg.data.control_point_interval * ratio)))
    return windows_from_rows(root, pose, T=T, frame_step=step, interval=interval,
                             max_windows=max_windows, source=str(path))


# ---------------------------------------------------------------------------------------------
# Style search: optimisation
# ---------------------------------------------------------------------------------------------


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
    step (curves.velocity)."""
    return _window_losses(root_vel_NxTx3, pose_NxTxR, curves.velocity(target.root_NxTx3),
                          target.pose_NxTxR, vel_weight, length_unit)


@functools.partial(jax.jit, static_argnames=("steps", "warmup", "record_every"))
def _search_scan(gstate, vel_NxTx3, u_NxTx3, pose_NxTxR, u0_SxD, center_D, scale_D, lr, vel_weight,
                 length_unit, *, steps: int, warmup: int, record_every: int):
    S, N = u0_SxD.shape[0], vel_NxTx3.shape[0]
    tx = optax.adam(search_schedule(lr, steps, warmup), b1=0.5, b2=0.999)
    vel, u, pose_t = (jnp.tile(a, (S, 1, 1)) for a in (vel_NxTx3, u_NxTx3, pose_NxTxR))

    def losses_S(p_SxD):
        w = center_D + scale_D * p_SxD
        rv, pose = step_lib.generator_apply(gstate, vel, w_BxD=jnp.repeat(w, N, axis=0))
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
    w, final, hist = _search_scan(step_lib.generator_state(state), host(curves.velocity(target.curve_NxTx3)),
                                  host(curves.velocity(target.root_NxTx3)), host(target.pose_NxTxR),
                                  host((w0 - center) / scale), host(center), host(scale), host(lr),
                                  host(vel_weight), host(length_unit), steps=int(steps),
                                  warmup=int(warmup), record_every=int(record_every))
    final, hist, w = np.asarray(final), np.asarray(hist), np.asarray(w)
    if not np.isfinite(final).any():
        raise AnalysisError(f"style search diverged from every start (final losses {final}); lower lr")
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


# ---------------------------------------------------------------------------------------------
# Generating with a code
# ---------------------------------------------------------------------------------------------


def reconstruct(state, target: MotionWindows, w_D):
    """G's (root_vel, pose) for every window of the target with one code w."""
    N = target.curve_NxTx3.shape[0]
    # numpy in: the same jit cache entry whether w comes from numpy or from a device computation
    w = np.broadcast_to(np.asarray(w_D, np.float32), (N, np.shape(w_D)[-1]))
    return generate.apply_code(state, curves.velocity(target.curve_NxTx3), w)


def generate_along(state, layout: RowLayout, w_D, curve_xz_Px2, *, spacing_m: float,
                   start_height_m: float) -> dict:
    """Walk with code w along a floor curve: the curve is resampled every `spacing_m` metres (the
    speed, e.g. the searched clip's `spacing_m`) and walked whole by `generate.generate_motion`
    (padded for G, in chunks when long, a gait phase from offset 0); the root starts at the
    curve's start at `start_height_m` (G predicts velocities only) in place of generate's floor
    shift. Returns numpy arrays: positions_TxJx3, root_Tx3, pose_TxR, curve_Tx3."""
    xz = curves.resample_polyline(curve_xz_Px2, spacing=float(spacing_m))
    if len(xz) < 2:
        raise AnalysisError(f"the curve gives {len(xz)} sample at {spacing_m:.3g} m per sample; a walk "
                            f"needs at least 2 (draw a longer curve)")
    curve = curves.on_floor(xz).astype(np.float32)
    gen = generate.generate_motion(state, layout, curve, np.reshape(np.asarray(w_D, np.float32), (1, -1)))
    positions = gen.positions[0].copy()
    positions[..., 1] += float(start_height_m) - gen.floor_shift_m[0]
    return {"positions_TxJx3": positions, "root_Tx3": positions[:, 0].copy(), "pose_TxR": gen.pose[0],
            "curve_Tx3": curve}
