"""BVH files in and out: the Skeleton and Motion containers, a strict reader and a writer.

CONTRACT (other modules rely on exactly this; keep it):
- Skeleton.names: one name per joint in file (depth-first) order, End Sites included and
  named "<parent>_EndSite".
- Skeleton.parents: parent index per joint, -1 for the file root; parents[j] < j always.
- Skeleton.offsets: (J, 3) float64 OFFSETs in file units.
- Skeleton.channels: per joint, the channel names in file order (e.g. ("Xposition", ...,
  "Zrotation", "Xrotation", "Yrotation")); () for End Sites.
- Motion.values: (F, C) float64 raw channel values in file order, C = sum of channel counts.

Reader: any hierarchy, 1-6 distinct channels per joint (names matched case-insensitively and
stored in their standard spelling), any order; a second End Site under one joint is named
"<parent>_EndSite2" (and so on). Every problem raises BVHError("{file}:{line}: {problem}").
The frame block is parsed in bulk by numpy; a line-by-line pass runs only to explain a failure.
"""

from __future__ import annotations

import dataclasses
import io
import math
import os
import re
from pathlib import Path

import numpy as np

from motiongan_jax import atomic

CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")


class BVHError(ValueError):
    """A malformed BVH file. The message names the file, the line (when known) and the problem."""


@dataclasses.dataclass(frozen=True, eq=False)
class Skeleton:
    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray  # (J, 3) float64, file units
    channels: tuple[tuple[str, ...], ...]

    @property
    def num_joints(self) -> int:
        return len(self.names)

    @property
    def is_end_site(self) -> tuple[bool, ...]:
        return tuple(len(c) == 0 for c in self.channels)

    @property
    def num_channels(self) -> int:
        return sum(len(c) for c in self.channels)

    def channel_slices(self) -> tuple[slice, ...]:
        """Column range of each joint's channels inside Motion.values."""
        out, start = [], 0
        for ch in self.channels:
            out.append(slice(start, start + len(ch)))
            start += len(ch)
        return tuple(out)

    def rotation_order(self, j: int) -> str:
        """Intrinsic Euler order of joint j's rotation channels, e.g. "ZXY" ("" if none)."""
        return "".join(c[0].upper() for c in self.channels[j] if c.endswith("rotation"))


@dataclasses.dataclass(frozen=True, eq=False)
class Motion:
    skeleton: Skeleton
    frame_time: float  # seconds per frame
    values: np.ndarray  # (F, C) float64 raw channel values, file order
    source: str = "<memory>"

    @property
    def num_frames(self) -> int:
        return int(self.values.shape[0])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time


# ----------------------------------------------------------------------------------------------
# Reader
# ----------------------------------------------------------------------------------------------

_CANONICAL_CHANNEL = {c.lower(): c for c in CHANNEL_NAMES}
_TOKEN_RE = re.compile(r"[{}]|[^\s{}]+")
_FRAMES_RE = re.compile(r"Frames\s*:\s*(.*)")
_FRAME_TIME_RE = re.compile(r"Frame\s+Time\s*:\s*(.*)")
_INT_RE = re.compile(r"\+?[0-9]+")


class _Lines:
    """Hands out the lines of a text one at a time (1-based numbers) without splitting it all."""

    def __init__(self, text: str):
        self.text = text
        self.pos = 0
        self.lineno = 0

    def next(self) -> str | None:
        if self.pos >= len(self.text):
            return None
        end = self.text.find("\n", self.pos)
        if end < 0:
            end = len(self.text)
        line = self.text[self.pos : end]
        self.pos = end + 1
        self.lineno += 1
        return line

    def next_nonblank(self) -> str | None:
        while True:
            line = self.next()
            if line is None or line.strip():
                return line

    def rest(self) -> str:
        return self.text[self.pos :]


def _number(tok: str) -> float:
    """float() without the Python-only extras (digit separators); raises ValueError."""
    if "_" in tok:
        raise ValueError(tok)
    return float(tok)


