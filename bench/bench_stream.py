#!/usr/bin/env python
"""Streaming generation's cost (generate/stream.py, the demo's steer mode; run by hand, never in CI).
Prints medians.

One walker with the shipped model (or --workdir/--model) steered along a wandering heading:
 * library: one `Walker.advance` of --step samples (G on one window, the phase clock, blending,
   integration, the floor), warm (the window's compile is timed apart);
 * server: one steer step through the demo's app (demo/steer.py via Flask's test client: the JSON
   in and out, the checks, revise_ahead and advance) of 1, 4, 8 and 16 samples, per step and per
   sample;
 * walkers one process holds, computed from the step times (walkers stepped one after another,
   never batched into one G call): at --hz, each walker stepped --hz times a second for one sample
   (1 / (hz x a 1-sample step)); and at the page's pace, each asking for 8 samples at a time
   (rate / 8 steps a second);
 * walkers held, run: N page loops (below) at once in real time with frames at --hz for
   --hold-s seconds, through the server's step slots: the share of time each one's display clock
   had to wait for samples (0: it never stopped), for N = 1, 2, 4, 6, 8;
 * key to visible turn: app.js's steer loop re-enacted in real time (its constants: the turn rate
   eased in over 0.1 s, the predicted path, a step of at least 4 samples in another thread
   whenever the buffer falls below its target, the display clock at real time), a turn key held
   from a random moment: the seconds until the shown heading (the root's direction over the last
   8 samples) has turned 20 degrees. This is the page's delay less the browser's drawing and the
   network. Beside it the same delay of the input's own path drawn the instant it is made
   (`ideal_turn_delay`: the turn rate and the heading's window alone); the difference is the latency
   the server, the buffer and G add.
The machine is shared: every figure is printed with the load average (bench.timing.load).

  JAX_PLATFORMS=cpu python -m bench.bench_stream [--steps 60] [--step 1] [--hz 30] [--turns 5]
"""

import argparse
import math
import os
import statistics
import threading
import time

import numpy as np

from bench.timing import load

# app.js's steer constants
TURN_RATE = 1.2  # rad/s with a turn key held
TURN_EASE_S = 0.1
MIN_STEP = 4  # samples a step asks for at least
HEADING_SPAN = 8  # samples: the shown heading is the root's direction over these
TURNED_DEG = 20.0


def _post(client, path, body):
    r = client.post(path, json=body)
    out = r.get_json()
    if r.status_code != 200:
        raise RuntimeError(f"{path}: {r.status_code} {out}")
    return out


class PageClient:
    """app.js's steer loop for one walker, driven by `frame(dt, turn)` at the display's rate."""

    def __init__(self, client, speed=1.2):
        self.client, self.speed = client, speed
        st = _post(client, "/api/steer/start", {"style": "Normal", "speed": speed})
        self.sid, self.rate, self.lookahead = st["session"], st["fps"], st["lookahead"]
        self.max_samples = st["max_samples"]
        self.next, self.last, self.psi = st["next"], np.array(st["last_point"]), 0.0
        self.omega, self.clock, self.rtt = 0.0, 0.0, 0.15
        self.roots: list[np.ndarray] = []  # every sample's root (x, z)
        self.steps: list[float] = []  # seconds per step (round trip in the process)
        self.lock = threading.Lock()
        self.thread = None
        self.waited = 0.0  # seconds the display clock stood still for want of samples

    def target(self) -> int:
        return int(min(max(math.ceil(self.rate * (0.05 + 1.5 * self.rtt)), 2), self.max_samples))

    def _step(self, n: int) -> None:
        with self.lock:
            frm, last, psi, omega = self.next, self.last.copy(), self.psi, self.omega
        pts, psis = [], []
        for _ in range(n + self.lookahead):
            psi += omega / self.rate
            last = last + self.speed / self.rate * np.array([np.cos(psi), np.sin(psi)])
            pts.append(np.round(last, 4).tolist())
            psis.append(psi)
        t0 = time.perf_counter()
        out = _post(self.client, "/api/steer/step", {"session": self.sid, "from": frm, "samples": n, "ahead": pts})
        dt = time.perf_counter() - t0
        with self.lock:
            self.roots += [np.array(p[0])[[0, 2]] for p in out["positions"]]
            used = out["next"] - frm
            if used > 0:
                self.psi = psis[used - 1]
            self.next, self.last = out["next"], np.array(out["last_point"])
            self.rtt = 0.8 * self.rtt + 0.2 * min(dt, 1.0)
            self.steps.append(dt)

    def frame(self, dt: float, turn: float) -> None:
        self.omega += (TURN_RATE * turn - self.omega) * min(1.0, dt / TURN_EASE_S)
        with self.lock:
            end = len(self.roots) - 1
            if end >= 0:
                to = self.clock + dt * self.rate
                if to > end:
                    self.waited += (to - max(end, self.clock)) / self.rate
                self.clock = max(self.clock, min(to, end))
            buffered = end - self.clock
        if (self.thread is None or not self.thread.is_alive()) and buffered < self.target():
            n = int(min(max(math.ceil(self.target() - buffered) + 1, MIN_STEP), self.max_samples))
            self.thread = threading.Thread(target=self._step, args=(n,))
            self.thread.start()

    def shown_heading(self) -> float | None:
        with self.lock:
            i = int(self.clock)
            if i < HEADING_SPAN:
                return None
            d = self.roots[i] - self.roots[i - HEADING_SPAN]
        return math.atan2(d[1], d[0])


