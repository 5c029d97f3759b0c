"""Generation from a trained model: style specs, input curves, G, root height and outputs.

The pieces bin/generate.py strings together (each usable on its own):

    parse_style(text, style_names, seed)  -> StyleSpec     a label, mix, expression, w file, random
    spec_codes(state, specs, names, z)    -> w (N, w_dim)  in w space, z = 0 by default
    load_curve(text, length, scale)       -> Curve         a shape, a CSV/JSON file or a BVH root path
    prepare_curve(curve, sample_rate, speed) -> (M, 3)     equal spacing, every sample of the curve
    generate_motion(state, layout, curve, w) -> Generated  G (in chunks if long), integration, floor
    write_outputs(out, generated, ...)                     .bvh / .npz / .gif / .mp4 / .png

Style (all in w space, the Latent Transform's output, computed with one z for every operand):
- a label `Happy`;
- a mix `Sad:0.3,Happy:0.7`: w = sum a_k w_k with the weights normalised to sum 1 (so weights
  1 and 0 give one style's w exactly, and `Sad:1,Happy:1` is the half-way mix);
- an expression `OldMan - Normal + Marching` (optional coefficients `0.5*Happy`): w = sum ±c_k w_k,
  as the reference's `--style_mode operation`;
- a raw w vector: a .npy or .txt file of w_dim numbers;
- `random`: a label drawn from the seed.
z: `zero` (default, like the reference's inference: w = LT(0, label)), `seed` (one z ~ N(0, I)
from the seed), or an integer K (K draws from the seed -> K outputs).

Curve -> G input. The curve (metres, floor x-z) is resampled at equal arc length with spacing
speed / sample_rate, sample_rate = meta fps / data.frame_step (15 Hz for the shipped configs);
speed defaults to DEFAULT_SPEED_M_PER_S (1.2 m/s, an ordinary adult walk; the embedded styles
range from 0.54 to 1.65 m/s, mean 1.08; checkpoints store no data statistics), and for a BVH
curve to that clip's own mean speed. The whole curve is walked: G needs T a multiple of 8 (and
>= MIN_T), so generate_motion extends the curve straight past its end to the next such T, runs
G, and crops the motion back to the curve's own samples.

Limits (module constants, checked by load_curve, prepare_curve and generate_motion before
anything large is allocated; beyond them GenerateError says which limit and by how much):
MAX_CURVE_LENGTH_M of walk, MAX_CURVE_SAMPLES samples of G input (40 minutes at 15 Hz),
MAX_CURVE_POINTS input points, MAX_CURVE_FILE_BYTES per curve file, MAX_TOTAL_SAMPLES motions x
samples per call, MAX_GIF_FRAMES frames x panels per GIF (Pillow holds every frame in memory).

Long curves in bounded memory. One G call takes at most CHUNK_T samples (and BATCH_SAMPLES
motions x samples). G instance-normalises over its whole time axis, so a curve up to CHUNK_T
goes through in one pass (the statistics span the whole curve, not a training window: DESIGN.md
§5.1); a longer one goes through in overlapping chunks of CHUNK_T samples, blended by
overlap-add: each chunk's weight is 0 within CHUNK_MARGIN samples of its ends (more than G's
receptive radius, about 100 samples at kw 5: the layers' half-widths times their strides, so
what a chunk's zero padding reaches is not used),
rises linearly over CHUNK_FADE samples, and the weights are normalised to sum 1. Each chunk's
statistics are its own 4.5 minutes instead of the whole walk's: tests/test_generate.py
bounds the difference to one pass on a curve that fits both ways. A G with a gait phase
(model.gait_phase) walks on one clock: each chunk's phase offset is the phase walked by its
first sample (offset + 2π s / λ(w)), so the phase is one pass's, not restarted per chunk; the
root (a blended velocity, its height's difference with model.root_height) is integrated once
over the whole curve, so neither path nor height jumps at a seam. The straight extension past
the curve's end is walked after it and changes no sample's phase.

Root height. G predicts the root velocity (y included) and root-relative joints, never an
absolute height. The root is integrated from the curve's start (curves.integrate: p[0] = start,
p[t] = p[t-1] + v[t]), then each clip is lifted as a whole so that the 5th percentile over frames
of its lowest joint's height is 0: feet on the floor, robust to a few frames of dipping toes.
(The reference hard-coded a start height per style name, DESIGN.md §6.)

Outputs (by suffix; several motions -> .bvh/.npz get one file each, `name_<i>.ext`;
.gif/.mp4/.png show them side by side). Every file is written atomically: on an error nothing
(not even a partial file) is left at the output path.
- .bvh: ik.positions_to_motion on the layout's skeleton (see ik.py for the twist rule), by
  default in the training skeleton's own hierarchy (the bones leaving a joint with several
  children are best fits; the error goes to `log`), or with hierarchy "exact" with zero-length
  branch joints and every bone direction exact; bone lengths the skeleton's; metres by default
  (Blender's BVH importer maps one file unit to one Blender unit = 1 m at its default scale
  1.0, and converts Y-up to its Z-up with its default axes), or centimetres with units="cm"
  (import those with scale 0.01).
- .npz: positions (T, J, 3) float64 metres, Y up (the generated joints, after the floor shift);
  positions_skeleton (T, J, 3): the same pose on the skeleton's bone lengths (= FK of the .bvh,
  in the same hierarchy); joint_names, parents, fps (samples per second), style, w, z, curve
  (T, 3), floor_shift_m.
- .gif (Pillow) / .mp4 (ffmpeg or imageio-ffmpeg): a chase-camera animation (viz.animate_motions).
- .png: stroboscopic strips (viz.pose_strips), the form of the paper's Figs. 4, 6 and 7.
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import os
import re
import tempfile
from pathlib import Path
from typing import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from motiongan_jax import atomic, curves, ik
from motiongan_jax import step as step_lib
from motiongan_jax.representation import from_rows

DEFAULT_SPEED_M_PER_S = 1.2
MIN_T = 16
# What one generation may ask for (module doc, README "Generating walks")
MAX_CURVE_LENGTH_M = 10_000.0
MAX_CURVE_SAMPLES = 36_000
MAX_CURVE_POINTS = 250_000
MAX_CURVE_FILE_BYTES = 128 * 2**20
MAX_TOTAL_SAMPLES = 300_000
MAX_GIF_FRAMES = 3_000
# How: one G call holds at most CHUNK_T samples of one motion and BATCH_SAMPLES in all
CHUNK_T = 4096
CHUNK_MARGIN = 128
CHUNK_FADE = 256
CHUNK_OVERLAP = 2 * CHUNK_MARGIN + CHUNK_FADE
BATCH_SAMPLES = 8_192
FLOOR_PERCENTILE = 5.0
SHAPE_POINTS_PER_M = 100  # built-in shapes are drawn at 1 cm before resampling (at most MAX_CURVE_POINTS)
OUTPUT_SUFFIXES = (".bvh", ".npz", ".gif", ".mp4", ".png")
BVH_UNITS = {"m": 1.0, "cm": 100.0}
FIGURES = ("styles", "interp", "arith")
INTERP_ALPHAS = (0.0, 0.25, 0.5, 0.75, 1.0)


# jitted once per shape: one XLA compile of G (~3 s on CPU) instead of op-by-op dispatch (~8 s)
_apply_g = jax.jit(lambda state, vel, w, phase: step_lib.generator_apply(state, vel, w_BxD=w, phase_offset_B=phase))
_latent_w = jax.jit(step_lib.latent_w)
_stride_m = jax.jit(lambda state, w: jnp.exp(step_lib.generator(state).log_stride(w)))  # λ(w), metres


def apply_code(state, curve_vel_BxTx3, w_BxD, phase_offset_B=None):
    """(root_vel_BxTx3, pose_BxTxR) of G for style codes w: the one jitted G of generation,
    analysis and evaluation (compiled once per shape, on G's part of the state; inputs go through
    numpy so that arrays from any computation share one cache entry). `phase_offset_B`: a G with
    a gait phase starts there (radians; None: 0)."""
    phase = None if phase_offset_B is None else np.asarray(phase_offset_B, np.float32)
    return _apply_g(step_lib.generator_state(state), np.asarray(curve_vel_BxTx3, np.float32),
                    np.asarray(w_BxD, np.float32), phase)


def latent_codes(state, labels_B, z_BxZ) -> jax.Array:
    """w = LT(label, z) for each row (B x w_dim; jitted on G's part of the state)."""
    return _latent_w(step_lib.generator_state(state), jnp.asarray(labels_B, jnp.int32),
                     jnp.asarray(z_BxZ, jnp.float32))


class GenerateError(ValueError):
    """Bad user input to generation (style, curve option, output path); the message says which."""


class StyleError(GenerateError):
    """A style spec that names no style, or is malformed."""


# ---------------------------------------------------------------------------------------------
# Styles
# ---------------------------------------------------------------------------------------------


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
    hint = f"; did you mean {best!r}?" if best else ""
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
        raise StyleError(f"{what}: {text!r} is not a number") from None
    if not math.isfinite(value):
        raise StyleError(f"{what}: {text!r} is not a finite number")
    return value


def _parse_mix(text: str, style_names) -> StyleSpec:
    terms = []
    for part in text.split(","):
        if not part.strip():
            raise StyleError(f"malformed mix {text!r}: empty entry (use Name:weight,Name:weight)")
        if part.count(":") != 1:
            raise StyleError(f"malformed mix {text!r}: entry {part.strip()!r} is not Name:weight")
        name, weight = part.split(":")
        terms.append((_resolve_name(name, style_names),
                      _number(weight.strip(), f"malformed mix {text!r}: weight of {name.strip()!r}")))
    names = [n for n, _ in terms]
    if len(set(names)) != len(names):
        raise StyleError(f"malformed mix {text!r}: a style appears twice")
    total = sum(a for _, a in terms)
    if abs(total) < 1e-9:
        raise StyleError(f"malformed mix {text!r}: the weights sum to 0 (they are normalised to sum 1)")
    terms = tuple((n, a / total) for n, a in terms)
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
        i = skip(i)
        if i >= n:
            raise StyleError(f"malformed expression {text!r}: "
                             f"{'empty' if not terms and i == 0 else 'ends with an operator'}")
        name = _starts_name(text, i, names_by_len)
        if name is None:
            if text[i] in "+-*":
                raise StyleError(f"malformed expression {text!r}: expected a style name at "
                                 f"position {i + 1}, found {text[i]!r}")
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
    return int(jax.eval_shape(lambda s: step_lib.latent_w(s, jnp.zeros((1,), jnp.int32)), state).shape[-1])


def z_codes(state, z: str | int = "zero", seed: int = 0) -> np.ndarray:
    """(K, z_dim) noise codes: "zero" -> one zero z; "seed" -> one N(0, I) draw from the seed;
    an integer K (or its string) -> K draws from the seed."""
    z_dim = step_lib.generator_z_dim(state)
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
    z_dim, D, C = step_lib.generator_z_dim(state), w_dim(state), len(style_names)
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


# ---------------------------------------------------------------------------------------------
# Curves
# ---------------------------------------------------------------------------------------------


@dataclasses.dataclass(frozen=True)
class Curve:
    """A user curve before resampling: (P, 2) floor points (x, z) in metres, and for a BVH curve
    its own mean speed and the spline interval (in points) that smooths its gait sway."""

    points: np.ndarray
    description: str
    speed_m_per_s: float | None = None
    smooth_interval: int | None = None


def load_curve(text: str, *, length: float | None = None, scale: float = 2.0,
               control_seconds: float | None = None) -> Curve:
    """A shape name (curves.SHAPES, with length/scale in metres), or a .csv/.txt/.json file of
    x,z points in metres, or a .bvh file (its pelvis path, units guessed from the leg length,
    smoothed by a spline with a knot every `control_seconds` as in training).
    Raises GenerateError (also for a curve beyond the module's limits, before it is built or
    read), curves.CurveFileError or curves.DegenerateCurveError."""
    text = str(text).strip()
    if text in curves.SHAPES:
        try:
            natural = None if length is None else float(length)
            total = natural
            if total is None:
                total = {"line": scale, "circle": 2 * math.pi * scale, "s_curve": 2 * math.pi * scale,
                         "figure8": 4 * math.pi * scale, "corner": 2 * scale}[text]
            if math.isfinite(total) and total > MAX_CURVE_LENGTH_M:
                raise GenerateError(_too_long(f"curve {text!r}", total))
            num = int(min(max(total * SHAPE_POINTS_PER_M, 256), MAX_CURVE_POINTS))
            pts = curves.shape_curve(text, length=natural, scale=scale, num_points=num)
        except (ValueError, TypeError) as e:
            if isinstance(e, (curves.DegenerateCurveError, GenerateError)):
                raise
            raise GenerateError(f"curve {text!r}: {e}") from None
        return Curve(pts, f"{text} (scale {scale:g} m, length {_polyline_length(pts):.3g} m)")
    path = Path(text)
    if not path.is_file():
        raise GenerateError(f"curve {text!r}: not a shape name ({', '.join(curves.SHAPES)}) and "
                            f"no such file")
    size = path.stat().st_size
    if size > MAX_CURVE_FILE_BYTES:
        raise GenerateError(f"curve file {path}: {size / 2**20:.0f} MiB is larger than the limit of "
                            f"{MAX_CURVE_FILE_BYTES / 2**20:.0f} MiB (generate.MAX_CURVE_FILE_BYTES)")
    if path.suffix.lower() == ".bvh":
        from motiongan_jax import bvh

        motion = bvh.read_bvh(path)
        _check_points(motion.num_frames, f"curve {path.name}")
        pts = curves.curve_from_bvh(motion)
        check_curve_limits(pts, f"curve {path.name}")
        frames = len(pts)
        seconds = (frames - 1) * motion.frame_time
        interval = None
        if control_seconds is not None:
            interval = max(2, int(round(control_seconds / motion.frame_time)))
        smoothed = pts if interval is None else curves.resample_polyline(pts, num_points=frames,
                                                                          smooth_interval=interval)
        speed = _polyline_length(smoothed) / seconds if seconds > 0 else None
        return Curve(pts, f"{path.name} (root path, {frames} frames, {seconds:.3g} s)",
                     speed if speed and speed > 0 else None, interval)
    pts = curves.load_curve_file(path)
    check_curve_limits(pts, f"curve {path.name}")
    return Curve(pts, f"{path.name}")


def _polyline_length(pts) -> float:
    return float(np.sum(np.linalg.norm(np.diff(np.asarray(pts), axis=0), axis=1)))


def _too_long(what: str, length_m: float) -> str:
    shown = f"{length_m:,.0f}" if length_m < 1e12 else f"{length_m:.3g}"
    return (f"{what}: {shown} m is longer than the limit of {MAX_CURVE_LENGTH_M:,.0f} m "
            f"(generate.MAX_CURVE_LENGTH_M)")


def check_curve_limits(points_Px2, what: str = "curve") -> None:
    """GenerateError when a user curve has more than MAX_CURVE_POINTS points or is longer than
    MAX_CURVE_LENGTH_M (its polyline length)."""
    _check_points(len(points_Px2), what)
    length = _polyline_length(points_Px2)
    if length > MAX_CURVE_LENGTH_M:
        raise GenerateError(_too_long(what, length))


def _check_points(n: int, what: str) -> None:
    if n > MAX_CURVE_POINTS:
        raise GenerateError(f"{what}: {n:,} points are more than the limit of {MAX_CURVE_POINTS:,} "
                            f"(generate.MAX_CURVE_POINTS); resample it more coarsely")


def padded_length(num_samples: int) -> int:
    """The T that G runs on for a curve of `num_samples`: the next multiple of 8, at least MIN_T."""
    return max(MIN_T, -(-int(num_samples) // 8) * 8)


def prepare_curve(curve: Curve | np.ndarray, sample_rate: float, speed: float | None = None,
                  log: Callable[[str], None] | None = None) -> np.ndarray:
    """G's input curve: (M, 3) float32 (x, 0, z) metres, equal spacing speed / sample_rate, every
    sample of the curve (M >= 2; generate_motion pads it for G and crops back, module doc).
    speed defaults to the curve's own (a BVH) or DEFAULT_SPEED_M_PER_S. GenerateError when the
    curve exceeds the limits (module doc), before it is resampled."""
    if not isinstance(curve, Curve):
        curve = Curve(curves.check_curve(curve, "curve"), "curve")
    check_curve_limits(curve.points, f"curve {curve.description}")
    if speed is None:
        speed = curve.speed_m_per_s or DEFAULT_SPEED_M_PER_S
    speed = float(speed)
    if not (math.isfinite(speed) and speed > 0):
        raise GenerateError(f"speed must be a positive number of m/s, got {speed}")
    if not (math.isfinite(sample_rate) and sample_rate > 0):
        raise GenerateError(f"sample rate must be positive, got {sample_rate}")
    spacing = speed / sample_rate
    # the samples resampling would give (smoothing only shortens a curve): refuse before allocating
    expected = _polyline_length(curve.points) / spacing + 1
    if expected > MAX_CURVE_SAMPLES:
        raise GenerateError(
            f"curve {curve.description}: {expected:,.0f} samples at {spacing:.3g} m ({speed:.3g} m/s at "
            f"{sample_rate:g} Hz) are more than the limit of {MAX_CURVE_SAMPLES:,} "
            f"({MAX_CURVE_SAMPLES / sample_rate / 60:.0f} minutes at this rate; generate.MAX_CURVE_SAMPLES): "
            f"shorten the curve or walk it faster")
    xz = curves.resample_polyline(curve.points, spacing=spacing, smooth_interval=curve.smooth_interval)
    M = len(xz)
    note = f"curve {curve.description}: {M} samples at {spacing:.3g} m ({speed:.3g} m/s at {sample_rate:g} Hz)"
    if padded_length(M) > M:
        note += (f"; walked in full: G takes a multiple of 8 samples (at least {MIN_T}), so it walks on "
                 f"straight past the curve's end and the motion is cropped back to its {M} samples")
    if M > CHUNK_T:
        note += f"; in overlapping chunks of {CHUNK_T} samples"
    if log is not None:
        log(note)
    return curves.on_floor(xz).astype(np.float32)


# ---------------------------------------------------------------------------------------------
# Generation
# ---------------------------------------------------------------------------------------------


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
        raise GenerateError(f"curve must be (M, 3) with M >= 2 samples, got shape {curve.shape}")
    if not np.isfinite(curve).all():
        raise GenerateError("curve has non-finite values")
    w = np.asarray(w_BxD, np.float32)
    if w.ndim != 2 or len(w) == 0:
        raise GenerateError(f"style codes must be (B, w_dim) with B >= 1, got shape {w.shape}")
    M, B = curve.shape[0], w.shape[0]
    if M > MAX_CURVE_SAMPLES:
        raise GenerateError(f"curve: {M:,} samples are more than the limit of {MAX_CURVE_SAMPLES:,} "
                            f"(generate.MAX_CURVE_SAMPLES)")
    if B * M > MAX_TOTAL_SAMPLES:
        raise GenerateError(f"{B} motions x {M:,} samples = {B * M:,} are more than the limit of "
                            f"{MAX_TOTAL_SAMPLES:,} (generate.MAX_TOTAL_SAMPLES): ask for fewer styles or "
                            f"noise draws at once, or a shorter curve")
    if step_lib.has_gait_phase(state):
        phase = np.zeros(B) if phase_offset_B is None else np.asarray(phase_offset_B, np.float64)
        if phase.shape != (B,) or not np.isfinite(phase).all():
            raise GenerateError(f"phase offsets must be {B} finite numbers (radians), one per motion, "
                                f"got shape {phase.shape}")
    elif phase_offset_B is not None:
        raise GenerateError("a phase offset was given, but this model has no gait phase")
    else:
        phase = None
    vel_Tx3 = curves.velocity(jnp.asarray(extend_straight(curve, padded_length(M) - M))[None])[0]
    root_vel, pose = _g_outputs(state, vel_Tx3, w, phase, chunk_T, progress)
    root_vel, pose = root_vel[:, :M], pose[:, :M]
    start = np.broadcast_to(curve[0].astype(np.float64) * np.array([1.0, 0.0, 1.0]), (B, 3))
    # curves.integrate's convention (p[0] = start, p[t] = p[t-1] + v[t], v[0] unused), in float64
    root = start[:, None, :] + np.concatenate([np.zeros((B, 1, 3)), np.cumsum(root_vel[:, 1:], axis=1)], 1)
    joints = np.asarray(from_rows(root, pose, layout), np.float64)
    if not np.isfinite(joints).all():
        raise GenerateError("the generator produced non-finite positions (a broken checkpoint?)")
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
        raise GenerateError(f"chunk_T must be a multiple of 8 and >= {2 * CHUNK_OVERLAP}, got {chunk_T}")
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
        # G's phase is a clock in walked distance from its first sample (nn.generator.walked_phase:
        # the first velocity is not walked): a chunk starting at s starts at the phase walked by s
        step_T = np.linalg.norm(np.asarray(vel_Tx3, np.float64)[:, ::2], axis=-1)
        walked_T = np.cumsum(np.concatenate([[0.0], step_T[1:]]))
        stride_B = np.asarray(_stride_m(step_lib.generator_state(state), jnp.asarray(w_BxD)), np.float64)
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
                phase = phase_B[idx] if s == 0 else np.mod(phase_B[idx] + 2 * np.pi * walked_T[s] / stride_B[idx],
                                                            2 * np.pi)
                phase = jnp.asarray(phase, jnp.float32)
            r, p = apply_code(state, jnp.broadcast_to(vel_Tx3[s:s + L], (group, L, 3)), wg, phase)
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


# ---------------------------------------------------------------------------------------------
# Figures: the lists of (title, style) behind the paper's Figs. 4, 6 and 7
# ---------------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------------
# Outputs
# ---------------------------------------------------------------------------------------------


def check_output_path(out, *, count: int = 1) -> list[Path]:
    """The file(s) an output will be written to; GenerateError for an unsupported suffix, a
    missing or unwritable directory, or a directory in the way. Nothing is created."""
    out = Path(out)
    suffix = out.suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise GenerateError(f"output {out}: unsupported format {out.suffix or '(none)'!r}; use one of "
                            f"{', '.join(OUTPUT_SUFFIXES)}")
    parent = out.parent
    if parent.exists() and not parent.is_dir():
        raise GenerateError(f"cannot write {out}: {parent} is not a directory")
    if not parent.is_dir():
        raise GenerateError(f"cannot write {out}: directory {parent} does not exist")
    try:  # a real probe: os.access says yes to root even where writing fails (/proc, read-only mounts)
        fd, probe = tempfile.mkstemp(dir=parent, prefix=f".{out.name}.", suffix=".probe")
        os.close(fd)
        os.unlink(probe)
    except OSError as e:
        raise GenerateError(f"cannot write {out}: directory {parent} is not writable "
                            f"({e.strerror})") from None
    paths = [out] if count == 1 or suffix in (".gif", ".mp4", ".png") else \
        [out.with_name(f"{out.stem}_{i}{out.suffix}") for i in range(count)]
    for p in paths:
        if p.is_dir():
            raise GenerateError(f"cannot write {p}: it is a directory")
        if p.exists() and not os.access(p, os.W_OK):
            raise GenerateError(f"cannot write {p}: the existing file is read-only")
    if suffix == ".mp4":
        from motiongan_jax import viz

        try:
            viz.video_writer(out, 15.0)
        except RuntimeError as e:
            raise GenerateError(str(e)) from None
    return paths


def check_output_size(out, frames: int, count: int = 1) -> None:
    """GenerateError when a .gif of `count` panels x `frames` frames exceeds MAX_GIF_FRAMES
    (Pillow keeps every frame in memory until the file is written; .mp4 streams to ffmpeg)."""
    if Path(out).suffix.lower() == ".gif" and frames * count > MAX_GIF_FRAMES:
        raise GenerateError(f"output {out}: a GIF of {count} panel(s) x {frames:,} frames is more than "
                            f"the limit of {MAX_GIF_FRAMES:,} frames x panels (generate.MAX_GIF_FRAMES; "
                            f"GIF frames are held in memory): write .mp4, .bvh or .npz, or a shorter curve")


def rest_offsets(layout) -> np.ndarray:
    """The export skeleton's rest offsets: the layout's (every checkpoint stores them)."""
    if layout.rest_offsets_m is None:
        raise GenerateError("this layout has no rest offsets: a BVH export needs the skeleton's rest pose")
    return np.asarray(layout.rest_offsets_m, np.float64)


def to_bvh_motion(positions_TxJx3, layout, fps: float, units: str = "m", log=None,
                  hierarchy: str = "source"):
    """(bvh.Motion, ExportSkeleton) of one generated clip on the `hierarchy` of ik.HIERARCHIES
    (see ik.py). For "source", `log` gets how far the best-fit bones are off the generated
    directions."""
    if units not in BVH_UNITS:
        raise GenerateError(f"BVH units must be one of {', '.join(BVH_UNITS)}, got {units!r}")
    if hierarchy not in ik.HIERARCHIES:
        raise GenerateError(f"BVH hierarchy must be one of {', '.join(ik.HIERARCHIES)}, got {hierarchy!r}")
    rest = rest_offsets(layout)
    scale = BVH_UNITS[units]
    motion = ik.positions_to_motion(positions_TxJx3, layout.joint_names, layout.parents, rest,
                                    1.0 / fps, units_per_m=scale, hierarchy=hierarchy)
    ex = ik.export_skeleton(layout.joint_names, layout.parents, rest, scale, hierarchy)
    if log is not None and hierarchy == "source":
        err = ik.bone_errors(positions_TxJx3, ik.layout_positions(motion, ex), layout.parents)
        kids = np.bincount(np.asarray(layout.parents[1:]), minlength=layout.num_joints)
        fitted = [b for b in range(layout.num_joints - 1)
                  if kids[layout.parents[b + 1]] > 1 and ex.helper_index[b + 1] < 0]
        if fitted:
            names = sorted({layout.joint_names[layout.parents[b + 1]] for b in fitted})
            deg = np.degrees(err[:, fitted])
            # how far the joint at the bone's end moves: a chord of the bone's length
            cm = 200 * np.asarray(layout.bone_lengths_m)[fitted] * np.sin(err[:, fitted] / 2)
            log(f"BVH, source hierarchy: the {len(fitted)} bones leaving {', '.join(names)} are best fits, "
                f"{deg.mean():.2g} deg mean and {deg.max():.2g} deg max off the generated directions "
                f"({cm.mean():.2g} cm mean, {cm.max():.2g} cm max at the joints they lead to; every other bone "
                f"direction exact); --bvh-hierarchy exact makes them exact with a zero-length joint per bone")
    return motion, ex


def save_bvh(path, positions_TxJx3, layout, fps: float, units: str = "m", log=None,
             hierarchy: str = "source") -> Path:
    from motiongan_jax import bvh

    motion, _ = to_bvh_motion(positions_TxJx3, layout, fps, units, log, hierarchy)
    bvh.write_bvh(path, motion, precision=6 if units == "cm" else 7)
    return Path(path)


def save_npz(path, gen: Generated, index: int, layout, fps: float, style: str, z=None,
             log=None, hierarchy: str = "source") -> Path:
    pos = gen.positions[index]
    motion, ex = to_bvh_motion(pos, layout, fps, "m", log, hierarchy)
    skel = ik.layout_positions(motion, ex)
    arrays = dict(positions=pos, positions_skeleton=skel,
                  joint_names=np.array(layout.joint_names), parents=np.array(layout.parents, np.int32),
                  fps=np.float64(fps), style=np.array(style), w=gen.w[index],
                  curve=gen.curve, floor_shift_m=np.float64(gen.floor_shift_m[index]))
    if z is not None:
        arrays["z"] = np.asarray(z, np.float32)
    path = Path(path)
    with atomic.atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            np.savez(fh, **arrays)
    return path


def write_outputs(out, gen: Generated, titles: Sequence[str], layout, fps: float, *,
                  bvh_units: str = "m", bvh_hierarchy: str = "source", z_per_motion=None,
                  log: Callable[[str], None] | None = None) -> list[Path]:
    """Writes every motion of `gen` to `out` by its suffix (module doc); returns the paths.
    `bvh_hierarchy` (ik.HIERARCHIES) is the skeleton of .bvh files and of .npz's
    positions_skeleton."""
    from motiongan_jax import viz

    out = Path(out)
    B = gen.positions.shape[0]
    paths = check_output_path(out, count=B)
    check_output_size(out, gen.positions.shape[1], B)
    suffix = out.suffix.lower()
    parents = list(layout.parents)
    try:
        if suffix == ".bvh":
            for i, p in enumerate(paths):
                save_bvh(p, gen.positions[i], layout, fps, bvh_units, log, bvh_hierarchy)
        elif suffix == ".npz":
            for i, p in enumerate(paths):
                save_npz(p, gen, i, layout, fps, titles[i],
                         None if z_per_motion is None else z_per_motion[i], log, bvh_hierarchy)
        elif suffix in (".gif", ".mp4"):
            viz.animate_motions(list(gen.positions), parents, list(titles), out, fps=fps,
                                curves=[gen.curve] * B, joint_names=layout.joint_names)
        else:
            viz.pose_strips(list(gen.positions), parents, list(titles), out, curves=[gen.curve] * B)
    except RuntimeError as e:  # e.g. ffmpeg vanished between the check and the write
        raise GenerateError(str(e)) from None
    except OSError as e:  # the temporary file is gone with the error (atomic writes)
        raise GenerateError(f"cannot write {out}: {e.strerror or e}") from None
    return paths
