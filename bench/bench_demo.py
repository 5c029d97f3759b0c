#!/usr/bin/env python
"""The demo's latency, server side (run by hand, never in CI). Prints medians.

Requests go through Flask's test client into the app motiongan-demo serves (JSON decode, the
request checks, style codes, curve resampling, G, the floor, JSON encode), with the shipped
model unless --workdir/--model is given. Each case is timed warm (after one untimed request of
its own), so compiling is excluded and reported on its own: the first request of a new sample
bucket, and a new path length inside a bucket already compiled (which must not compile again).
Cases: a 10 m S-curve (one style; a mix of two; an expression; three styles side by side;
K = 3 samples of z) and a drawn-looking 10 m path that changes a little every request.

  JAX_PLATFORMS=cpu python -m bench.bench_demo [--repeats 15] [--workdir RUN | --model FILE]
"""

import argparse
import statistics
import time

import numpy as np

from bench.timing import load


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=15)
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--model", default=None)
    args = ap.parse_args()

    from motiongan_jax.demo import server

    t0 = time.perf_counter()
    engine = server.load_engine(args.workdir, args.model)
    client = server.create_app(engine).test_client()
    print(f"{engine.details}\nloaded in {time.perf_counter() - t0:.1f} s; {load()}")
    names = engine.style_names
    s_curve = engine.shape("s_curve", 10.0).tolist()
    rng = np.random.default_rng(0)

    def drawn():
        """A 10 m wobbly path, different on every call (a new drawing each time)."""
        x = np.linspace(0, 9.0, 200)
        z = 1.5 * np.sin(x / 1.7 + rng.uniform(0, 0.3)) + rng.normal(0, 0.01, x.size)
        return np.stack([x, z], -1).tolist()

    def post(body):
        t = time.perf_counter()
        r = client.post("/api/generate", json=body)
        dt = time.perf_counter() - t
        assert r.status_code == 200, r.get_json()
        return dt, r.get_json()

    cases = [
        ("10 m S-curve, 1 style", lambda: {"points": s_curve, "styles": [names[0]]}),
        ("10 m S-curve, mix of 2", lambda: {"points": s_curve, "styles": [f"{names[0]}:0.3,{names[1]}:0.7"]}),
        ("10 m S-curve, expression", lambda: {"points": s_curve, "styles": [" - ".join(names[:2]) + f" + {names[2]}"]}),
        ("10 m S-curve, mix weights changing", None),
        ("10 m S-curve, 3 styles side by side", lambda: {"points": s_curve, "styles": names[:3]}),
        ("10 m S-curve, z = 3 samples", lambda: {"points": s_curve, "styles": [names[0]], "z": 3}),
        ("10 m drawn path, new every request", lambda: {"points": drawn(), "styles": [names[0]]}),
    ]
    print(f"\n{'case':40s} {'frames':>6s} {'bucket':>6s} {'request ms':>10s} {'server ms':>9s}")
    for name, make in cases:
        if make is None:  # a slider being dragged: a new mix every request
            weights = iter(np.linspace(0.05, 0.95, args.repeats + 1))
            make = lambda: {"points": s_curve, "styles": [f"{names[0]}:{next(weights):.3f},{names[1]}:1"]}  # noqa: E731
        first, out = post(make())
        times, server_ms = [], []
        for _ in range(args.repeats):
            dt, out = post(make())
            times.append(dt)
            server_ms.append(out["server_ms"]["generate"] + out["server_ms"]["serialise"])
        print(f"{name:40s} {out['frames']:6d} {out['samples_bucket']:6d} "
              f"{1e3 * statistics.median(times):10.1f} {statistics.median(server_ms):9.1f}"
              f"   (first: {1e3 * first:.0f} ms)")

    # compiling: a bucket never used before, then a new length inside it
    long_path = engine.shape("line", 30.0).tolist()
    dt_new, out = post({"points": long_path, "styles": [names[0]]})
    other = engine.shape("line", 28.0).tolist()
    dt_same, out2 = post({"points": other, "styles": [names[0]]})
    print(f"\nnew bucket ({out['frames']} frames -> {out['samples_bucket']}): {dt_new:.2f} s (compiles G)")
    print(f"new length in that bucket ({out2['frames']} frames -> {out2['samples_bucket']}): "
          f"{1e3 * dt_same:.0f} ms (no compile)")
    print(load())


if __name__ == "__main__":
    main()