def key_to_turn(app, rng, fps=60.0, settle_s=4.0, limit_s=4.0) -> tuple[float, float]:
    """(seconds from a turn key going down to a 20-degree turn of the shown heading, median step s)."""
    page = PageClient(app.test_client())
    press = settle_s + rng.uniform(0, 1)
    t0 = time.perf_counter()
    last = t0
    before = delay = None
    while delay is None:
        time.sleep(1 / fps)
        now = time.perf_counter()
        t = now - t0
        page.frame(now - last, 1.0 if t >= press else 0.0)
        last = now
        h = page.shown_heading()
        if t < press:
            before = h
        elif h is not None and before is not None:
            if math.degrees(abs(math.remainder(h - before, 2 * math.pi))) >= TURNED_DEG:
                delay = t - press
        if t > press + limit_s:
            delay = float("nan")
    if page.thread is not None:
        page.thread.join()
    _post(app.test_client(), "/api/steer/stop", {"session": page.sid})
    return delay, statistics.median(page.steps[1:])


def ideal_turn_delay(rate: float, fps: float = 60.0) -> float:
    """Seconds from the key going down until the input's own path, drawn the instant it is made (no
    server, no buffer, no body), turns the shown heading (over HEADING_SPAN samples) by TURNED_DEG:
    what the turn rate, its easing and the heading's window take. The rest of key_to_turn's delay
    is the system's latency."""
    omega = psi = 0.0
    path = [np.zeros(2)] * (HEADING_SPAN + 1)
    t, next_sample = 0.0, 0.0
    while True:
        t += 1 / fps
        omega += (TURN_RATE - omega) * min(1.0, (1 / fps) / TURN_EASE_S)
        psi += omega / fps
        while next_sample <= t:
            path.append(path[-1] + np.array([math.cos(psi), math.sin(psi)]) / rate)
            next_sample += 1 / rate
        d = path[-1] - path[-1 - HEADING_SPAN]
        if math.degrees(abs(math.atan2(d[1], d[0]))) >= TURNED_DEG:
            return t


