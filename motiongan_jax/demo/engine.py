"""What the demo page asks for, checked and generated: requests in, motions and files out.

No web framework here (server.py is the HTTP side): a request is a plain dict as decoded from
JSON, checked against the stated limits below, then run through generate.py's public steps
(parse_style, z_codes, spec_codes, prepare_curve, generate_motion, write_outputs), so the page
gets the same styles, messages and files as bin/generate.py.

Latency. G is jit-compiled once per input shape (a few seconds each), so a freshly drawn path of
a new length would wait for a compile. Curves are therefore padded to one of a few sample counts
(SAMPLE_BUCKETS, straight on along the last direction at the same spacing) and the style codes to
one of a few batch sizes (BATCH_BUCKETS, repeating the last code); the motion is then cut back to
the curve's own samples and its floor recomputed over them. Padding the batch changes nothing (G
treats every motion on its own); padding the curve does change the result a little, since G's
instance norms take their statistics over the whole curve, padding included: the page shows, and
its downloads contain, the bucketed result. A curve whose sample count is a bucket size is
generated exactly as bin/generate.py does.
"""

from __future__ import annotations

import collections
import dataclasses
import json
import math
import re
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

from motiongan_jax.analysis import clips as clips_lib
from motiongan_jax.analysis import search as search_lib
from motiongan_jax.analysis import style_space
from motiongan_jax.data import curves
from motiongan_jax.generate import limits, stream, user_curves, walk, writers
from motiongan_jax.generate import styles as styles_lib
from motiongan_jax.motion import bvh, ik, rigs

# Limits the server enforces on every request (each breach is a 400 naming it): an interactive
# page's, inside generate.py's MAX_* limits, which every entry point applies (so here too)
MAX_POINTS = 20_000  # floor points of a drawn path
MAX_PATH_M = 60.0  # metres of path
MAX_STYLES = 6  # panels side by side (one style each)
MAX_SAMPLES_Z = 4  # K of z = K
MAX_MOTIONS = 8  # styles x K
MAX_STYLE_CHARS = 400
SPEED_RANGE_M_PER_S = (0.3, 3.0)
MAX_SEED = limits.MAX_SEED  # the command line's too
MAX_JSON_DEPTH = 8  # nesting of a request body (a generate body needs 3: object, points, pair)
GIF_MAX_FRAMES = 300  # 20 s at 15 Hz: matplotlib draws a few frames a second
STYLE_CACHE = 256  # style codes kept per (styles, z): the same style again costs no G call
SAMPLE_BUCKETS = (16, 32, 48, 64, 96, 128, 160, 192, 256, 320, 384, 512, 640, 768, 1024)
BATCH_BUCKETS = (1, 2, 4, 8)
WARM_FIRST_SAMPLES = 256  # warm_up compiles the buckets up to here first (21 s of walking at 15 Hz)
EXPORT_FORMATS = {"bvh": "text/plain", "npz": "application/octet-stream", "gif": "image/gif",
                  "glb": "model/gltf-binary"}
RIG_FORMATS = ("bvh", "glb")  # what a walk on a built-in rig can be downloaded as
# "Walk like this clip": an uploaded BVH file (read in memory by the strict reader, never written)
MAX_CLIP_BYTES = 4 * 2**20  # inside analysis.clips.MAX_CLIP_BYTES, like its frames and joints
MAX_CLIP_FRAMES = 18_000  # 5 minutes at 60 fps, 2.5 at 120
MAX_CLIP_JOINTS = 128
MAX_CLIP_NAME = 120
DIGITS = 4  # decimals of the metres sent to the page (0.1 mm)


class RequestError(ValueError):
    """A request the demo refuses (malformed, over a limit); the message says which and why."""


def bucket(n: int, sizes) -> int:
    """The smallest size >= n; RequestError past the largest."""
    for s in sizes:
        if n <= s:
            return s
    raise RequestError(f"{n} exceeds the largest size {sizes[-1]}")


@dataclasses.dataclass(frozen=True)
class Request:
    points: np.ndarray  # (P, 2) floor points, metres
    styles: tuple[str, ...]
    z: str | int
    seed: int
    speed: float | None
    rig: str | None = None  # a built-in rig's name (motion.rigs.BUILTIN_RIGS), None: the model's skeleton

    @property
    def motions(self) -> int:
        """How many motions it makes: one per style and z sample."""
        return len(self.styles) * (self.z if isinstance(self.z, int) else 1)


