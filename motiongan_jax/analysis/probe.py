"""Linear probe. Least squares with an intercept from codes to known quantities (the embedded
dataset's gait parameters), scored by the cross-validated R² of each target
(leave-one-group-out or K-fold), optionally on the training fold's leading principal components
so that a few points in a wide code space still give a well-posed fit.
"""

from __future__ import annotations

import functools
import json
import math
from pathlib import Path
from typing import NamedTuple

import chex
import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax.analysis.style_space import StyleCodes, pca


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
    from motiongan_jax.data import synthetic

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
