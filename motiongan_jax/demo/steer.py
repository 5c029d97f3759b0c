"""The page's steer mode: one streaming walker (generate.stream.Walker) per browser tab, fed the
path ahead that the tab predicts from its keys or gamepad.

A tab starts a walker (a session id), then asks for the next few samples whenever its buffer
runs low, sending the path it predicts from its current input for the samples not walked yet
(Walker.revise_ahead, then one Walker.advance); a style change blends in over BLEND_S seconds
of walk (Walker.set_style).

Transport: short polls, one request per few samples. They keep the server as it is (waitress's
request threads, the body limit, JSON errors) and let the tab's clock set the pace: a tab that
is slow or in the background asks for less and costs nothing. Server-sent events would hold one
of the server's few request threads per tab for as long as it is open and still need a request
per key change to send the path ahead, so they save nothing.

Bounds: at most MAX_WALKERS walkers at once (the next start is a 503 naming the limit), each
bounded by its rings (generate.stream); a walker without a request for IDLE_S seconds is dropped
(at the next steer request); a step emits at most MAX_POLL_SAMPLES samples (one G call), takes
at most MAX_AHEAD_POINTS points ahead, none faster than MAX_SPEED_M_PER_S, and runs in one of
STEP_SLOTS slots (a G call each, so that many walkers cannot pile up memory).
"""

from __future__ import annotations

import contextlib
import dataclasses
import secrets
import threading
import time

import numpy as np

from motiongan_jax.demo import engine as engine_lib
from motiongan_jax.demo.engine import DIGITS, RequestError, _int, _number
from motiongan_jax.generate import stream, user_curves

MAX_WALKERS = 8  # walkers (tabs) at once
IDLE_S = 30.0  # a walker without a request this long is dropped
BLEND_S = 1.0  # seconds of walk over which a new style blends in
MAX_POLL_SAMPLES = stream.MAX_STEP  # samples one step emits at most: one G call
MAX_AHEAD_POINTS = 4 * stream.LOOKAHEAD  # points of predicted path one step sends at most
MAX_SPEED_M_PER_S = engine_lib.SPEED_RANGE_M_PER_S[1]  # the page's top speed
SPEED_SLACK = 1.25  # a predicted step may be this much faster (a turn's chord, rounding)
STEP_SLOTS = 2  # steps running G at once (the machine's cores; the others wait)
WAIT_S = 10.0  # a step waits this long for a slot or its walker, then gets a 503 / 409
MAX_SESSION_CHARS = 64


class SteerError(RequestError):
    """A steer request refused with an HTTP status other than 400 (unknown walker 404, a request
    on a walker that another one holds 409, no room 503); the message says which and why."""

    def __init__(self, status: int, message: str, retry_after_s: float | None = None):
        super().__init__(message)
        self.status = status
        self.retry_after_s = retry_after_s


@dataclasses.dataclass(eq=False)
class Session:
    walker: stream.Walker
    style: str
    seen: float  # the clock at its last request
    rotations: bool = False  # each step also gives the joints' local rotations (the page's character)
    lock: threading.Lock = dataclasses.field(default_factory=threading.Lock)


def _fields(body, known: set[str], required: set[str]) -> dict:
    if not isinstance(body, dict):
        raise RequestError("the request body must be a JSON object")
    unknown = sorted(set(body) - known)
    if unknown:
        raise RequestError(f"unknown field(s) {', '.join(map(repr, unknown))}; known: {', '.join(sorted(known))}"[:300])
    missing = sorted(required - set(body))
    if missing:
        raise RequestError(f"missing field(s) {', '.join(map(repr, missing))}")
    return body


def _xz(value, what: str) -> np.ndarray:
    if not (isinstance(value, list) and len(value) == 2):
        raise RequestError(f"{what} must be an [x, z] pair in metres, got {value!r}"[:200])
    return np.array([_number(c, what) for c in value])


def parse_ahead(value) -> np.ndarray:
    """(N, 2) float64 from the JSON list of [x, z] pairs of a step's predicted path."""
    if not isinstance(value, list) or not value:
        raise RequestError("'ahead' must be a non-empty list of [x, z] pairs in metres: the predicted path, "
                           "one point per sample")
    if len(value) > MAX_AHEAD_POINTS:
        raise RequestError(f"'ahead': {len(value)} points; a step takes at most {MAX_AHEAD_POINTS}")
    return np.stack([_xz(p, f"'ahead': entry {i}") for i, p in enumerate(value)])