def decode_json(raw: bytes):
    """A request body decoded; RequestError when it is not JSON or nested deeper than
    MAX_JSON_DEPTH (the decoder recurses per level, so a deep body would end in RecursionError)."""
    too_deep = RequestError(f"the request body is nested too deeply (at most {MAX_JSON_DEPTH} levels)")
    try:
        data = json.loads(raw)
    except RecursionError:
        raise too_deep from None
    except ValueError as e:  # UnicodeDecodeError too
        raise RequestError(f"the request body is not valid JSON: {e}"[:200]) from None
    stack = [(data, 1)]
    while stack:
        item, depth = stack.pop()
        if isinstance(item, (list, dict)):
            if depth > MAX_JSON_DEPTH:
                raise too_deep
            stack.extend((v, depth + 1) for v in (item.values() if isinstance(item, dict) else item))
    return data


def _number(value, what: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise RequestError(f"{what} must be a number, got {type(value).__name__} {value!r}"[:200])
    try:
        value = float(value)
    except OverflowError:  # an integer beyond float range: JSON has no limit on digits
        raise RequestError(f"{what} must be a finite number, got an integer beyond float range") from None
    if not math.isfinite(value):
        raise RequestError(f"{what} must be a finite number, got {value}")
    return value


def _int(value, what: str, lo: int, hi: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise RequestError(f"{what} must be an integer {lo}..{hi}, got {value!r}"[:200])
    return int(value)


def parse_points(value, what: str = "points") -> np.ndarray:
    """(P, 2) float64 from a JSON list of [x, z] pairs in metres, checked against the limits."""
    if not isinstance(value, list):
        raise RequestError(f"{what} must be a list of [x, z] pairs in metres")
    if len(value) > MAX_POINTS:
        raise RequestError(f"{what}: {len(value)} points; the demo takes at most {MAX_POINTS}")
    for i, p in enumerate(value):
        if not (isinstance(p, list) and len(p) == 2):
            raise RequestError(f"{what}: entry {i} is not an [x, z] pair: {p!r}"[:200])
        for c in p:
            _number(c, f"{what}: entry {i}")
    pts = curves.check_curve(np.array(value, np.float64).reshape(-1, 2), "path")
    length = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
    if length > MAX_PATH_M:
        raise RequestError(f"path: {length:.1f} m long; the demo walks at most {MAX_PATH_M:g} m")
    return pts


def parse_request(body) -> Request:
    """A Request from the decoded JSON body; RequestError (or a curves error) naming the problem."""
    if not isinstance(body, dict):
        raise RequestError("the request body must be a JSON object")
    known = {"points", "styles", "z", "seed", "speed", "format", "index", "rig"}
    unknown = sorted(set(body) - known)
    if unknown:
        raise RequestError(f"unknown field(s) {', '.join(map(repr, unknown))}; known: {', '.join(sorted(known))}"[:300])
    if "points" not in body:
        raise RequestError("missing 'points': the path as a list of [x, z] pairs in metres")
    points = parse_points(body["points"])
    styles = body.get("styles", None)
    if isinstance(styles, str):
        styles = [styles]
    if not isinstance(styles, list) or not styles or not all(isinstance(s, str) for s in styles):
        raise RequestError("'styles' must be a non-empty list of style strings (a name, a mix "
                           "'A:0.3,B:0.7' or an expression 'A - B + C')")
    if len(styles) > MAX_STYLES:
        raise RequestError(f"{len(styles)} styles; the demo shows at most {MAX_STYLES} side by side")
    for s in styles:
        if len(s) > MAX_STYLE_CHARS:
            raise RequestError(f"a style of {len(s)} characters; at most {MAX_STYLE_CHARS}")
    z = body.get("z", "zero")
    if isinstance(z, str) and z.strip().isdecimal() and len(z.strip()) <= 3:  # int() takes every decimal digit
        z = int(z)
    if isinstance(z, str):
        if z.strip().lower() not in ("zero", "seed"):
            raise RequestError(f"'z' must be 'zero', 'seed' or a number of samples, got {z!r}"[:200])
    else:
        z = _int(z, "'z' (the number of samples)", 1, MAX_SAMPLES_Z)
    seed = _int(body.get("seed", 0), "'seed'", 0, MAX_SEED)
    speed = body.get("speed", None)
    if speed is not None:
        speed = _number(speed, "'speed'")
        lo, hi = SPEED_RANGE_M_PER_S
        if not lo <= speed <= hi:
            raise RequestError(f"'speed' must be {lo:g}..{hi:g} m/s, got {speed:g}")
    rig = body.get("rig", None)
    if rig is not None and (not isinstance(rig, str) or rig not in rigs.BUILTIN_RIGS):
        raise RequestError(f"'rig' must be one of {', '.join(rigs.BUILTIN_RIGS)} (or absent: the model's "
                           f"skeleton), got {rig!r}"[:200])
    return Request(points, tuple(styles), z, seed, speed, rig)


@dataclasses.dataclass(frozen=True, eq=False)
class Result:
    generated: walk.Generated  # cut to the curve's samples
    titles: tuple[str, ...]
    z_per_motion: np.ndarray  # (B, z_dim)
    notes: tuple[str, ...]
    samples_bucket: int
    batch_bucket: int


def _call(fn, *args):
    return fn(*args)


def _safe_name(text: str, at_most: int = 60, keep_end: bool = False, empty: str = "walk") -> str:
    """Only safe characters, at most `at_most` of them: the start kept, or the end (a file name's suffix)."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", text).strip("_")
    return (safe[-at_most:] if keep_end else safe[:at_most]) or empty


class Engine:
    """A loaded model and what the page does with it. Thread-safe: jitted calls may run from
    several request threads at once; nothing mutable is shared but the compile caches."""

    def __init__(self, state, meta: dict, cfg, layout, title: str = "", details: str = ""):
        self.state, self.meta, self.cfg, self.layout = state, meta, cfg, layout
        self.style_names = list(meta["style_names"])
        self.rate = walk.sample_rate(meta, cfg)
        self.title, self.details = title, details
        self._warm = threading.Event()
        self._walker_warm = threading.Event()  # the steer mode's stream window is compiled
        self._compiled: set[tuple[int, int]] = set()  # (sample bucket, batch bucket) G has run at
        self._compile_times: list[float] = []  # seconds of each first run at a new pair
        self._codes: collections.OrderedDict = collections.OrderedDict()
        self._codes_lock = threading.Lock()
        self._zero: np.ndarray | None = None  # the known styles' codes at z = 0 (clip_style)
        self.search_steps = search_lib.STEPS  # an uploaded clip's style search (motiongan-demo --search-steps)

    # -- model facts for the page ---------------------------------------------------------------
    def info(self) -> dict:
        return {
            "model": self.title, "model_details": self.details, "style_names": self.style_names,
            "joint_names": list(self.layout.joint_names), "parents": list(self.layout.parents),
            "fps": self.rate, "default_speed": user_curves.DEFAULT_SPEED_M_PER_S, "shapes": list(curves.SHAPES),
            "limits": {"max_points": MAX_POINTS, "max_path_m": MAX_PATH_M, "max_styles": MAX_STYLES,
                       "max_samples_z": MAX_SAMPLES_Z, "max_motions": MAX_MOTIONS,
                       "max_samples": SAMPLE_BUCKETS[-1], "speed_m_per_s": list(SPEED_RANGE_M_PER_S),
                       "gif_max_frames": GIF_MAX_FRAMES},
            "warm": self._warm.is_set(), "walker_warm": self._walker_warm.is_set(),
            # what the page can tell its user while it waits: which programs are compiled, how many to go
            "compiled": self.compiled(), "programs": len(warm_plan()), "compile_s": self.compile_seconds(),
            "buckets": {"samples": list(SAMPLE_BUCKETS), "batch": list(BATCH_BUCKETS)},
            "rigs": {name: desc for name, (_, _, desc) in rigs.BUILTIN_RIGS.items()},
        }

    def compiled(self) -> list[tuple[int, int]]:
        """The (sample bucket, batch bucket) pairs G has run at in this process."""
        with self._codes_lock:
            return sorted(self._compiled)

    def compile_seconds(self) -> float | None:
        """The median wait of a first run at a new (samples, batch) pair so far (None: none yet)."""
        with self._codes_lock:
            return round(float(np.median(self._compile_times)), 1) if self._compile_times else None

    def check_style(self, text) -> dict:
        """The parsed form of one style string (the page's live check); StyleError as generate.py."""
        if not isinstance(text, str) or len(text) > MAX_STYLE_CHARS:
            raise RequestError(f"'style' must be a string of at most {MAX_STYLE_CHARS} characters")
        spec = self._spec(text, 0)
        return {"kind": spec.kind, "text": spec.text, "terms": [[n, c] for n, c in spec.terms]}

    def _spec(self, text: str, seed: int) -> styles_lib.StyleSpec:
        # a .npy/.txt w file would be read from the server's disk: not from a web page
        if text.strip().lower().endswith((".npy", ".txt")):
            raise styles_lib.StyleError(f"style {text!r}: w files are not accepted by the demo (use "
                                     "bin/generate.py); give a name, a mix or an expression")
        return styles_lib.parse_style(text, self.style_names, seed)

    def shape(self, name, length=None, scale=None) -> np.ndarray:
        """A built-in shape's floor points (generate.user_curves.load_curve), at most a few hundred.
        Without a scale, one period of the shape at the given length (the page's presets: a
        circle of that circumference, a figure-8 of two lobes); without either, scale 2 m."""
        if not isinstance(name, str) or name not in curves.SHAPES:
            raise RequestError(f"unknown shape {name!r}; valid shapes: {', '.join(curves.SHAPES)}"[:200])
        length = None if length is None else _number(length, "'length'")
        if scale is None:
            scale = 2.0 if length is None or length <= 0 else curves.scale_for_length(name, length)
        scale = _number(scale, "'scale'")
        if length is not None and not 0 < length <= MAX_PATH_M:
            raise RequestError(f"'length' must be in (0, {MAX_PATH_M:g}] m, got {length:g}")
        if not 0 < scale <= MAX_PATH_M:
            raise RequestError(f"'scale' must be in (0, {MAX_PATH_M:g}] m, got {scale:g}")
        pts = user_curves.load_curve(name, length=length, scale=scale).points
        total = float(np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)))
        if total > MAX_PATH_M:
            raise RequestError(f"shape {name} at scale {scale:g} m is {total:.1f} m long; the demo "
                               f"walks at most {MAX_PATH_M:g} m")
        return curves.resample_polyline(pts, num_points=int(min(max(total / 0.05, 200), 1200)) + 1)

    def style_code(self, text, z="zero", seed=0) -> tuple[np.ndarray, str]:
        """(w (w_dim,), its canonical text) of one style string at z "zero" or "seed" (a steered
        walker has one code); the codes are remembered as generate's are."""
        if not isinstance(text, str) or not text.strip() or len(text) > MAX_STYLE_CHARS:
            raise RequestError(f"'style' must be a non-empty string of at most {MAX_STYLE_CHARS} characters")
        if not isinstance(z, str) or z.strip().lower() not in ("zero", "seed"):
            raise RequestError(f"'z' must be 'zero' or 'seed' for a steered walker, got {z!r}"[:200])
        seed = _int(seed, "'seed'", 0, MAX_SEED)
        spec = self._spec(text, seed)
        return self._spec_codes([spec], styles_lib.z_codes(self.state, z, seed))[0], spec.text

    def walker(self, w, start_xz=(0.0, 0.0), heading_xz=(1.0, 0.0), speed=None) -> stream.Walker:
        """A streaming walker (generate.stream) of this model, at the stream's default window: every
        walker of the process shares one compiled program."""
        speed = user_curves.DEFAULT_SPEED_M_PER_S if speed is None else speed
        return stream.Walker(self.state, self.layout, w, self.rate, start_xz=start_xz, heading_xz=heading_xz,
                             speed_m_per_s=speed)

    def export_joint_names(self) -> tuple[str, ...]:
        """The joints of the skeleton the page's GLB carries (the export's, ik.export_skeleton with
        the writers' defaults), in the order of local_quaternions."""
        ex = ik.export_skeleton(self.layout.joint_names, self.layout.parents, writers.rest_offsets(self.layout))
        return tuple(ex.skeleton.names)

    def local_quaternions(self, positions_TxJx3) -> np.ndarray:
        """(T, Je, 4) local joint rotations [x, y, z, w] (glTF's order) on export_joint_names'
        skeleton whose forward kinematics give `positions_TxJx3` (ik.solve_rotations, as the GLB's
        animation has them): a streamed walk posed on the page's character."""
        from scipy.spatial.transform import Rotation

        _, local, _ = ik.solve_rotations(np.asarray(positions_TxJx3, np.float64), self.layout.joint_names,
                                         self.layout.parents, writers.rest_offsets(self.layout))
        T, Je = local.shape[:2]
        return Rotation.from_matrix(local.reshape(-1, 3, 3)).as_quat().reshape(T, Je, 4)

    def _warm_walker(self) -> None:
        w, _ = self.style_code(self.style_names[0])
        wk = self.walker(w)
        n = wk.lookahead + 1
        wk.feed_steps(np.tile([1.0, 0.0], (n, 1)), np.full(n, user_curves.DEFAULT_SPEED_M_PER_S))
        wk.advance(1)
        self._walker_warm.set()

    # -- generation -----------------------------------------------------------------------------
    def run(self, req: Request, max_frames: int | None = None, max_motions: int = MAX_MOTIONS) -> Result:
        """G for a checked request; every limit (the caller's `max_frames`, a GIF's, included) is
        checked before G runs."""
        specs = [self._spec(s, req.seed) for s in req.styles]
        z = styles_lib.z_codes(self.state, req.z, req.seed)
        if len(specs) * len(z) > max_motions:
            raise RequestError(f"{len(specs)} styles x {len(z)} samples = {len(specs) * len(z)} "
                               f"motions; the demo makes at most {max_motions} at once")
        notes: list[str] = []
        curve_T = user_curves.prepare_curve(user_curves.Curve(req.points, "path"), self.rate, req.speed,
                                            log=notes.append)
        T = len(curve_T)
        if T > SAMPLE_BUCKETS[-1]:
            speed = req.speed or user_curves.DEFAULT_SPEED_M_PER_S
            raise RequestError(f"path: {T} samples at {speed:g} m/s ({T / self.rate:.0f} s of walking); "
                               f"the demo walks at most {SAMPLE_BUCKETS[-1]} "
                               f"({SAMPLE_BUCKETS[-1] / self.rate:.0f} s): draw a shorter path or walk faster")
        if max_frames is not None and T > max_frames:
            raise RequestError(f"GIF export takes at most {max_frames} frames ({max_frames / self.rate:.0f} s); "
                               f"this walk has {T}: download the BVH or NPZ")
        w = self._spec_codes(specs, z)
        B = len(w)
        Tb, Bb = bucket(T, SAMPLE_BUCKETS), bucket(B, BATCH_BUCKETS)
        w_pad = np.concatenate([w, np.repeat(w[-1:], Bb - B, axis=0)])
        new = (Tb, Bb) not in self.compiled()
        t0 = time.perf_counter()
        full = walk.generate_motion(self.state, self.layout, walk.extend_straight(curve_T, Tb - T), w_pad)
        with self._codes_lock:
            self._compiled.add((Tb, Bb))
            if new:  # compiled (or loaded from the persistent cache): what a first request waits
                self._compile_times.append(time.perf_counter() - t0)
        raw = full.positions[:B, :T].copy()
        raw[..., 1] -= full.floor_shift_m[:B, None, None]
        shift = walk.floor_shift(raw)
        raw[..., 1] += shift[:, None, None]
        cut = walk.Generated(raw, full.root_velocity[:B, :T], full.pose[:B, :T], curve_T, w, shift)
        titles = tuple(t if len(z) == 1 else f"{t} z{k}" for t in (s.text for s in specs) for k in range(len(z)))
        zs = np.concatenate([z] * len(specs))
        return Result(cut, titles, zs, tuple(notes), Tb, Bb)

    def _spec_codes(self, specs, z) -> np.ndarray:
        """generate.styles.spec_codes, remembered for the last STYLE_CACHE (styles, z): moving the
        speed or redrawing the path reuses them."""
        key = (tuple((s.kind, s.terms) for s in specs), z.tobytes())
        with self._codes_lock:
            if key in self._codes:
                self._codes.move_to_end(key)
                return self._codes[key]
        w = styles_lib.spec_codes(self.state, specs, self.style_names, z)
        w.setflags(write=False)  # shared by the requests that hit the cache
        with self._codes_lock:
            self._codes[key] = w
            while len(self._codes) > STYLE_CACHE:
                self._codes.popitem(last=False)
        return w

    def generate(self, body) -> dict:
        """The page's /api/generate: motions as nested lists (metres, DIGITS decimals)."""
        t0 = time.perf_counter()
        res = self.run(parse_request(body))
        g = res.generated
        t1 = time.perf_counter()
        out = {
            "fps": self.rate, "frames": int(g.positions.shape[1]),
            "curve": np.round(g.curve[:, [0, 2]].astype(np.float64), DIGITS).tolist(),
            "length_m": float(np.sum(np.linalg.norm(np.diff(g.curve, axis=0), axis=1))),
            "motions": [{"title": t, "positions": np.round(p, DIGITS).tolist()}
                        for t, p in zip(res.titles, g.positions)],
            "notes": list(res.notes), "samples_bucket": res.samples_bucket, "batch_bucket": res.batch_bucket,
        }
        out["server_ms"] = {"generate": round(1e3 * (t1 - t0), 2),
                            "serialise": round(1e3 * (time.perf_counter() - t1), 2)}
        return out

    def export(self, body, run=None) -> tuple[bytes, str, str]:
        """(file bytes, file name, MIME type) of /api/export: the motion `index` as .bvh/.npz, every
        motion side by side as .gif, or every motion as one animation each of a skinned character
        as .glb (what the page's 3-D view draws), written by generate.writers.write_outputs; with
        "rig" (.bvh, .glb) on that built-in rig. The request, the format, the index and the GIF's
        frame limit are checked before G runs; `run(fn, *args)` runs the generation (the server's
        generation slot), the file is written outside it."""
        if not isinstance(body, dict):
            raise RequestError("the request body must be a JSON object")
        fmt = body.get("format")
        if fmt not in EXPORT_FORMATS:
            raise RequestError(f"'format' must be one of {', '.join(EXPORT_FORMATS)}, got {fmt!r}"[:200])
        req = parse_request(body)
        if req.rig is not None and fmt not in RIG_FORMATS:
            raise RequestError(f"a walk on a rig downloads as {' or '.join(RIG_FORMATS)}, not {fmt}")
        rig = None if req.rig is None else rigs.load_rig(req.rig)
        suffix = f"_{req.rig}" if req.rig else ""
        if fmt in ("gif", "glb"):
            res = (run or _call)(self.run, req, GIF_MAX_FRAMES if fmt == "gif" else None)
            g = res.generated
            pick, titles, zs = g, res.titles, list(res.z_per_motion)
            name = "motiongan_" + _safe_name("_".join(res.titles)) + suffix + f".{fmt}"
        else:
            i = _int(body.get("index", 0), "'index'", 0, req.motions - 1)
            res = (run or _call)(self.run, req)
            g = res.generated
            pick = walk.Generated(g.positions[i:i + 1], g.root_velocity[i:i + 1], g.pose[i:i + 1],
                                  g.curve, g.w[i:i + 1], g.floor_shift_m[i:i + 1])
            titles, zs = (res.titles[i],), [res.z_per_motion[i]]
            name = f"motiongan_{_safe_name(res.titles[i])}{suffix}.{fmt}"
        with tempfile.TemporaryDirectory(prefix="motiongan-demo-") as tmp:
            paths = writers.write_outputs(Path(tmp) / name, pick, titles, self.layout, self.rate,
                                          z_per_motion=zs, rig=rig)
            return paths[0].read_bytes(), name, EXPORT_FORMATS[fmt]

    # -- walk like this clip --------------------------------------------------------------------
    def clip_style(self, data: bytes, name: str = "clip.bvh") -> dict:
        """The page's /api/clip: an uploaded BVH file's style as a mix of the known styles
        (analysis.search.search_style), its nearest styles and its speed. The file is bounded
        (MAX_CLIP_BYTES, MAX_CLIP_FRAMES, MAX_CLIP_JOINTS) and parsed in memory by the strict
        reader; a clip on another skeleton is retargeted onto the model's (analysis.clips); a
        malformed one, a skeleton it cannot retarget from or a motion without steps is a
        RequestError (400) naming the problem."""
        t0 = time.perf_counter()
        name = _safe_name(str(name), MAX_CLIP_NAME, keep_end=True, empty="clip.bvh")
        if not data:
            raise RequestError(f"{name}: empty file: expected a BVH file's text")
        if len(data) > MAX_CLIP_BYTES:
            raise RequestError(f"{name}: {len(data) / 2**20:.1f} MiB; the demo reads BVH files of at most "
                               f"{MAX_CLIP_BYTES // 2**20} MiB")
        text = bvh.decode(data)
        try:
            motion = bvh.parse_bvh(text, name, max_joints=MAX_CLIP_JOINTS, max_frames=MAX_CLIP_FRAMES)
            root, pose, fps = clips_lib.motion_rows(motion, name, self.cfg, self.layout)
            target = clips_lib.model_rate_windows(root, pose, fps, self.meta, self.cfg, self.layout,
                                                  spread=search_lib.WINDOWS, phase=True, source=name)
            found = search_lib.search_style(self.state, self._zero_codes(), self.style_names, target,
                                            steps=self.search_steps)
        except (bvh.BVHError, style_space.AnalysisError) as err:
            raise RequestError(str(err)) from None
        speed = target.spacing_m * self.rate
        return {"name": name, "style": found.mix_text(), "mix": found.mix(),
                "nearest": [[n, round(d, DIGITS)] for n, d in found.nearest[:3]],
                "speed": round(speed, 3), "frames": int(len(root)), "fps": float(fps),
                "seconds": round(len(root) / fps, 2), "windows": int(target.root_NxTx3.shape[0]),
                "search_ms": round(1e3 * found.seconds, 1), "server_ms": round(1e3 * (time.perf_counter() - t0), 1)}

    def _zero_codes(self) -> np.ndarray:
        """Every known style's code at z = 0 (the codes a mix is made of), computed once."""
        with self._codes_lock:
            codes = self._zero
        if codes is None:
            codes = np.asarray(style_space.label_codes(self.state, self.style_names, k=1).zero_CxD)
            with self._codes_lock:
                self._zero = codes
        return codes

    # -- warm-up --------------------------------------------------------------------------------
    def warm_up(self, run=None, plan=None) -> float:
        """Compiles G for every (sample bucket, batch bucket) of `plan` (default: warm_plan(), all
        the page can ask for) not compiled yet, the style codes of every z the page can ask for, the
        steer mode's stream window and the style search of an uploaded clip, so that no request
        waits for a compile; `run(fn, *args)`
        runs each (the server's generation slot). Returns seconds."""
        t0 = time.perf_counter()
        run = run or _call
        name = self.style_names[0]
        for k in range(1, MAX_SAMPLES_Z + 1):  # the latent codes of z = K (z = zero/seed: K = 1)
            run(self._spec_codes, [self._spec(name, 0)], styles_lib.z_codes(self.state, k, 0))
        if not self._walker_warm.is_set():  # one program serves every walker
            run(self._warm_walker)
        for T, B in plan or warm_plan():
            if (T, B) in self.compiled():
                continue
            # (T - 1/2) spacings long: exactly T samples, trimmed or padded by nothing
            pts = np.array([[0.0, 0.0], [(T - 0.5) * user_curves.DEFAULT_SPEED_M_PER_S / self.rate, 0.0]])
            run(self.run, Request(pts, (name,) * B, "zero", 0, None))
        run(self._warm_clip)
        self._warm.set()
        return time.perf_counter() - t0

    def _warm_clip(self) -> None:
        """The style search's one program (every upload has the same windows), compiled on G's own
        walk of an arc."""
        T = self.cfg.data.window_T
        n = search_lib.WINDOWS * T
        pts = curves.shape_curve("circle", length=(n - 0.5) * user_curves.DEFAULT_SPEED_M_PER_S / self.rate,
                                 scale=3.0, num_points=400)
        curve = user_curves.prepare_curve(user_curves.Curve(pts, "arc"), self.rate, None)
        gen = walk.generate_motion(self.state, self.layout, curve, self._zero_codes()[:1])
        root = gen.positions[0, :, 0]
        pose = (gen.positions[0, :, 1:] - root[:, None]).reshape(len(root), -1)
        target = clips_lib.model_rate_windows(root, pose, self.rate, self.meta, self.cfg, self.layout,
                                              spread=search_lib.WINDOWS, phase=True, source="warm-up")
        search_lib.search_style(self.state, self._zero_codes(), self.style_names, target, steps=self.search_steps)


def warm_plan() -> list[tuple[int, int]]:
    """Every (sample bucket, batch bucket) the page can ask for, most wanted first: one walk of
    ordinary length, then side by side and z samples, then long paths and 8 walks."""
    short = [T for T in SAMPLE_BUCKETS if T <= WARM_FIRST_SAMPLES]
    long = [T for T in SAMPLE_BUCKETS if T > WARM_FIRST_SAMPLES]
    return ([(T, B) for B in BATCH_BUCKETS[:3] for T in short] + [(T, 1) for T in long]
            + [(T, B) for B in BATCH_BUCKETS[1:3] for T in long] + [(T, BATCH_BUCKETS[3]) for T in short + long])
