#!/usr/bin/env python
"""Cold starts (run by hand, never in CI): a fresh `motiongan-generate` end to end, and the first
request of each kind on a freshly started `motiongan-demo`, without the persistent compilation
cache (every process compiles G from nothing) and with it (a first process fills the cache
folder, the next ones load from it). Prints seconds of wall time and of CPU time (user + system:
the generate process's, or the server process's during the request), the CPU time being the
steadier figure on a shared machine. Each process is new, so nothing is warm in memory. The
cache folder is a temporary one, the user's is left alone.

  JAX_PLATFORMS=cpu python -m bench.bench_cold [--skip-server] [--skip-generate]
"""

import argparse
import json
import os
import re
import resource
import subprocess
import sys
import tempfile
import time
import urllib.error
import urllib.request

from bench.timing import load

GENERATE = ["--style", "Sad", "--curve", "s_curve", "--length", "10"]


def _env(cache: str | None) -> dict:
    env = {k: v for k, v in os.environ.items() if k not in ("JAX_COMPILATION_CACHE_DIR", "XLA_FLAGS")}
    env["MOTIONGAN_COMPILE_CACHE"] = cache or "off"
    env.setdefault("JAX_PLATFORMS", "cpu")
    return env


def generate_once(cache, out_dir) -> str:
    """'wall s (CPU s)' of one fresh motiongan-generate."""
    t, r0 = time.perf_counter(), resource.getrusage(resource.RUSAGE_CHILDREN)
    main = "from motiongan_jax.cli.generate import main; raise SystemExit(main())"  # motiongan-generate
    subprocess.run([sys.executable, "-c", main, *GENERATE, "--out", f"{out_dir}/w.npz"],
                   env=_env(cache), check=True, capture_output=True)
    r1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = r1.ru_utime + r1.ru_stime - r0.ru_utime - r0.ru_stime
    return f"{time.perf_counter() - t:6.1f} s wall ({cpu:5.1f} s CPU)"


def _cpu(pid: int) -> float:
    """User + system seconds of process `pid` so far (all its threads)."""
    with open(f"/proc/{pid}/stat") as fh:
        fields = fh.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _post(url, body, timeout=600):
    req = urllib.request.Request(url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"})
    t = time.perf_counter()
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            r.read()
            code = r.status
    except urllib.error.HTTPError as e:
        code = e.code
    return time.perf_counter() - t, code


def server_firsts(cache, warm_up: bool) -> list[tuple[str, float, float, int]]:
    """(kind, wall s, server CPU s, status) of the first request of each kind on a fresh server."""
    args = [sys.executable, "-m", "motiongan_jax.demo", "--port", "0"] + ([] if warm_up else ["--no-warm-up"])
    t_start = time.perf_counter()
    proc = subprocess.Popen(args, env=_env(cache), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    out = []
    try:
        base = None
        while base is None:
            line = proc.stdout.readline()
            if not line:
                raise RuntimeError("the demo exited")
            m = re.search(r"serving on (http://\S+)/", line)
            base = m.group(1) if m else None
        out.append(("start (model loaded, listening)", time.perf_counter() - t_start, _cpu(proc.pid), 0))
        if warm_up:
            t, c = time.perf_counter(), _cpu(proc.pid)
            while "warmed up" not in proc.stdout.readline():
                pass
            out.append(("background warm-up, all programs", time.perf_counter() - t, _cpu(proc.pid) - c, 0))
        t, c = time.perf_counter(), _cpu(proc.pid)
        with urllib.request.urlopen(base + "/api/model") as r:
            r.read()
        out.append(("GET /api/model", time.perf_counter() - t, _cpu(proc.pid) - c, 200))
        path10 = json.loads(urllib.request.urlopen(base + "/api/shape?name=s_curve&length=10").read())["points"]
        circle60 = json.loads(urllib.request.urlopen(base + "/api/shape?name=circle&length=60&scale=9.5")
                              .read())["points"]
        short = json.loads(urllib.request.urlopen(base + "/api/shape?name=line&length=4").read())["points"]
        kinds = [
            ("POST /api/style", "/api/style", {"style": "OldMan - Normal + Marching"}),
            ("generate: 10 m, 1 style", "/api/generate", {"points": path10, "styles": ["Sad"]}),
            ("generate: + side by side (2 styles)", "/api/generate", {"points": path10, "styles": ["Sad", "Happy"]}),
            ("generate: 3 styles side by side", "/api/generate",
             {"points": path10, "styles": ["Sad", "Happy", "Drunk"]}),
            ("generate: 60 m circle", "/api/generate", {"points": circle60, "styles": ["Sad"]}),
            ("generate: 10 m at 0.3 m/s", "/api/generate", {"points": path10, "styles": ["Sad"], "speed": 0.3}),
            ("generate: z = 3", "/api/generate", {"points": path10, "styles": ["Sad"], "z": 3}),
            ("export: BVH", "/api/export", {"points": path10, "styles": ["Sad"], "format": "bvh"}),
            ("export: GIF of a 4 m line", "/api/export", {"points": short, "styles": ["Sad"], "format": "gif"}),
        ]
        for kind, route, body in kinds:
            c = _cpu(proc.pid)
            dt, code = _post(base + route, body)
            out.append((kind, dt, _cpu(proc.pid) - c, code))
    finally:
        proc.terminate()
        proc.wait(30)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--skip-generate", action="store_true")
    ap.add_argument("--skip-server", action="store_true")
    ap.add_argument("--warm-up", action="store_true",
                    help="also time a server whose background warm-up compiles every program (minutes when cold)")
    args = ap.parse_args()
    print(load())
    with tempfile.TemporaryDirectory(prefix="bench-cold-") as tmp:
        cache = os.path.join(tmp, "xla")
        if not args.skip_generate:
            print("\nmotiongan-generate " + " ".join(GENERATE) + " --out w.npz, a fresh process each:")
            print(f"  no cache:                  {generate_once(None, tmp)}")
            print(f"  cache, first run (fills):  {generate_once(cache, tmp)}")
            for i in range(2):
                print(f"  cache, run {i + 2}:              {generate_once(cache, tmp)}")
        if not args.skip_server:
            runs = [("no cache", None, False), ("cache, first start (fills)", cache, False),
                    ("cache, second start", cache, False)]
            if args.warm_up:
                runs.append(("cache, warm-up first", cache, True))
            results = [(name, server_firsts(c, w)) for name, c, w in runs]
            kinds = [k for k, _, _, _ in results[-1][1]]
            print("\nfirst request of each kind on a fresh motiongan-demo, s wall (s of the server's CPU);"
                  " --no-warm-up unless said:")
            print(f"  {'kind':40s}" + "".join(f"{n:>30s}" for n, _ in results))
            for kind in kinds:
                row = []
                for _, res in results:
                    hit = [(dt, cpu, code) for k, dt, cpu, code in res if k == kind]
                    row.append(f"{hit[0][0]:16.2f} ({hit[0][1]:6.2f})"
                               + (f" {hit[0][2]}" if hit[0][2] not in (0, 200) else "    ") if hit else f"{'':>30s}")
                print(f"  {kind:40s}" + "".join(row))
    print(load())


if __name__ == "__main__":
    main()