def parse_bvh(text: str, source: str = "<string>", *, max_joints: int | None = None,
              max_frames: int | None = None) -> Motion:
    """Parse BVH text. Raises BVHError("{source}:{line}: {problem}") on anything malformed, and on
    more joints (End Sites included) than `max_joints` or a declared frame count over `max_frames`
    (checked before the frames are read: bounds for text from outside, e.g. an upload)."""
    if text.startswith("\ufeff"):
        text = text[1:]
    if "\r" in text:
        text = text.replace("\r\n", "\n").replace("\r", "\n")
    lines = _Lines(text)

    def fail(line: int, problem: str) -> BVHError:
        return BVHError(f"{source}:{max(line, 1)}: {problem}")

    names: list[str] = []
    parents: list[int] = []
    offsets: list[tuple[float, float, float] | None] = []
    channels: list[tuple[str, ...] | None] = []
    kinds: list[str] = []  # "ROOT", "JOINT" or "End Site"
    opened_at: list[int] = []
    first_seen: dict[str, int] = {}
    end_site_count: dict[int, int] = {}

    def describe(j: int) -> str:
        return f"{kinds[j]} {names[j]!r}" if kinds[j] != "End Site" else f"End Site of {names[parents[j]]!r}"

    def new_joint(name: str, parent: int, kind: str, lineno: int) -> int:
        if name in first_seen:
            raise fail(lineno, f"duplicate joint name {name!r} (first defined at line {first_seen[name]})")
        if max_joints is not None and len(names) >= max_joints:
            raise fail(lineno, f"more than {max_joints} joints (End Sites included); at most {max_joints} are read")
        first_seen[name] = lineno
        names.append(name)
        parents.append(parent)
        offsets.append(None)
        channels.append(None)
        kinds.append(kind)
        opened_at.append(lineno)
        return len(names) - 1

    def take_args(toks: list[str], k: int) -> tuple[list[str], int]:
        """Tokens from k up to a brace or the end of the line."""
        end = k
        while end < len(toks) and toks[end] not in "{}":
            end += 1
        return toks[k:end], end

    state = "start"  # start -> root -> open -> body (-> open -> body ...) -> after
    stack: list[int] = []
    pending = -1
    motion_found = False
    while not motion_found:
        line = lines.next()
        lineno = lines.lineno
        if line is None:
            if state == "start":
                raise fail(lineno, "empty file: expected HIERARCHY")
            if state == "root":
                raise fail(lineno, "expected ROOT, found end of file")
            if state == "open":
                raise fail(lineno, f"missing '{{' after {describe(pending)}: end of file")
            if state == "body":
                j = stack[-1]
                raise fail(lineno, f"missing '}}': {describe(j)} opened at line {opened_at[j]} "
                                   "is not closed at end of file")
            raise fail(lineno, "missing MOTION section")
        toks = _TOKEN_RE.findall(line)
        k = 0
        while k < len(toks):
            tok = toks[k]
            if state == "start":
                if tok != "HIERARCHY":
                    raise fail(lineno, f"expected HIERARCHY, found {tok!r}")
                state, k = "root", k + 1
            elif state == "root":
                if tok != "ROOT":
                    raise fail(lineno, f"expected ROOT, found {tok!r}")
                args, k = take_args(toks, k + 1)
                if not args:
                    raise fail(lineno, "ROOT without a name")
                pending, state = new_joint(" ".join(args), -1, "ROOT", lineno), "open"
            elif state == "open":
                if tok != "{":
                    raise fail(lineno, f"missing '{{': expected '{{' after {describe(pending)} "
                                       f"(line {opened_at[pending]}), found {tok!r}")
                stack.append(pending)
                state, k = "body", k + 1
            elif state == "body":
                j = stack[-1]
                if tok == "OFFSET":
                    args, k = take_args(toks, k + 1)
                    if offsets[j] is not None:
                        raise fail(lineno, f"second OFFSET in {describe(j)}")
                    if len(args) != 3:
                        raise fail(lineno, f"OFFSET needs 3 values, found {len(args)}")
                    try:
                        vals = tuple(_number(a) for a in args)
                    except ValueError:
                        raise fail(lineno, f"non-numeric OFFSET value in {' '.join(args)!r}") from None
                    if not all(math.isfinite(v) for v in vals):
                        raise fail(lineno, f"NaN or infinite OFFSET value in {' '.join(args)!r}")
                    offsets[j] = vals  # type: ignore[assignment]
                elif tok == "CHANNELS":
                    args, k = take_args(toks, k + 1)
                    if kinds[j] == "End Site":
                        raise fail(lineno, "an End Site cannot have CHANNELS")
                    if channels[j] is not None:
                        raise fail(lineno, f"second CHANNELS in {describe(j)}")
                    if not args or not _INT_RE.fullmatch(args[0]):
                        raise fail(lineno, f"bad CHANNELS count {args[0] if args else ''!r}: "
                                           "expected an integer from 1 to 6")
                    count, chans = int(args[0]), args[1:]
                    if not 1 <= count <= 6:
                        raise fail(lineno, f"bad CHANNELS count {count}: expected 1 to 6")
                    if count != len(chans):
                        raise fail(lineno, f"bad CHANNELS count: says {count} but lists {len(chans)} "
                                           "channel names")
                    canon = []
                    for c in chans:
                        if c.lower() not in _CANONICAL_CHANNEL:
                            raise fail(lineno, f"unknown channel name {c!r} (expected one of "
                                               f"{', '.join(CHANNEL_NAMES)})")
                        canon.append(_CANONICAL_CHANNEL[c.lower()])
                    if len(set(canon)) != len(canon):
                        raise fail(lineno, f"duplicate channel in {' '.join(chans)!r}")
                    channels[j] = tuple(canon)
                elif tok == "JOINT" or tok == "End":
                    if kinds[j] == "End Site":
                        raise fail(lineno, f"an End Site cannot have children (found {tok!r})")
                    if offsets[j] is None or channels[j] is None:
                        raise fail(lineno, f"{describe(j)} needs OFFSET and CHANNELS before its children")
                    if tok == "JOINT":
                        args, k = take_args(toks, k + 1)
                        if not args:
                            raise fail(lineno, "JOINT without a name")
                        pending = new_joint(" ".join(args), j, "JOINT", lineno)
                    else:
                        if k + 1 >= len(toks) or toks[k + 1] != "Site":
                            raise fail(lineno, "expected 'End Site'")
                        if k + 2 < len(toks) and toks[k + 2] not in "{}":
                            raise fail(lineno, f"unexpected {toks[k + 2]!r} after 'End Site'")
                        k += 2
                        n = end_site_count.get(j, 0) + 1
                        end_site_count[j] = n
                        name = f"{names[j]}_EndSite" + (str(n) if n > 1 else "")
                        pending = new_joint(name, j, "End Site", lineno)
                    state = "open"
                elif tok == "}":
                    if offsets[j] is None:
                        raise fail(lineno, f"{describe(j)} has no OFFSET")
                    if kinds[j] != "End Site" and channels[j] is None:
                        raise fail(lineno, f"{describe(j)} has no CHANNELS")
                    stack.pop()
                    k += 1
                    if not stack:
                        state = "after"
                elif tok == "MOTION":
                    raise fail(lineno, f"missing '}}': {describe(j)} opened at line {opened_at[j]} "
                                       "is not closed before MOTION")
                elif tok == "{":
                    raise fail(lineno, f"unexpected '{{' in {describe(j)}")
                else:
                    raise fail(lineno, f"unexpected {tok!r} in {describe(j)}")
            else:  # after the root's closing brace
                if tok == "MOTION":
                    if len(toks) > k + 1:
                        raise fail(lineno, f"unexpected {toks[k + 1]!r} after MOTION")
                    motion_found = True
                    break
                if tok == "}":
                    raise fail(lineno, "unbalanced '}': no block is open")
                if tok == "ROOT":
                    raise fail(lineno, "a second ROOT is not supported")
                raise fail(lineno, f"missing MOTION section: expected MOTION, found {tok!r}")

    # --- MOTION header ---------------------------------------------------------------------
    motion_line = lines.lineno
    line = lines.next_nonblank()
    m = _FRAMES_RE.fullmatch(line.strip()) if line is not None else None
    if m is None:
        found = "end of file" if line is None else repr(line.strip())
        raise fail(lines.lineno, f"missing 'Frames:' line after MOTION (line {motion_line}), found {found}")
    frames_line = lines.lineno
    if not _INT_RE.fullmatch(m.group(1).strip()):
        raise fail(frames_line, f"bad frame count {m.group(1).strip()!r}: expected a positive integer")
    declared = int(m.group(1))
    if declared == 0:
        raise fail(frames_line, "zero frames: 'Frames: 0'")
    if max_frames is not None and declared > max_frames:
        raise fail(frames_line, f"{declared} frames; at most {max_frames} are read")
    line = lines.next_nonblank()
    m = _FRAME_TIME_RE.fullmatch(line.strip()) if line is not None else None
    if m is None:
        found = "end of file" if line is None else repr(line.strip())
        raise fail(lines.lineno, f"missing 'Frame Time:' line, found {found}")
    time_line = lines.lineno
    try:
        frame_time = _number(m.group(1).strip())
    except ValueError:
        raise fail(time_line, f"bad frame time {m.group(1).strip()!r}: not a number") from None
    if not (math.isfinite(frame_time) and frame_time > 0):
        raise fail(time_line, f"non-positive frame time {m.group(1).strip()!r}: must be a finite number > 0")

    # --- frames: numpy's C parser in bulk; a Python pass only to explain a failure ----------
    num_channels = sum(len(c) for c in channels if c)
    block = lines.rest()
    values = None
    if block.strip():
        try:
            arr = np.loadtxt(io.StringIO(block), dtype=np.float64, comments=None, ndmin=2)
            if arr.shape == (declared, num_channels) and np.isfinite(arr).all():
                values = arr
        except ValueError:
            pass
    if values is None:
        _explain_bad_frames(block, time_line, declared, frames_line, num_channels, fail)

    skeleton = Skeleton(
        names=tuple(names),
        parents=tuple(parents),
        offsets=np.asarray(offsets, dtype=np.float64).reshape(len(names), 3),
        channels=tuple(c if c is not None else () for c in channels),
    )
    return Motion(skeleton=skeleton, frame_time=float(frame_time), values=values, source=source)