def hold(app, n: int, hz: float, seconds: float) -> tuple[float, float]:
    """n page loops at once in real time, frames at hz: (the largest share of time a walker's
    display clock waited for samples, steps served per second)."""
    pages = [PageClient(app.test_client()) for _ in range(n)]

    def run(secs):
        t0 = last = time.perf_counter()
        while (now := time.perf_counter()) - t0 < secs:
            for p in pages:
                p.frame(now - last, 0.0)
            last = now
            time.sleep(max(0.0, 1 / hz - (time.perf_counter() - now)))

    run(2.0)  # the first samples, buffers filled
    for p in pages:
        p.waited = 0.0
    steps0 = sum(len(p.steps) for p in pages)
    run(seconds)
    served = (sum(len(p.steps) for p in pages) - steps0) / seconds
    for p in pages:
        if p.thread is not None:
            p.thread.join()
        _post(app.test_client(), "/api/steer/stop", {"session": p.sid})
    return max(p.waited for p in pages) / seconds, served


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--steps", type=int, default=60, help="timed advances (and server steps per size)")
    ap.add_argument("--step", type=int, default=1, help="samples per library advance")
    ap.add_argument("--hz", type=float, default=30.0, help="steps per second each walker gets")
    ap.add_argument("--turns", type=int, default=5, help="key-to-turn trials (about 6 s of real time each)")
    ap.add_argument("--hold-s", type=float, default=8.0, help="seconds each run of N walkers at once lasts")
    ap.add_argument("--lookahead", type=int, default=None)
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--model", default=None)
    args = ap.parse_args()

    from motiongan_jax.demo import server
    from motiongan_jax.generate import stream
    from motiongan_jax.model import apply as model_apply

    print(f"{load()}, {os.cpu_count()} CPUs visible", flush=True)
    engine = server.load_engine(args.workdir, args.model)
    state, layout, rate = engine.state, engine.layout, engine.rate
    w = np.asarray(model_apply.style_codes(state, [0]))[0]
    kw = {} if args.lookahead is None else {"lookahead": args.lookahead}
    wk = stream.Walker(state, layout, w, rate, **kw)
    rng = np.random.default_rng(0)
    heading = 0.0

    def feed(n):
        nonlocal heading
        heading += rng.normal(0, 0.05)
        wk.feed_steps(np.tile([np.cos(heading), np.sin(heading)], (n, 1)), np.full(n, 1.2))

    feed(wk.lookahead + args.step)
    t0 = time.perf_counter()
    wk.advance(args.step)
    first = time.perf_counter() - t0
    times = []
    for _ in range(args.steps):
        feed(args.step)
        t0 = time.perf_counter()
        wk.advance(args.step)
        times.append(time.perf_counter() - t0)
    med = statistics.median(times)
    print(f"rate {rate:g} samples/s, window {wk.window} samples (history {wk.history}, lookahead {wk.lookahead}), "
          f"lookahead latency {wk.lookahead / rate:.2f} s when the path is only appended")
    print(f"first advance (compile included): {first:.2f} s")
    print(f"library: advance of {args.step} sample(s): median {1e3 * med:.1f} ms, "
          f"p90 {1e3 * np.percentile(times, 90):.1f} ms over {args.steps}", flush=True)

    # the server's steer step, as the page sends it
    app = server.create_app(engine)
    client = app.test_client()
    per_step = {}
    for n in (1, 4, 8, 16):
        page = PageClient(client)
        page._step(n)  # the first: warm
        page.steps.clear()
        for _ in range(args.steps):
            page._step(n)
        per_step[n] = statistics.median(page.steps)
        _post(client, "/api/steer/stop", {"session": page.sid})
        print(f"server: step of {n:2d} sample(s): median {1e3 * per_step[n]:.1f} ms, "
              f"p90 {1e3 * np.percentile(page.steps, 90):.1f} ms, {1e3 * per_step[n] / n:.1f} ms per sample",
              flush=True)
    print(f"walkers in one process, stepped {args.hz:g} times a second for one sample each: "
          f"{1 / (args.hz * per_step[1]):.1f}")
    print(f"walkers in one process at the page's pace ({rate:g} samples/s each, 8 a step): "
          f"{1 / (rate / 8 * per_step[8]):.1f} (the server admits {server.steer_lib.MAX_WALKERS})", flush=True)
    for n in (1, 2, 4, 6, 8):
        waited, served = hold(app, n, args.hz, args.hold_s)
        print(f"{n} walker(s) at once, frames at {args.hz:g} Hz for {args.hold_s:g} s: the display clock waited "
              f"{100 * waited:.1f} % of the time at most, {served:.1f} steps/s served", flush=True)

    delays, steps = [], []
    for _ in range(args.turns):
        d, s = key_to_turn(app, rng)
        delays.append(d)
        steps.append(s)
    ideal = ideal_turn_delay(rate)
    print(f"key to a {TURNED_DEG:g}-degree turn of the shown heading: median {statistics.median(delays):.2f} s "
          f"(trials {', '.join(f'{d:.2f}' for d in delays)}; median step round trip "
          f"{1e3 * statistics.median(steps):.0f} ms); the input's own path drawn at once takes {ideal:.2f} s "
          f"(the turn rate, eased, over the heading's {HEADING_SPAN} samples): latency "
          f"{statistics.median(delays) - ideal:.2f} s")
    print(f"state after {wk.emitted} samples: {wk.state_size()} numbers; {load()}")


if __name__ == "__main__":
    main()
