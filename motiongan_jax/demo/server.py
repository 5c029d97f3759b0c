"""The demo's HTTP side (Flask): the page, its JSON API, and the `motiongan-demo` command.

  motiongan-demo [--workdir RUN | --model FILE.npz] [--port 8000] [--host 127.0.0.1]

Routes (JSON in and out; every refusal is {"error": message} with a 4xx status):
  GET  /                 the page (static/, no file from outside this package)
  GET  /api/model        style names, skeleton, sample rate, limits, shapes
  GET  /api/shape        ?name=circle&length=10&scale=2: a built-in shape's floor points
  POST /api/style        {"style": "OldMan - Normal + Marching"}: its parsed form, or the error
  POST /api/generate     {"points", "styles", "z", "seed", "speed"}: the motions (engine.py)
  POST /api/export       the same plus "format" (bvh|npz|gif) and "index": the file
Bad input (generate.py's style and curve errors, the demo's limits) is a 400 with the message
bin/generate.py would print; a body over MAX_BODY_BYTES is a 413. Generation runs in the request
threads, at most MAX_CONCURRENT at once (the others wait up to QUEUE_TIMEOUT_S, then get a 503),
so many requests cannot pile up memory.
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from pathlib import Path

from flask import Flask, jsonify, request, send_from_directory
from werkzeug.exceptions import HTTPException

from motiongan_jax.cli import add_model_arguments
from motiongan_jax.data import curves
from motiongan_jax.demo import engine as engine_lib
from motiongan_jax.generate import limits
from motiongan_jax.motion.ik import IKError

STATIC = Path(__file__).resolve().parent / "static"
MAX_BODY_BYTES = 2 * 1024 * 1024
MAX_CONCURRENT = 2
QUEUE_TIMEOUT_S = 30.0
BAD_INPUT = (engine_lib.RequestError, limits.GenerateError, curves.DegenerateCurveError,
             curves.CurveFileError, IKError)


class Busy(Exception):
    pass


def create_app(engine: engine_lib.Engine) -> Flask:
    app = Flask(__name__, static_folder=None)
    app.config["MAX_CONTENT_LENGTH"] = MAX_BODY_BYTES
    slots = threading.BoundedSemaphore(MAX_CONCURRENT)

    def bounded(fn, *args):
        if not slots.acquire(timeout=QUEUE_TIMEOUT_S):
            raise Busy()
        try:
            return fn(*args)
        finally:
            slots.release()

    def body():
        data = request.get_json(silent=True)
        if data is None:
            raise engine_lib.RequestError("the request body must be JSON (Content-Type: application/json)")
        return data

    @app.errorhandler(HTTPException)
    def http_error(err):
        if err.code == 413:
            msg = f"request body too large: the demo takes at most {MAX_BODY_BYTES // 1024} KiB"
        else:
            msg = err.description
        return jsonify(error=msg), err.code

    def bad_input(err):
        return jsonify(error=str(err)), 400

    for exc in BAD_INPUT:
        app.register_error_handler(exc, bad_input)

    @app.errorhandler(Busy)
    def busy(_):
        return jsonify(error=f"the server is busy (more than {MAX_CONCURRENT} generations at once); "
                             "try again"), 503

    @app.get("/")
    def index():
        return send_from_directory(STATIC, "index.html")

    @app.get("/static/<path:name>")
    def static_file(name):
        return send_from_directory(STATIC, name)

    @app.get("/api/model")
    def model():
        return jsonify(engine.info())

    @app.get("/api/shape")
    def shape():
        args = request.args

        def num(key, default):
            if key not in args:
                return default
            try:
                return float(args[key])
            except ValueError:
                raise engine_lib.RequestError(f"'{key}' must be a number, got {args[key]!r}"[:200]) from None

        pts = engine.shape(args.get("name"), num("length", None), num("scale", 2.0))
        return jsonify(points=pts.round(engine_lib.DIGITS).tolist())

    @app.post("/api/style")
    def style():
        data = body()
        if not isinstance(data, dict) or "style" not in data:
            raise engine_lib.RequestError("expected {\"style\": \"...\"}")
        return jsonify(engine.check_style(data["style"]))

    @app.post("/api/generate")
    def generate():
        t0 = time.perf_counter()
        out = bounded(engine.generate, body())
        out["server_ms"]["total"] = round(1e3 * (time.perf_counter() - t0), 2)
        return jsonify(out)

    @app.post("/api/export")
    def export():
        data, name, mime = bounded(engine.export, body())
        return app.response_class(data, mimetype=mime,
                                  headers={"Content-Disposition": f'attachment; filename="{name}"'})

    return app


def load_engine(workdir=None, model=None, step=None, params="ema") -> engine_lib.Engine:
    from motiongan_jax.train import pretrained

    state, meta, cfg, layout = pretrained.load_model(workdir, step, params, model)
    if workdir is not None:
        title = f"run {Path(workdir).name} · {cfg.name} config · step {int(state.step)}"
        details = f"{Path(workdir).resolve()}, {params} parameters, config {meta.get('config_hash', '?')}"
    else:
        export = pretrained.read_export(pretrained.SHIPPED_MODEL if model is None else model)
        p = export.provenance
        title = (("shipped model" if model is None else export.path.name)
                 + f" · {cfg.name} config · {p['steps']} steps · seed {p['seed']}")
        details = export.describe()
    return engine_lib.Engine(state, meta, cfg, layout, title, details)


def _compilation_cache() -> None:
    """G's compiled programs persist between runs of the demo (unless the user set a cache)."""
    import jax

    if os.environ.get("JAX_COMPILATION_CACHE_DIR") or jax.config.jax_compilation_cache_dir:
        return
    from motiongan_jax.cache import cache_root

    jax.config.update("jax_compilation_cache_dir", str(cache_root() / "xla"))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="motiongan-demo", description="Draw a path, pick a style, watch it walk.")
    add_model_arguments(ap)
    ap.add_argument("--host", default="127.0.0.1",
                    help="address to listen on (default 127.0.0.1: this machine only)")
    ap.add_argument("--port", type=int, default=8000, help="port (default 8000; 0: any free port)")
    ap.add_argument("--no-warm-up", action="store_true", help="compile G on first use instead of at start")
    args = ap.parse_args(argv)
    if not 0 <= args.port <= 65535:
        ap.error(f"--port must be 0..65535, got {args.port}")

    from werkzeug.serving import make_server

    from motiongan_jax.train.checkpoint import CheckpointError

    _compilation_cache()
    try:
        engine = load_engine(args.workdir, args.model, args.step, args.params)
    except CheckpointError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    try:
        server = make_server(args.host, args.port, create_app(engine), threaded=True)
    except OSError as err:
        print(f"error: cannot listen on {args.host}:{args.port}: {err.strerror or err}", file=sys.stderr)
        return 2
    host = f"[{args.host}]" if ":" in args.host else args.host
    print(f"motiongan demo: {engine.details}", flush=True)
    print(f"serving on http://{host}:{server.server_port}/  (Ctrl-C to stop)", flush=True)
    if not args.no_warm_up:
        def warm():
            secs = engine.warm_up()
            print(f"warmed up in {secs:.1f} s (paths up to {engine_lib.WARM_MAX_SAMPLES} samples)", flush=True)

        threading.Thread(target=warm, daemon=True).start()
    try:
        server.serve_forever()
    except KeyboardInterrupt:
        pass
    finally:
        server.server_close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