def _explain_bad_frames(block, before_line, declared, frames_line, num_channels, fail):
    """Find the first problem in the frame lines and raise it (slow path, errors only)."""
    frame = 0
    for i, line in enumerate(block.split("\n")):
        toks = line.split()
        if not toks:
            continue
        lineno = before_line + 1 + i
        if frame >= declared:
            raise fail(lineno, f"more frames than declared: 'Frames: {declared}' (line {frames_line}) "
                               f"but frame {frame + 1} starts here")
        if len(toks) != num_channels:
            raise fail(lineno, f"wrong number of values in frame {frame + 1}: expected {num_channels}, "
                               f"found {len(toks)}")
        for tok in toks:
            try:
                v = _number(tok)
            except ValueError:
                raise fail(lineno, f"non-numeric value {tok!r} in frame {frame + 1}") from None
            if not math.isfinite(v):
                raise fail(lineno, f"NaN or infinite value {tok!r} in frame {frame + 1}")
        frame += 1
    if frame < declared:
        raise fail(frames_line, f"fewer frames than declared: 'Frames: {declared}' but the file has "
                                f"{frame} frame lines")
    raise fail(frames_line, "unreadable motion data")  # numpy refused something float() accepts


def read_bvh(path: str | os.PathLike) -> Motion:
    """Read one BVH file (UTF-8, falling back to Latin-1). Raises BVHError naming the file."""
    return parse_bvh(decode(Path(path).read_bytes()), source=str(path))


