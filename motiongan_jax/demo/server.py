"""The demo's HTTP side (Flask): the page, its JSON API, and the `motiongan-demo` command.

  motiongan-demo [--workdir RUN | --model FILE.npz] [--port 8000] [--host 127.0.0.1] [--debug]

Served by waitress (a production WSGI server: THREADS request threads, at most CONNECTIONS open
connections, a connection idle or trickling for IDLE_TIMEOUT_S closed); `--debug` serves through
Flask's development server instead, on this machine only.

Routes (JSON in and out; every refusal is {"error": message} with a 4xx status):
  GET  /                 the page (static/, no file from outside this package)
  GET  /api/model        style names, skeleton, sample rate, limits, shapes
  GET  /api/shape        ?name=circle&length=10&scale=2: a built-in shape's floor points
  POST /api/style        {"style": "OldMan - Normal + Marching"}: its parsed form, or the error
  POST /api/generate     {"points", "styles", "z", "seed", "speed"}: the motions (engine.py)
  POST /api/export       the same plus "format" (bvh|npz|gif|glb), "index" and "rig": the file
  POST /api/clip         a BVH file's bytes as the body (?name=walk.bvh): its style as a mix of the
                         known styles, its nearest styles and its speed (engine.clip_style)
  POST /api/steer/start  {"style", "z", "seed", "start", "heading", "speed"}: a walker of its own (steer.py)
  POST /api/steer/step   {"session", "from", "ahead", "samples"}: the next samples along the predicted path
  POST /api/steer/style  {"session", "style", "z", "seed"}: blend to another style over a second
  POST /api/steer/stop   {"session"}: the walker is dropped
  GET  /api/steer        how many walkers are live and how much each holds
Bad input (generate.py's style and curve errors, the demo's limits) is a 400 with the message
bin/generate.py would print; a body over MAX_BODY_BYTES (an uploaded clip: engine.MAX_CLIP_BYTES) is a
413 (chunked ones too); bodies are held in memory, never spooled to disk. Generation
runs in the request threads, at most MAX_CONCURRENT at once (the others wait up to QUEUE_TIMEOUT_S,
then get a 503), so many requests cannot pile up memory; an export draws its file after giving
its generation slot back, MAX_EXPORTS at a time (a GIF takes matplotlib seconds to draw). Steered
walkers have their own bounds and slots (steer.py): an unknown walker is a 404, a request on a
walker another one holds a 409, a start beyond steer.MAX_WALKERS a 503.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from pathlib import Path

from flask import Flask, jsonify, request, send_from_directory
from werkzeug.exceptions import HTTPException

from motiongan_jax.cli import add_model_arguments, use_compilation_cache
from motiongan_jax.data import curves
from motiongan_jax.demo import engine as engine_lib
from motiongan_jax.demo import steer as steer_lib
from motiongan_jax.generate import limits
from motiongan_jax.motion.gltf import GLTFError
from motiongan_jax.motion.ik import IKError
from motiongan_jax.motion.rigs import RigError

STATIC = Path(__file__).resolve().parent / "static"
MAX_BODY_BYTES = 2 * 1024 * 1024
MAX_CONCURRENT = 2
MAX_EXPORTS = 1  # files drawn at once (matplotlib's GIF frames: seconds of one core each)
QUEUE_TIMEOUT_S = 30.0
THREADS = 8  # waitress's request threads: a few beyond the generation slots for the page's quick requests
CONNECTIONS = 64  # open connections at most (waitress refuses more)
IDLE_TIMEOUT_S = 30  # a connection idle (or sending nothing) this long is closed
BAD_INPUT = (engine_lib.RequestError, limits.GenerateError, curves.DegenerateCurveError,
             curves.CurveFileError, IKError, RigError, GLTFError)
LOOPBACK = ("127.0.0.1", "localhost", "::1")


class Busy(Exception):
    pass


def create_app(engine: engine_lib.Engine) -> Flask:
    app = Flask(__name__, static_folder=None)
    app.config["MAX_CONTENT_LENGTH"] = MAX_BODY_BYTES
    slots = threading.BoundedSemaphore(MAX_CONCURRENT)
    export_slots = threading.BoundedSemaphore(MAX_EXPORTS)

    def bounded(fn, *args, sem=slots, what="generations"):
        if not sem.acquire(timeout=QUEUE_TIMEOUT_S):
            raise Busy(what)
        try:
            return fn(*args)
        finally:
            sem.release()

    def patient(fn, *args):
        with slots:
            return fn(*args)

    # the background warm-up compiles in a generation slot too (waiting as long as it takes), so a
    # request waits for one compile at most
    app.config["run_in_slot"] = patient

    def body():
        if not request.is_json:
            raise engine_lib.RequestError("the request body must be JSON (Content-Type: application/json)")
        # read here, not by get_json(silent=True): that would turn a chunked body over the limit
        # (RequestEntityTooLarge while reading) and a deeply nested one into other answers
        return engine_lib.decode_json(request.get_data(cache=False))

    @app.errorhandler(HTTPException)
    def http_error(err):
        if err.code == 413:
            limit = engine_lib.MAX_CLIP_BYTES if request.path == "/api/clip" else MAX_BODY_BYTES
            msg = f"request body too large: the demo takes at most {limit // 1024} KiB"
            if request.path == "/api/clip":
                msg += " (a BVH file)"
        else:
            msg = err.description
        return jsonify(error=msg), err.code

    def bad_input(err):
        return jsonify(error=str(err)), 400

    for exc in BAD_INPUT:
        app.register_error_handler(exc, bad_input)

    @app.errorhandler(steer_lib.SteerError)
    def steer_refused(err):
        headers = {} if err.retry_after_s is None else {"Retry-After": str(int(round(err.retry_after_s)))}
        return jsonify(error=str(err)), err.status, headers

    @app.errorhandler(Busy)
    def busy(err):
        what = err.args[0] if err.args else "generations"
        n = MAX_EXPORTS if what == "exports" else MAX_CONCURRENT
        return jsonify(error=f"the server is busy (more than {n} {what} at once for {QUEUE_TIMEOUT_S:g} s); "
                             "try again"), 503

    @app.errorhandler(Exception)
    def internal(err):
        # a bug, not bad input: logged with its traceback, answered as JSON like every refusal
        app.logger.exception("internal error")
        return jsonify(error=f"internal error ({type(err).__name__}); the server log has the details"), 500

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

        pts = engine.shape(args.get("name"), num("length", None), num("scale", None))
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
        data, name, mime = bounded(engine.export, body(), bounded, sem=export_slots, what="exports")
        return app.response_class(data, mimetype=mime,
                                  headers={"Content-Disposition": f'attachment; filename="{name}"'})

    @app.post("/api/clip")
    def clip():
        # the file is the body (not a form: nothing is parsed into temporary files), read whole in
        # memory up to the clip's own limit
        request.max_content_length = engine_lib.MAX_CLIP_BYTES
        data = request.get_data(cache=False)
        out = bounded(engine.clip_style, data, request.args.get("name", "clip.bvh"))
        return jsonify(out)

    walkers = steer_lib.SteeredWalkers(engine)
    app.config["walkers"] = walkers

    @app.get("/api/steer")
    def steer_stats():
        return jsonify(walkers.stats())

    @app.post("/api/steer/<action>")
    def steer(action):
        act = {"start": walkers.start, "step": walkers.step, "style": walkers.style, "stop": walkers.stop}
        if action not in act:
            return jsonify(error=f"unknown steer action {action[:40]!r}; known: {', '.join(act)}"), 404
        t0 = time.perf_counter()
        out = act[action](body())
        if action == "step":
            out["server_ms"]["total"] = round(1e3 * (time.perf_counter() - t0), 2)
        return jsonify(out)

    return app


def load_engine(workdir=None, model=None, step=None, params="ema") -> engine_lib.Engine:
    from motiongan_jax.model import pretrained

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


def make_server(app, host: str, port: int, debug: bool = False):
    """A started-on-demand server for `app`: waitress (module doc), or Flask's development
    server when `debug`. Its `.port` is the port it listens on; `.serve()` serves until `.close()`."""
    if debug:
        from werkzeug.serving import make_server as dev_server

        srv = dev_server(host, port, app, threaded=True)
        return _Server(srv.server_port, srv.serve_forever, lambda: (srv.shutdown(), srv.server_close()))
    from waitress.server import create_server

    # bodies up to twice the limit reach the app, which answers its JSON 413; beyond, waitress's own
    # 413. Bodies stay in memory (inbuf_overflow at the limit: waitress would spool larger ones to a
    # temporary file), so an uploaded clip never touches the disk.
    body_limit = 2 * max(MAX_BODY_BYTES, engine_lib.MAX_CLIP_BYTES)
    srv = create_server(app, host=host, port=port, threads=THREADS, connection_limit=CONNECTIONS,
                        channel_timeout=IDLE_TIMEOUT_S, cleanup_interval=min(IDLE_TIMEOUT_S, 30),
                        max_request_body_size=body_limit, inbuf_overflow=body_limit, ident="motiongan-demo",
                        clear_untrusted_proxy_headers=True)
    return _Server(srv.effective_port, srv.run, srv.close)


class _Server:
    def __init__(self, port, serve, close):
        self.port, self.serve, self.close = port, serve, close


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="motiongan-demo", description="Draw a path, pick a style, watch it walk.")
    add_model_arguments(ap)
    ap.add_argument("--host", default="127.0.0.1",
                    help="address to listen on (default 127.0.0.1: this machine only; 0.0.0.0: every network)")
    ap.add_argument("--port", type=int, default=8000, help="port (default 8000; 0: any free port)")
    ap.add_argument("--no-warm-up", action="store_true", help="compile G on first use instead of at start")
    ap.add_argument("--search-steps", type=int, default=None,
                    help="Adam steps of an uploaded clip's style search (default analysis.search.STEPS, 30; "
                         "fewer: a faster, rougher answer)")
    ap.add_argument("--debug", action="store_true",
                    help="serve through Flask's development server (this machine only) instead of waitress")
    args = ap.parse_args(argv)
    if not 0 <= args.port <= 65535:
        ap.error(f"--port must be 0..65535, got {args.port}")
    if args.search_steps is not None and not 1 <= args.search_steps <= 1000:
        ap.error(f"--search-steps must be 1..1000, got {args.search_steps}")
    if args.debug and args.host not in LOOPBACK:
        ap.error(f"--debug serves through Flask's development server, which is for this machine only: "
                 f"use --host 127.0.0.1, not {args.host}")

    from motiongan_jax.model.checkpoint import CheckpointError

    use_compilation_cache()
    try:
        engine = load_engine(args.workdir, args.model, args.step, args.params)
    except CheckpointError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if args.search_steps is not None:
        engine.search_steps = args.search_steps
    try:
        app = create_app(engine)
        server = make_server(app, args.host, args.port, args.debug)
    except (OSError, ValueError) as err:  # port taken, address not ours, a host name that does not resolve
        why = getattr(err, "strerror", None) or err
        print(f"error: cannot listen on {args.host}:{args.port}: {why}", file=sys.stderr)
        return 2
    host = f"[{args.host}]" if ":" in args.host else args.host
    print(f"motiongan demo: {engine.details}", flush=True)
    print(f"serving on http://{host}:{server.port}/  (Ctrl-C to stop)", flush=True)
    if not args.no_warm_up:
        def warm():
            secs = engine.warm_up(run=app.config["run_in_slot"])
            print(f"warmed up in {secs:.1f} s: every path length and number of walks the page can ask for",
                  flush=True)

        threading.Thread(target=warm, daemon=True).start()
    try:
        server.serve()
    except KeyboardInterrupt:
        pass
    finally:
        server.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
