"""Style codes and the geometry of w: codes per label, PCA, distances, nearest styles, blending.

Style codes. w = LT(label, z) (`styles.latent_codes`): `label_codes` gives, for every label,
w at z = 0 (what the inference tools use) and K codes from z ~ N(0, I), whose mean is the
style's *centroid*.

Blending. The AdaIN scale and bias of every layer are affine in w (s = A_s w + a_s,
b = A_b w + a_b), so blending codes with weights that sum to 1 (`interpolate`, `mix`) gives
exactly the generator output of blending each AdaIN's (s, b) with the same weights (the
reference's AdaIN-space method). `generator_apply_adain` runs G with per-layer (s, b) so the two
can be compared; `arithmetic` (Σ ±w, weights need not sum to 1) has no such twin.
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple, Sequence

import chex
import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax.generate import styles
from motiongan_jax.model import apply as model_apply


class AnalysisError(ValueError):
    """A problem with analysis inputs (a motion that does not fit the model, a short clip, ...)."""


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
    Z = model_apply.z_dim(state)
    labels = jnp.arange(C, dtype=jnp.int32)
    zero = styles.latent_codes(state, labels, jnp.zeros((C, Z), jnp.float32))
    rep = jnp.repeat(labels, k)
    z = jax.random.normal(jax.random.key(0) if key is None else key, (C * k, Z), jnp.float32)
    samples = styles.latent_codes(state, rep, z).reshape(C, k, -1)
    chex.assert_shape(samples, (C, k, zero.shape[-1]))
    return StyleCodes(tuple(style_names), zero, samples)


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