def decode(data: bytes) -> str:
    """A BVH file's bytes as text: UTF-8, falling back to Latin-1 (which decodes any bytes)."""
    try:
        return data.decode("utf-8")
    except UnicodeDecodeError:
        return data.decode("latin-1")


def read_bvh_dir(
    root: str | os.PathLike, *, skip_bad: bool = False, pattern: str = "*.bvh"
) -> tuple[list[Motion], list[BVHError]]:
    """Read every file matching `pattern` under `root` (recursive), sorted by relative path.

    By default the first bad file raises its BVHError. With skip_bad=True bad files are skipped
    and their errors returned alongside the motions that were read.
    """
    root = Path(root)
    if not root.is_dir():
        raise NotADirectoryError(f"{root}: not a directory")
    paths = sorted((p for p in root.rglob(pattern) if p.is_file()),
                   key=lambda p: p.relative_to(root).parts)
    motions: list[Motion] = []
    errors: list[BVHError] = []
    for p in paths:
        try:
            motions.append(read_bvh(p))
        except BVHError as e:
            if not skip_bad:
                raise
            errors.append(e)
    return motions, errors


# ----------------------------------------------------------------------------------------------
# Writer
# ----------------------------------------------------------------------------------------------

def _format_bvh(motion: Motion, precision: int, where: str) -> str:
    """BVH text for `motion`; raises BVHError(f"{where}: problem") if it cannot be written faithfully."""

    def fail(problem: str) -> BVHError:
        return BVHError(f"{where}: {problem}")

    sk = motion.skeleton
    J = sk.num_joints
    if not (isinstance(precision, (int, np.integer)) and 0 <= precision <= 17):
        raise fail(f"precision must be an integer from 0 to 17, got {precision!r}")
    if J == 0:
        raise fail("skeleton has no joints")
    if not len(sk.parents) == len(sk.channels) == J:
        raise fail("names, parents and channels differ in length")
    offsets = np.asarray(sk.offsets, dtype=np.float64)
    if offsets.shape != (J, 3):
        raise fail(f"offsets have shape {offsets.shape}, expected ({J}, 3)")
    if not np.isfinite(offsets).all():
        raise fail("NaN or infinite OFFSET")
    if sk.parents[0] != -1 or any(not 0 <= p < j for j, p in enumerate(sk.parents) if j > 0):
        raise fail("parents must be -1 for joint 0 and satisfy 0 <= parents[j] < j otherwise")
    children: list[list[int]] = [[] for _ in range(J)]
    for j, p in enumerate(sk.parents[1:], start=1):
        children[p].append(j)
    order, todo = [], [0]
    while todo:
        j = todo.pop()
        order.append(j)
        todo.extend(reversed(children[j]))
    if order != list(range(J)):
        raise fail("joints are not in depth-first order (the order of a BVH file)")
    seen: set[str] = set()
    for j, (name, ch) in enumerate(zip(sk.names, sk.channels)):
        if not ch:
            if j == 0 or children[j]:
                raise fail(f"joint {name!r} has no channels but is the root or has children")
            continue
        if not name or name != " ".join(name.split()) or "{" in name or "}" in name:
            raise fail(f"joint name {name!r} cannot be written (empty, braces or odd whitespace)")
        if name in seen:
            raise fail(f"duplicate joint name {name!r}")
        seen.add(name)
        if len(ch) > 6 or len(set(ch)) != len(ch) or any(c not in CHANNEL_NAMES for c in ch):
            raise fail(f"joint {name!r} has bad channels {ch!r}")
    values = np.asarray(motion.values, dtype=np.float64)
    C = sk.num_channels
    if values.ndim != 2 or values.shape[1] != C:
        raise fail(f"values have shape {values.shape}, expected (frames, {C})")
    if values.shape[0] == 0:
        raise fail("zero frames")
    if not np.isfinite(values).all():
        f = int(np.flatnonzero(~np.isfinite(values).all(axis=1))[0])
        raise fail(f"NaN or infinite value in frame {f + 1}")
    ft = float(motion.frame_time)
    if not (math.isfinite(ft) and ft > 0):
        raise fail(f"non-positive frame time {motion.frame_time!r}")

    num = f"%.{precision}f"
    out = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        ind = "\t" * depth
        if j == 0:
            out.append(f"ROOT {sk.names[0]}")
        elif not sk.channels[j]:
            out.append(f"{ind}End Site")
        else:
            out.append(f"{ind}JOINT {sk.names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET " + " ".join(num % v for v in offsets[j]))
        if sk.channels[j]:
            out.append(f"{ind}\tCHANNELS {len(sk.channels[j])} " + " ".join(sk.channels[j]))
        for c in children[j]:
            emit(c, depth + 1)
        out.append(f"{ind}}}")

    emit(0, 0)
    out += ["MOTION", f"Frames: {values.shape[0]}", f"Frame Time: {ft!r}"]
    row = " ".join([num] * C)
    out.extend(row % tuple(r) for r in values.tolist())
    return "\n".join(out) + "\n"


def write_bvh(path: str | os.PathLike, motion: Motion, precision: int = 6) -> None:
    """Write `motion` as BVH text, atomically (temporary file in the same folder, then rename).

    Values and offsets are printed with `precision` decimals. End Sites are the joints without
    channels; their names are not stored in BVH (the reader calls them "<parent>_EndSite").
    Raises BVHError for a motion that cannot be written (NaN, bad shapes, ...) and OSError for
    file-system problems; in both cases no file is left behind.
    """
    path = Path(path)
    text = _format_bvh(motion, precision, str(path))
    atomic.write_text(path, text)