class SteeredWalkers:
    """The walkers of one server process (thread-safe). `clock` is injectable for tests."""

    def __init__(self, engine: engine_lib.Engine, clock=time.monotonic, max_walkers: int = MAX_WALKERS,
                 idle_s: float = IDLE_S):
        self.engine, self.clock = engine, clock
        self.max_walkers, self.idle_s = max_walkers, idle_s
        self._sessions: dict[str, Session] = {}
        self._lock = threading.Lock()
        self._slots = threading.BoundedSemaphore(STEP_SLOTS)

    # -- sessions -------------------------------------------------------------------------------
    def _purge(self) -> None:
        """Drops idle walkers (not those a request holds right now); under self._lock."""
        now = self.clock()
        for sid, s in list(self._sessions.items()):
            if now - s.seen > self.idle_s and not s.lock.locked():
                del self._sessions[sid]

    def _session(self, data) -> tuple[str, Session]:
        sid = data.get("session")
        if not isinstance(sid, str) or not 0 < len(sid) <= MAX_SESSION_CHARS:
            raise RequestError("'session' must be the id that /api/steer/start gave")
        with self._lock:
            self._purge()
            s = self._sessions.get(sid)
            if s is None:
                raise SteerError(404, f"no walker {sid!r} here (a walker without a request for {self.idle_s:g} s "
                                      "is dropped, as is one stopped or from before a restart): start a new one")
            s.seen = self.clock()
        return sid, s

    @contextlib.contextmanager
    def _hold(self, s: Session):
        """The walker to this request alone (Walker is not thread-safe)."""
        if not s.lock.acquire(timeout=WAIT_S):
            raise SteerError(409, f"another request on this walker has run for over {WAIT_S:g} s: "
                                  "send one step at a time")
        try:
            yield s.walker
        finally:
            s.lock.release()

    def start(self, body) -> dict:
        """A new walker: {"style", "z", "seed", "start": [x, z], "heading": [x, z], "speed",
        "rotations": false}; with "rotations" every step also gives each sample's local joint
        rotations on the export skeleton whose joint names the answer lists ("joints"): what poses
        the character of the page's GLB."""
        data = _fields(body, {"style", "z", "seed", "start", "heading", "speed", "rotations"}, {"style"})
        rotations = data.get("rotations", False)
        if not isinstance(rotations, bool):
            raise RequestError(f"'rotations' must be true or false, got {str(rotations)[:40]!r}")
        w, text = self.engine.style_code(data["style"], data.get("z", "zero"), data.get("seed", 0))
        start = _xz(data.get("start", [0.0, 0.0]), "'start'")
        heading = _xz(data.get("heading", [1.0, 0.0]), "'heading'")
        if np.hypot(*heading) < 1e-6:
            raise RequestError("'heading' must be a non-zero floor direction [x, z]")
        lo, hi = engine_lib.SPEED_RANGE_M_PER_S
        speed = _number(data.get("speed", user_curves.DEFAULT_SPEED_M_PER_S), "'speed'")
        if not lo <= speed <= hi:
            raise RequestError(f"'speed' must be {lo:g}..{hi:g} m/s, got {speed:g}")
        if np.abs(start).max() > 1e6:
            raise RequestError("'start' must lie within 1000 km of the origin")
        wk = self.engine.walker(w, start, heading, speed)
        sid = secrets.token_urlsafe(16)
        with self._lock:
            self._purge()
            if len(self._sessions) >= self.max_walkers:
                raise SteerError(503, f"the server steers at most {self.max_walkers} walkers at once and all are "
                                      f"in use; one is freed when its tab stops or is idle for {self.idle_s:g} s",
                                 retry_after_s=self.idle_s)
            self._sessions[sid] = Session(wk, text, self.clock(), rotations=rotations)
        joints = {"joints": list(self.engine.export_joint_names())} if rotations else {}
        return {**joints, "session": sid, "fps": self.engine.rate, "style": text, "next": 1,
                "last_point": np.round(start, DIGITS).tolist(), "lookahead": wk.lookahead,
                "max_samples": MAX_POLL_SAMPLES, "max_ahead": MAX_AHEAD_POINTS, "blend_s": BLEND_S,
                "idle_s": self.idle_s, "max_speed": MAX_SPEED_M_PER_S}

    def step(self, body) -> dict:
        """{"session", "from", "ahead", "samples"}: the path ahead from sample `from` (the
        walker's next sample, or 1 before the first step) replaced by `ahead`, then the next
        `samples` samples. `ahead` must reach `lookahead` samples beyond the last one asked for."""
        data = _fields(body, {"session", "from", "ahead", "samples"}, {"session", "from", "ahead", "samples"})
        n = _int(data["samples"], "'samples'", 1, MAX_POLL_SAMPLES)
        ahead = parse_ahead(data["ahead"])
        _, s = self._session(data)
        with self._hold(s):
            wk = s.walker
            nxt = max(wk.emitted, 1)  # the sample the path ahead starts at (0 is the start point)
            frm = _int(data["from"], "'from'", 0, 2 ** 53)
            if frm != nxt:
                raise SteerError(409, f"'from' is {frm}, but this walker's path ahead starts at sample {nxt}: "
                                      "send the path from there")
            need = n + wk.lookahead - (nxt - wk.emitted)
            if len(ahead) < need:
                raise RequestError(f"'ahead': {len(ahead)} points; {n} sample(s) need the path known "
                                   f"{wk.lookahead} samples beyond them: send at least {need}")
            steps = np.linalg.norm(np.diff(np.concatenate([wk.path_point(nxt - 1)[None], ahead]), axis=0), axis=1)
            fastest = float(steps.max()) * self.engine.rate
            if fastest > MAX_SPEED_M_PER_S * SPEED_SLACK:
                i = int(steps.argmax())
                raise RequestError(f"'ahead': the step into entry {i} is {steps[i]:.3g} m, {fastest:.3g} m/s at "
                                   f"{self.engine.rate:g} samples/s; the page steers at most {MAX_SPEED_M_PER_S:g} m/s")
            if not self._slots.acquire(timeout=WAIT_S):
                raise SteerError(503, f"the server is busy (more than {STEP_SLOTS} walker steps at once for "
                                      f"{WAIT_S:g} s); try again", retry_after_s=1.0)
            try:
                t0 = time.perf_counter()
                wk.revise_ahead(ahead)
                out = wk.advance(n)
                ms = 1e3 * (time.perf_counter() - t0)
            finally:
                self._slots.release()
            s.seen = self.clock()
            nxt = max(wk.emitted, 1)
            rot = ({"rotations": np.round(self.engine.local_quaternions(out.positions), 5).tolist()}
                   if s.rotations else {})
            return {**rot, "index0": out.index0, "positions": np.round(out.positions, DIGITS).tolist(),
                    "curve": np.round(out.curve[:, [0, 2]], DIGITS).tolist(),
                    "blend": [round(wk.style_progress(t), 4) for t in range(out.index0, out.index0 + len(out.curve))],
                    "style": s.style, "next": nxt, "last_point": np.round(wk.path_point(nxt - 1), DIGITS).tolist(),
                    "server_ms": {"generate": round(ms, 2)}}

    def style(self, body) -> dict:
        """{"session", "style", "z", "seed"}: the walker's style blends to this one over BLEND_S
        seconds from its next sample."""
        data = _fields(body, {"session", "style", "z", "seed"}, {"session", "style"})
        _, s = self._session(data)
        w, text = self.engine.style_code(data["style"], data.get("z", "zero"), data.get("seed", 0))
        with self._hold(s):
            s.walker.set_style(w, BLEND_S)
            s.style = text
            return {"style": text, "from": s.walker.emitted, "blend_s": BLEND_S}

    def stop(self, body) -> dict:
        data = _fields(body, {"session"}, {"session"})
        sid, _ = self._session(data)
        with self._lock:
            self._sessions.pop(sid, None)
        return {"stopped": True}

    def stats(self) -> dict:
        """How many walkers are live and what each holds (numbers: generate.stream.Walker.state_size)."""
        with self._lock:
            self._purge()
            sessions = list(self._sessions.values())
        return {"walkers": len(sessions), "max_walkers": self.max_walkers, "idle_s": self.idle_s,
                "emitted": [s.walker.emitted for s in sessions],
                "state_numbers": [s.walker.state_size() for s in sessions]}
