"""Styles to generate: the style language, z, and the w codes it names; the lists behind the
paper's figures.

Style (all in w space, the Latent Transform's output, computed with one z for every operand):
- a label `Happy`;
- a mix `Sad:0.3,Happy:0.7`: w = sum a_k w_k with the weights normalised to sum 1 (so weights
  1 and 0 give one style's w exactly, and `Sad:1,Happy:1` is the half-way mix);
- an expression `OldMan - Normal + Marching` (optional coefficients `0.5*Happy`): w = sum ±c_k w_k,
  as the reference's `--style_mode operation`;
  the numbers are bounded where they are parsed (MAX_MIX_WEIGHT, MAX_COEFFICIENT_SUM, below);
- a raw w vector: a .npy or .txt file of w_dim numbers;
- `random`: a label drawn from the seed.
z: `zero` (default, like the reference's inference: w = LT(0, label)), `seed` (one z ~ N(0, I)
from the seed), or an integer K (K draws from the seed -> K outputs).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import re
from pathlib import Path
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax.generate.limits import GenerateError
from motiongan_jax.model import apply as model_apply

FIGURES = ("styles", "interp", "arith")
# The bounds on a style's numbers, the one definition for the command line, the API and the page:
# a w far outside the styles' own drives G off its training range (1e30*Sad gave non-finite
# positions), so a style is refused where it is parsed, not blamed on the model afterwards.
MAX_MIX_WEIGHT = 1000.0  # |weight| of one mix entry as written, before normalising to sum 1
MAX_COEFFICIENT_SUM = 10.0  # sum of |c| over the terms (expression coefficients or normalised weights)
INTERP_ALPHAS = (0.0, 0.25, 0.5, 0.75, 1.0)
_latent_w = jax.jit(model_apply.style_codes)


def latent_codes(state, labels_B, z_BxZ) -> jax.Array:
    """w = LT(label, z) for each row (B x w_dim; jitted on G's part of the state)."""
    return _latent_w(model_apply.generator_state(state), jnp.asarray(labels_B, jnp.int32),
                     jnp.asarray(z_BxZ, jnp.float32))


class StyleError(GenerateError):
    """A style spec that names no style, or is malformed."""


@dataclasses.dataclass(frozen=True)
class StyleSpec:
    """A parsed style. kind: "label", "mix", "expr" or "file". terms: (style name, coefficient)
    pairs (label: one pair with 1.0; mix: normalised weights); path: the w file (kind "file");
    text: a readable description (used in titles and saved files)."""

    kind: str
    terms: tuple[tuple[str, float], ...] = ()
    path: str | None = None
    text: str = ""


def unknown_style_message(name: str, style_names: Sequence[str]) -> str:
    close = difflib.get_close_matches(name, list(style_names), n=1, cutoff=0.0)
    lower = {s.lower(): s for s in style_names}
    best = lower.get(name.lower()) or (close[0] if close else None)
    hint = f"; did you mean {best!r}?" if best and best != name else ""
    return f"unknown style {name!r}{hint} Valid styles: {', '.join(style_names)}"


def _resolve_name(name: str, style_names: Sequence[str]) -> str:
    name = name.strip()
    if name in style_names:
        return name
    matches = [s for s in style_names if s.lower() == name.lower()]
    if len(matches) == 1:
        return matches[0]
    raise StyleError(unknown_style_message(name, style_names))


def _number(text: str, what: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise StyleError(f"{what}: {text!r} is not a number"[:300]) from None
    if not math.isfinite(value):
        raise StyleError(f"{what}: {text.strip()[:40]!r} is not a finite number")
    return value


def bounds_text() -> str:
    """The bounds (MAX_MIX_WEIGHT, MAX_COEFFICIENT_SUM) as every refusal states them."""
    return (f"bounds: each mix weight within ±{MAX_MIX_WEIGHT:g}, and the sizes of the coefficients (a mix's "
            f"weights once normalised to sum 1) add up to at most {MAX_COEFFICIENT_SUM:g}")


def _check_terms(text: str, kind: str, terms) -> None:
    """StyleError unless every coefficient is finite and the sizes add up to at most
    MAX_COEFFICIENT_SUM (for a mix: its normalised weights, which weights that nearly cancel blow up)."""
    total = math.fsum(abs(c) for _, c in terms)
    if not math.isfinite(total) or total > MAX_COEFFICIENT_SUM:
        shown = ", ".join(f"{n} {c:.3g}" for n, c in terms[:6]) + (", ..." if len(terms) > 6 else "")
        why = "the weights nearly cancel, so the normalised weights are " if kind == "mix" else "coefficients "
        raise StyleError(f"{kind} {text[:80]!r}: {why}{shown} (sizes add up to {total:.3g}); "
                         f"{bounds_text()}")


def _parse_mix(text: str, style_names) -> StyleSpec:
    terms = []
    for part in text.split(","):
        if not part.strip():
            raise StyleError(f"malformed mix {text!r}: empty entry (use Name:weight,Name:weight)")
        if part.count(":") != 1:
            raise StyleError(f"malformed mix {text!r}: entry {part.strip()!r} is not Name:weight")
        name, weight = part.split(":")
        name = _resolve_name(name, style_names)
        a = _number(weight.strip(), f"malformed mix {text!r}: weight of {name!r}")
        if abs(a) > MAX_MIX_WEIGHT:
            raise StyleError(f"mix {text[:80]!r}: weight {a:g} of {name!r} is too large; {bounds_text()}")
        terms.append((name, a))
    names = [n for n, _ in terms]
    if len(set(names)) != len(names):
        raise StyleError(f"malformed mix {text!r}: a style appears twice")
    total = math.fsum(a for _, a in terms)  # exact: weights of 1e-300 sum to a non-zero total
    if total == 0:
        raise StyleError(f"malformed mix {text!r}: the weights sum to 0 (they are normalised to sum 1)")
    terms = tuple((n, a / total) for n, a in terms)
    _check_terms(text, "mix", terms)
    return StyleSpec("mix", terms, text=",".join(f"{n}:{a:.3g}" for n, a in terms))


_NUM_RE = re.compile(r"\s*((?:\d+\.?\d*|\.\d+)(?:[eE][+-]?\d+)?)\s*\*\s*")
_OP_RE = re.compile(r"\s*([+-])\s*")


def _parse_expression(text: str, style_names) -> StyleSpec:
    """Terms [sign] [number *] Name joined by + and -; names are matched longest first, so a
    style name that contains '-' (e.g. Bandai's not-confident) is one operand."""
    names_by_len = sorted(style_names, key=len, reverse=True)
    terms: list[tuple[str, float]] = []
    n = len(text)

    def skip(i):
        while i < n and text[i].isspace():
            i += 1
        return i

    sign, i = 1.0, 0
    m = _OP_RE.match(text, 0)
    if m:  # a leading sign
        sign, i = (-1.0 if m.group(1) == "-" else 1.0), m.end()
    while True:
        coef = 1.0
        m = _NUM_RE.match(text, i)
        if m:
            coef, i = float(m.group(1)), m.end()
            if not math.isfinite(coef):  # digits beyond float range, e.g. 1e400
                raise StyleError(f"expression {text[:80]!r}: coefficient {m.group(1)[:40]!r} is not a finite "
                                 f"number; {bounds_text()}")
        i = skip(i)
        if i >= n:
            raise StyleError(f"malformed expression {text!r}: "
                             f"{'empty' if not terms and i == 0 else 'ends with an operator'}")
        name = _starts_name(text, i, names_by_len)
        if name is None:
            if text[i] in "+-*":
                raise StyleError(f"malformed expression {text!r}: expected a style name at "
                                 f"position {i + 1}, found {text[i]!r}")
            known = _name_then_symbol(text, i, names_by_len)
            if known is not None:  # a valid name followed by something other than + or -
                j = skip(i + len(known))
                if text[j] == "*":
                    raise StyleError(f"malformed expression {text!r}: a coefficient goes before its style "
                                     f"('2*{known}'), not after it")
                raise StyleError(f"malformed expression {text!r}: expected + or - after {known!r} at position "
                                 f"{j + 1}, found {text[j]!r}")
            token = re.match(r"[^\s+*,:-]+", text[i:]).group(0)
            raise StyleError(unknown_style_message(token, style_names))
        terms.append((name, sign * coef))
        i = skip(i + len(name))
        if i >= n:
            break
        m = _OP_RE.match(text, i)
        if not m:
            raise StyleError(f"malformed expression {text!r}: expected + or - at position {i + 1}, "
                             f"found {text[i]!r}")
        sign, i = (-1.0 if m.group(1) == "-" else 1.0), m.end()
    _check_terms(text, "expression", terms)
    parts = []
    for k, (nm, c) in enumerate(terms):
        op = "- " if c < 0 else ("+ " if k else "")
        parts.append(op + (f"{abs(c):g}*" if abs(c) != 1 else "") + nm)
    return StyleSpec("expr", tuple(terms), text=" ".join(parts))


def _starts_name(text: str, i: int, names_by_len) -> str | None:
    """The longest style name starting at text[i] and ending at a term boundary (or None).
    Case-sensitive first, then case-insensitive."""
    for fold in (False, True):
        for name in names_by_len:
            chunk = text[i:i + len(name)]
            if (chunk.lower() == name.lower()) if fold else (chunk == name):
                rest = text[i + len(name):].lstrip()
                if not rest or rest[0] in "+-":
                    return name
    return None


def _name_then_symbol(text: str, i: int, names_by_len) -> str | None:
    """The longest style name at text[i] (any case) followed by a symbol (not a letter, digit or
    '_', which would make it part of another word): what `Sad*2` or `Sad/2` starts with."""
    for name in names_by_len:
        if text[i:i + len(name)].lower() == name.lower():
            rest = text[i + len(name):].lstrip()
            if rest and not (rest[0].isalnum() or rest[0] == "_"):
                return name
    return None


def parse_style(text: str, style_names: Sequence[str], seed: int = 0) -> StyleSpec:
    """A style spec from the command line (see the module doc). Raises StyleError naming the
    problem; an unknown name lists the valid ones and the closest match."""
    if not isinstance(text, str) or not text.strip():
        raise StyleError(f"empty style; valid styles: {', '.join(style_names)}")
    text = text.strip()
    names = list(style_names)
    if text in names:
        return StyleSpec("label", ((text, 1.0),), text=text)
    if text.lower() == "random":
        k = int(jax.random.randint(jax.random.fold_in(jax.random.key(seed), 1), (), 0, len(names)))
        return StyleSpec("label", ((names[k], 1.0),), text=names[k])
    if text.lower().endswith((".npy", ".txt")):
        if not Path(text).is_file():
            raise StyleError(f"style file {text!r} not found (a .npy/.txt style is a raw w vector)")
        return StyleSpec("file", path=text, text=Path(text).stem)
    if ":" in text or "," in text:
        return _parse_mix(text, names)
    if _OP_RE.search(text) or "*" in text:
        # a name that contains '-' is a label, not an expression
        name = _starts_name(text, 0, sorted(names, key=len, reverse=True))
        if name is not None and len(name) == len(text):
            return StyleSpec("label", ((name, 1.0),), text=name)
        return _parse_expression(text, names)
    return StyleSpec("label", ((_resolve_name(text, names), 1.0),), text=_resolve_name(text, names))


def load_w_file(path: str, w_dim: int) -> np.ndarray:
    """A raw style code from .npy or .txt: exactly w_dim numbers (any shape with that size)."""
    try:
        w = np.load(path) if path.lower().endswith(".npy") else np.loadtxt(path, ndmin=1)
    except (OSError, ValueError) as e:
        raise StyleError(f"style file {path}: cannot read a w vector ({e})") from None
    w = np.asarray(w, np.float64).reshape(-1)
    if w.size != w_dim:
        raise StyleError(f"style file {path} has {w.size} values, but this checkpoint's style code "
                         f"w has {w_dim} (model.w_dim): incompatible with this model")
    if not np.isfinite(w).all():
        raise StyleError(f"style file {path}: non-finite values")
    return w.astype(np.float32)


def w_dim(state) -> int:
    """The style code's size (model.w_dim), read off the Latent Transform's last layer."""
    return int(jax.eval_shape(lambda s: model_apply.style_codes(s, jnp.zeros((1,), jnp.int32)), state).shape[-1])


def z_codes(state, z: str | int = "zero", seed: int = 0) -> np.ndarray:
    """(K, z_dim) noise codes: "zero" -> one zero z; "seed" -> one N(0, I) draw from the seed;
    an integer K (or its string) -> K draws from the seed."""
    z_dim = model_apply.z_dim(state)
    key = jax.random.fold_in(jax.random.key(seed), 2)
    if isinstance(z, str) and z.strip().lower() == "zero":
        return np.zeros((1, z_dim), np.float32)
    if isinstance(z, str) and z.strip().lower() == "seed":
        return np.asarray(jax.random.normal(key, (1, z_dim), jnp.float32))
    try:
        k = int(z)
    except (TypeError, ValueError):
        raise GenerateError(f"--z must be 'zero', 'seed' or a number of samples, got {z!r}") from None
    if not 1 <= k <= 64:
        raise GenerateError(f"--z: number of samples must be 1..64, got {k}")
    return np.asarray(jax.random.normal(key, (k, z_dim), jnp.float32))


def spec_codes(state, specs: Sequence[StyleSpec], style_names: Sequence[str],
               z_KxZ: np.ndarray | None = None) -> np.ndarray:
    """w (len(specs) * K, w_dim) float32: for each spec, for each of the K z codes (default one
    zero z). Every label's w is computed in one fixed batch (all labels x all z), so a style's
    w does not depend on the other specs; sums are taken in float64, so weights 1 and 0 give
    that style's w exactly."""
    z_dim, D, C = model_apply.z_dim(state), w_dim(state), len(style_names)
    z = np.zeros((1, z_dim), np.float32) if z_KxZ is None else np.asarray(z_KxZ, np.float32)
    if z.ndim != 2 or z.shape[1] != z_dim:
        raise GenerateError(f"z must be (K, {z_dim}), got shape {z.shape}")
    K = len(z)
    labels = np.repeat(np.arange(C, dtype=np.int32), K)
    w_all = np.asarray(latent_codes(state, labels, np.tile(z, (C, 1))), np.float64).reshape(C, K, D)
    index = {n: i for i, n in enumerate(style_names)}
    out = []
    for s in specs:
        if s.kind == "file":
            out.append(np.broadcast_to(load_w_file(s.path, D), (K, D)))
            continue
        acc = np.zeros((K, D))
        for name, c in s.terms:
            acc = acc + c * w_all[index[name]]
        out.append(acc)
    return np.concatenate(out).astype(np.float32)


def figure_specs(kind: str, text: str | None, style_names: Sequence[str], seed: int = 0
                 ) -> list[tuple[str, StyleSpec]]:
    """(title, spec) panels of a figure.
    styles: a comma-separated list of styles (default: every style) on one curve (Fig. 4);
    interp: "A,B" -> w = (1-α) w_A + α w_B at α = 0, 1/4, 1/2, 3/4, 1 (Fig. 6);
    arith: an expression -> each operand, then the result (Fig. 7)."""
    names = list(style_names)
    if kind == "styles":
        items = names if text is None or text.strip().lower() in ("", "all") else text.split(",")
        specs = [parse_style(t, names, seed) for t in items]
        return [(s.text, s) for s in specs]
    if kind == "interp":
        parts = [] if text is None else [p for p in re.split(r"\s*,\s*", text.strip()) if p]
        if len(parts) != 2:
            raise StyleError(f"--figure interp needs two styles 'A,B', got {text!r}")
        a, b = (_resolve_name(p, names) for p in parts)
        out = []
        for alpha in INTERP_ALPHAS:
            spec = StyleSpec("mix", ((a, 1.0 - alpha), (b, alpha)), text=f"{a}:{1 - alpha:g},{b}:{alpha:g}")
            out.append((f"{a} {1 - alpha:g} / {b} {alpha:g}", spec))
        return out
    if kind == "arith":
        if text is None:
            raise StyleError("--figure arith needs an expression, e.g. 'OldMan - Normal + Marching'")
        spec = parse_style(text, names, seed)
        if spec.kind != "expr":
            raise StyleError(f"--figure arith needs an expression of several styles joined by + "
                             f"and -, got {text!r}")
        ops = [(n, StyleSpec("label", ((n, 1.0),), text=n)) for n, _ in spec.terms]
        return ops + [(spec.text, spec)]
    raise GenerateError(f"unknown figure {kind!r}; one of {', '.join(FIGURES)}")
