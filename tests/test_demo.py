"""The demo's JSON API and request checks (motiongan_jax/demo), through Flask's test client.

The model is the tiny config with seeded random parameters (conftest's random_tiny): the API's job is to
check requests and pass them through generate.py unchanged, which a random G shows as well as a
trained one, and it compiles in a fraction of the time. The page itself: test_demo_browser.py.
"""

import concurrent.futures
import io
import json
import re
import threading
import urllib.request

import chex
import numpy as np
import pytest

pytest.importorskip("flask")

from motiongan_jax.data import curves  # noqa: E402
from motiongan_jax.demo import engine as E  # noqa: E402
from motiongan_jax.demo import server  # noqa: E402
from motiongan_jax.generate import limits, user_curves, walk, writers
from motiongan_jax.generate import styles as styles_lib
from motiongan_jax.model import apply as model_apply
from motiongan_jax.model import checkpoint  # noqa: E402
from motiongan_jax.motion import bvh  # noqa: E402

RATE = 15.0
SPEED = 1.2


@pytest.fixture(scope="module")
def model(random_tiny):
    return checkpoint.load_run(random_tiny)


@pytest.fixture(scope="module")
def engine(model):
    return E.Engine(*model, title="tiny", details="tiny random")


@pytest.fixture(scope="module")
def client(engine):
    return server.create_app(engine).test_client()


def _line(T):
    """Floor points of a straight path that resamples to exactly T samples at SPEED."""
    return [[0.0, 0.0], [(T - 0.5) * SPEED / RATE, 0.0]]


def _arc(T):
    """Floor points of a circular arc (radius 2 m) that resamples to exactly T samples at SPEED.
    (On a straight line at constant speed G's instance norms see channels that are constant in
    time, so its output there depends on float rounding, e.g. on the batch size.)"""
    return curves.shape_curve("circle", length=(T - 0.5) * SPEED / RATE, scale=2.0, num_points=400).tolist()


def _direct(engine, points, styles, z="zero", seed=0):
    """What bin/generate.py's steps give for the same request, without the demo."""
    curve = user_curves.prepare_curve(user_curves.Curve(np.asarray(points, float), "path"), RATE, SPEED)
    specs = [styles_lib.parse_style(s, engine.style_names, seed) for s in styles]
    w = styles_lib.spec_codes(engine.state, specs, engine.style_names, styles_lib.z_codes(engine.state, z, seed))
    return walk.generate_motion(engine.state, engine.layout, curve, w), specs


def _post(client, path, body):
    return client.post(path, json=body)


def test_page_and_model_info_are_served_from_the_package_alone(client, engine):
    page = client.get("/")
    assert page.status_code == 200 and b"<canvas id=\"view\"" in page.data
    html = page.data.decode()
    refs = re.findall(r'(?:src|href)="([^"]+)"', html)
    assert refs and all(r.startswith("/static/") or r.startswith("data:") for r in refs), refs
    for r in refs:
        if r.startswith("/static/"):
            body = client.get(r).data.decode()
            assert not re.search(r"https?://", body), f"{r} refers to another site"
    info = client.get("/api/model").get_json()
    assert info["style_names"] == engine.style_names and info["fps"] == RATE
    assert info["parents"] == list(engine.layout.parents) and info["shapes"] == list(curves.SHAPES)
    assert info["limits"]["max_path_m"] == E.MAX_PATH_M
    assert client.get("/static/../server.py").status_code == 404


def test_generate_at_a_bucket_size_is_what_generate_py_makes(client, engine):
    styles = ["Happy", "Sad:0.3,Happy:0.7", "OldMan - Normal + Marching", "drunk"]  # batch 4: a bucket
    r = _post(client, "/api/generate", {"points": _line(32), "styles": styles, "speed": SPEED})
    assert r.status_code == 200, r.get_json()
    out = r.get_json()
    J = len(engine.layout.joint_names)
    assert out["frames"] == 32 and out["samples_bucket"] == 32 and out["batch_bucket"] == 4
    direct, specs = _direct(engine, _line(32), styles)
    assert [m["title"] for m in out["motions"]] == [s.text for s in specs]
    for m, want in zip(out["motions"], direct.positions):
        got = np.array(m["positions"])
        chex.assert_shape(got, (32, J, 3))
        np.testing.assert_allclose(got, want, atol=0.6 * 10 ** -E.DIGITS)  # rounded to DIGITS decimals
    np.testing.assert_allclose(np.array(out["curve"]), direct.curve[:, [0, 2]], atol=1e-4)
    assert out["length_m"] == pytest.approx(31 * SPEED / RATE, rel=1e-4)


def test_a_new_length_in_a_bucket_does_not_compile_again(engine):
    base = E.parse_request({"points": _line(48), "styles": ["Happy"], "speed": SPEED})
    engine.run(base)
    compiled = model_apply.g_apply._cache_size()
    res = engine.run(E.parse_request({"points": _line(40), "styles": ["Sad"], "speed": SPEED}))
    assert res.generated.positions.shape[1] == 40 and res.samples_bucket == 48  # padded to 48
    assert model_apply.g_apply._cache_size() == compiled


def test_padding_keeps_the_motion_on_its_curve_and_its_feet_on_the_floor(engine):
    res = engine.run(E.parse_request({"points": _arc(40), "styles": ["Happy", "Drunk"], "speed": SPEED}))
    g = res.generated
    chex.assert_shape(g.positions, (2, 40, len(engine.layout.joint_names), 3))
    chex.assert_shape(g.curve, (40, 3))
    lowest = g.positions[..., 1].min(axis=-1)
    np.testing.assert_allclose(np.percentile(lowest, walk.FLOOR_PERCENTILE, axis=-1), 0.0, atol=1e-9)
    # a padded batch gives each motion what it gets alone (G treats motions independently), up to
    # float rounding in programs compiled for another batch size
    alone = engine.run(E.parse_request({"points": _arc(40), "styles": ["Happy"], "speed": SPEED})).generated
    np.testing.assert_allclose(g.positions[0], alone.positions[0], atol=1e-4)  # 0.1 mm


def test_z_samples_and_seeds(client):
    body = {"points": _line(32), "styles": ["Happy"], "z": 3, "seed": 5}
    out = _post(client, "/api/generate", body).get_json()
    assert [m["title"] for m in out["motions"]] == ["Happy z0", "Happy z1", "Happy z2"]
    p = [np.array(m["positions"]) for m in out["motions"]]
    assert np.abs(p[0] - p[1]).max() > 1e-3  # different z, different walks
    again = _post(client, "/api/generate", body).get_json()
    assert again["motions"] == out["motions"]  # same seed, same walks
    other = _post(client, "/api/generate", {**body, "seed": 6}).get_json()
    assert np.abs(np.array(other["motions"][0]["positions"]) - p[0]).max() > 1e-3


def _style_error(text, names):
    with pytest.raises(styles_lib.StyleError) as e:
        styles_lib.parse_style(text, names)
    return str(e.value)


@pytest.mark.parametrize("change, status, match", [
    ({"styles": ["Hapy"]}, 400, None),  # the message is generate.py's (checked below)
    ({"styles": ["OldMan - - Normal"]}, 400, None),
    ({"styles": ["Sad:0.5,Sad:0.5"]}, 400, None),
    ({"styles": ["w.npy"]}, 400, "w files are not accepted"),
    ({"styles": []}, 400, "non-empty list"),
    ({"styles": ["Happy"] * (E.MAX_STYLES + 1)}, 400, "at most 6 side by side"),
    ({"styles": ["x" * (E.MAX_STYLE_CHARS + 1)]}, 400, "at most 400"),
    ({"points": [[0, 0]]}, 400, "needs at least 2 points"),
    ({"points": [[1, 1], [1, 1], [1, 1]]}, 400, "zero length"),
    ({"points": [[0, 0], [1, "a"]]}, 400, "must be a number"),
    ({"points": [[0, 0], [1, True]]}, 400, "must be a number"),
    ({"points": [[0, 0], [1, 2, 3]]}, 400, "not an \\[x, z\\] pair"),
    ({"points": "0,0 1,1"}, 400, "must be a list"),
    ({"points": [[0, 0], [1e308, 0], [-1e308, 0]]}, 400, "at most 60 m"),
    ({"points": [[0, 0], [E.MAX_PATH_M + 1, 0]]}, 400, "61.0 m long; the demo walks at most 60 m"),
    ({"points": [[i * 1e-4, 0] for i in range(E.MAX_POINTS + 1)]}, 400, "at most 20000"),
    ({"z": 99}, 400, "integer 1..4"),
    ({"z": "many"}, 400, "'z' must be"),
    ({"seed": -1}, 400, "'seed' must be an integer"),
    ({"speed": 0.0}, 400, "0.3..3 m/s"),
    ({"speed": "fast"}, 400, "must be a number"),
    ({"colour": "red"}, 400, "unknown field"),
    ({"rig": ["mixamo"]}, 400, "'rig' must be one of mixamo, smpl, bandai"),
    ({"styles": ["Happy"] * 3, "z": 3}, 400, "at most 8 at once"),
])
def test_bad_requests_are_400s_naming_the_problem(client, engine, change, status, match):
    body = {"points": _line(32), "styles": ["Happy"], **change}
    r = _post(client, "/api/generate", body)
    assert r.status_code == status, r.get_json()
    msg = r.get_json()["error"]
    if match is None:
        assert msg == _style_error(body["styles"][0], engine.style_names)
    else:
        assert re.search(match, msg), msg


def test_non_json_bodies_non_finite_numbers_and_oversized_bodies(client):
    for data in ("not json", "[1, 2]", '{"points": [[0, 0], [NaN, 1]], "styles": ["Happy"]}',
                 '{"points": [[0, 0], [Infinity, 1]], "styles": ["Happy"]}'):
        r = client.post("/api/generate", data=data, content_type="application/json")
        assert r.status_code == 400 and r.get_json()["error"], data
    assert "finite" in client.post("/api/generate", data='{"points": [[0,0],[NaN,1]], "styles": ["Happy"]}',
                                   content_type="application/json").get_json()["error"]
    big = json.dumps({"points": _line(32), "styles": ["Happy"], "pad": "x" * server.MAX_BODY_BYTES})
    r = client.post("/api/generate", data=big, content_type="application/json")
    assert r.status_code == 413 and "too large" in r.get_json()["error"]
    # too long to walk at the slowest speed: the sample limit, before G runs
    r = _post(client, "/api/generate", {"points": [[0, 0], [50, 0]], "styles": ["Happy"], "speed": 0.3})
    assert r.status_code == 400 and "at most 1024" in r.get_json()["error"]
    # and the server still answers
    assert _post(client, "/api/generate", {"points": _line(32), "styles": ["Happy"]}).status_code == 200


def test_the_demo_limits_lie_inside_generates_which_apply_too(client, monkeypatch):
    """generate.py's limits are the one definition every entry point applies; the demo's own are
    an interactive page's and lie inside them. A path within the demo's but beyond a (lowered)
    generate limit is a 400 with generate's message, before G runs."""
    assert E.MAX_PATH_M <= limits.MAX_CURVE_LENGTH_M and E.MAX_POINTS <= limits.MAX_CURVE_POINTS
    assert E.MAX_MOTIONS * E.SAMPLE_BUCKETS[-1] <= min(limits.MAX_TOTAL_SAMPLES, walk.BATCH_SAMPLES)  # one G call
    assert E.MAX_MOTIONS * E.GIF_MAX_FRAMES <= limits.MAX_GIF_FRAMES

    def no_g(*args):
        raise AssertionError("G ran")

    monkeypatch.setattr(model_apply, "g_apply", no_g)
    monkeypatch.setattr(limits, "MAX_CURVE_LENGTH_M", 2.0)
    r = _post(client, "/api/generate", {"points": _line(32), "styles": ["Happy"]})  # 2.5 m
    assert r.status_code == 400, r.get_json()
    assert re.search(r"3 m is longer than the limit of 2 m \(generate.limits.MAX_CURVE_LENGTH_M\)",
                     r.get_json()["error"])


def test_style_check_and_shapes(client, engine):
    r = _post(client, "/api/style", {"style": "oldman - Normal + 0.5*Marching"})
    assert r.get_json() == {"kind": "expr", "text": "OldMan - Normal + 0.5*Marching",
                            "terms": [["OldMan", 1.0], ["Normal", -1.0], ["Marching", 0.5]]}
    r = _post(client, "/api/style", {"style": "OldMan +"})
    assert r.status_code == 400 and r.get_json()["error"] == _style_error("OldMan +", engine.style_names)
    pts = np.array(client.get("/api/shape?name=circle&scale=2").get_json()["points"])
    np.testing.assert_allclose(np.linalg.norm(pts - [0, 2], axis=1), 2.0, atol=1e-3)  # radius 2 about (0, 2)
    L = np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1))
    assert L == pytest.approx(2 * np.pi * 2, rel=1e-3)
    assert client.get("/api/shape?name=spiral").status_code == 400
    assert client.get("/api/shape?name=line&length=1000").status_code == 400
    assert client.get("/api/shape?name=line&length=x").status_code == 400


def test_exports_are_written_by_generate_py_writers(client, engine, tmp_path, monkeypatch):
    body = {"points": _line(32), "styles": ["Happy", "Sad"]}
    shown = _post(client, "/api/generate", body).get_json()
    r = _post(client, "/api/export", {**body, "format": "bvh", "index": 1})
    assert r.status_code == 200 and 'filename="motiongan_Sad.bvh"' in r.headers["Content-Disposition"]
    (tmp_path / "a.bvh").write_bytes(r.data)
    motion = bvh.read_bvh(tmp_path / "a.bvh")
    assert motion.num_frames == 32 and motion.frame_time == pytest.approx(1 / RATE)
    res = engine.run(E.parse_request(body))
    writers.save_bvh(tmp_path / "b.bvh", res.generated.positions[1], engine.layout, RATE)
    assert (tmp_path / "b.bvh").read_bytes() == r.data

    r = _post(client, "/api/export", {**body, "format": "npz", "index": 0})
    z = np.load(io.BytesIO(r.data))
    np.testing.assert_allclose(z["positions"], np.array(shown["motions"][0]["positions"]), atol=1e-4)
    assert str(z["style"]) == "Happy" and float(z["fps"]) == RATE

    monkeypatch.setattr(E, "GIF_MAX_FRAMES", 16)
    r = _post(client, "/api/export", {"points": _line(16), "styles": ["Happy"], "format": "gif"})
    assert r.status_code == 200 and r.data[:6] == b"GIF89a"
    from PIL import Image

    assert Image.open(io.BytesIO(r.data)).n_frames == 16
    r = _post(client, "/api/export", {**body, "format": "gif"})
    assert r.status_code == 400 and "at most 16 frames" in r.get_json()["error"]
    assert _post(client, "/api/export", {**body, "format": "bvh", "index": 2}).status_code == 400
    assert _post(client, "/api/export", {**body, "format": "exe"}).status_code == 400


def test_glb_export_is_the_character_the_page_draws_on_the_chosen_rig(client, engine, tmp_path):
    assert set(client.get("/api/model").get_json()["rigs"]) == {"mixamo", "smpl", "bandai"}
    body = {"points": _line(32), "styles": ["Happy", "Sad"]}
    res = engine.run(E.parse_request(body))
    for rig in (None, "smpl"):
        r = _post(client, "/api/export", {**body, "format": "glb", **({"rig": rig} if rig else {})})
        assert r.status_code == 200 and r.mimetype == "model/gltf-binary" and r.data[:4] == b"glTF"
        assert f'filename="motiongan_Happy_Sad{"_" + rig if rig else ""}.glb"' in r.headers["Content-Disposition"]
        # the bytes generate.py's writers make of the same result: one animation per motion
        from motiongan_jax.motion import rigs

        writers.write_outputs(tmp_path / "w.glb", res.generated, res.titles, engine.layout, RATE,
                              rig=None if rig is None else rigs.load_rig(rig))
        assert (tmp_path / "w.glb").read_bytes() == r.data
    r = _post(client, "/api/export", {**body, "format": "bvh", "rig": "mixamo"})
    assert r.status_code == 200 and b"mixamorig:Hips" in r.data
    for bad, match in (({"rig": "blender"}, "'rig' must be one of mixamo, smpl, bandai"),
                       ({"rig": "smpl", "format": "npz"}, "a walk on a rig downloads as bvh or glb, not npz")):
        r = _post(client, "/api/export", {**body, "format": "glb", **bad})
        assert r.status_code == 400 and match in r.get_json()["error"], r.get_json()


def test_concurrent_requests_each_get_their_own_answer(engine, client):
    """Eight requests at once against the threaded server give what each gives alone."""
    from werkzeug.serving import make_server

    app = server.create_app(engine)
    srv = make_server("127.0.0.1", 0, app, threaded=True)
    thread = threading.Thread(target=srv.serve_forever, daemon=True)
    thread.start()
    try:
        bodies = [{"points": _line(32), "styles": [s], "seed": i} for i, s in enumerate(engine.style_names[:8])]
        want = [_post(client, "/api/generate", b).get_json()["motions"] for b in bodies]

        def ask(b):
            req = urllib.request.Request(f"http://127.0.0.1:{srv.server_port}/api/generate",
                                         data=json.dumps(b).encode(), headers={"Content-Type": "application/json"})
            with urllib.request.urlopen(req, timeout=120) as resp:
                return json.loads(resp.read())["motions"]

        with concurrent.futures.ThreadPoolExecutor(8) as pool:
            got = list(pool.map(ask, bodies))
        assert got == want
    finally:
        srv.shutdown()
        thread.join(10)


def test_an_uploaded_clip_is_a_mix_the_page_can_walk(client, engine):
    """/api/clip: a held-out clip of the embedded dataset (the model's skeleton) gives a mix of the
    known styles, its nearest styles and its speed; the mix walks as a style of /api/generate."""
    from pathlib import Path

    data = (Path(engine.meta["data_dir"]) / "Happy_05.bvh").read_bytes()
    r = client.post("/api/clip?name=Happy_05.bvh", data=data, content_type="application/octet-stream")
    assert r.status_code == 200, r.get_json()
    res = r.get_json()
    assert res["name"] == "Happy_05.bvh" and res["windows"] == 4 and res["fps"] == 60.0
    assert abs(sum(a for _, a in res["mix"]) - 1) < 0.01 and {n for n, _ in res["mix"]} <= set(engine.style_names)
    assert [n for n, _ in res["nearest"]] and all(n in engine.style_names for n, _ in res["nearest"])
    motion = bvh.parse_bvh(data.decode())
    assert res["frames"] == motion.num_frames - engine.cfg.data.start_offset
    assert res["seconds"] == pytest.approx(res["frames"] / 60.0, abs=0.01)
    # the embedded dataset walks at 1.2-1.5 m/s; the clip's speed is the windows' curve spacing
    assert 0.5 < res["speed"] < 2.5
    assert styles_lib.parse_style(res["style"], engine.style_names).kind in ("mix", "label")
    r = _post(client, "/api/generate", {"points": _line(32), "styles": [res["style"]], "speed": res["speed"]})
    assert r.status_code == 200, r.get_json()


def test_cli_refuses_bad_arguments(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        server.main(["--port", "70000"])
    assert e.value.code == 2
    with pytest.raises(SystemExit) as e:
        server.main(["--workdir", "a", "--model", "b"])
    assert e.value.code == 2
    assert server.main(["--model", str(tmp_path / "missing.npz")]) == 2
    assert "not found" in capsys.readouterr().err


@pytest.mark.parametrize("name, turning", [("circle", 2 * np.pi), ("figure8", 0.0), ("s_curve", 0.0)])
@pytest.mark.parametrize("length", [1.0, 10.0, E.MAX_PATH_M])
def test_the_page_presets_make_one_whole_shape_at_every_length(client, name, turning, length):
    """Without a scale, a shape of length L is one period: a circle of circumference L (not laps
    of a 2 m circle), a figure-8 of two lobes, one S; closed shapes end where they start."""
    pts = np.array(client.get(f"/api/shape?name={name}&length={length}").get_json()["points"])
    seg = np.diff(pts, axis=0)
    assert np.sum(np.linalg.norm(seg, axis=1)) == pytest.approx(length, rel=2e-3)
    heading = np.unwrap(np.arctan2(seg[:, 1], seg[:, 0]))
    assert heading[-1] - heading[0] == pytest.approx(turning, abs=0.1)  # total turning
    if name == "circle":  # every point at the radius L / 2 pi from the centre
        r = length / (2 * np.pi)
        np.testing.assert_allclose(np.linalg.norm(pts - [0, r], axis=1), r, atol=2e-3 * length)
    if name == "figure8":  # two lobes of radius L / 4 pi, one each side of the start, meeting there
        r = length / (4 * np.pi)
        half = len(pts) // 2
        assert pts[:half, 1].max() == pytest.approx(2 * r, rel=0.02)
        assert pts[half:, 1].min() == pytest.approx(-2 * r, rel=0.02)
        assert np.linalg.norm(pts[half]) < 0.02 * length
    if name != "s_curve":
        assert np.linalg.norm(pts[-1] - pts[0]) < 0.01 * length


def test_gif_frames_keep_the_walks_clock():
    """GIF delays are whole hundredths of a second: at 15 Hz they alternate so that frame i ends
    at i / 15 s (rounded), instead of 1/15 s rounded down to 60 ms (10 % fast)."""
    from motiongan_jax import viz

    d = viz.gif_durations_ms(30, 15.0)
    assert d[:6] == [70, 60, 70, 70, 60, 70] and sum(d) == 2000
    assert all(abs(sum(d[:i]) - 1000 * i / 15) <= 5 for i in range(31))
    assert viz.gif_durations_ms(4, 10.0) == [100] * 4


def test_warm_up_compiles_what_the_page_can_ask_for(engine):
    plan = E.warm_plan()
    assert sorted(plan) == sorted((T, B) for T in E.SAMPLE_BUCKETS for B in E.BATCH_BUCKETS)
    assert plan[0] == (16, 1) and len(set(plan)) == len(plan)
    fresh = E.Engine(engine.state, engine.meta, engine.cfg, engine.layout)
    assert fresh.info()["compiled"] == [] and not fresh.info()["warm"] and not fresh.info()["walker_warm"]
    ran = []
    fresh.warm_up(run=lambda fn, *args: ran.append(fn.__name__) or fn(*args), plan=[(48, 1)])  # test_demo's
    info = fresh.info()
    assert info["compiled"] == [(48, 1)] and info["warm"] and info["compile_s"] is not None
    assert info["walker_warm"]
    # every z's codes, the steer mode's stream window, G, then the style search of an uploaded clip,
    # each in a slot
    assert ran == ["_spec_codes"] * E.MAX_SAMPLES_Z + ["_warm_walker", "run", "_warm_clip"]


def test_the_compilation_cache_folder_is_the_users_unless_told(monkeypatch, tmp_path):
    import jax

    from motiongan_jax.cli import COMPILE_CACHE_ENV, use_compilation_cache

    before = jax.config.jax_compilation_cache_dir
    try:
        monkeypatch.setenv(COMPILE_CACHE_ENV, "off")
        assert use_compilation_cache() is None
        monkeypatch.setenv(COMPILE_CACHE_ENV, str(tmp_path / "xla"))
        assert use_compilation_cache() == str(tmp_path / "xla") == jax.config.jax_compilation_cache_dir
        monkeypatch.delenv(COMPILE_CACHE_ENV)
        assert use_compilation_cache() == str(tmp_path / "xla")  # a folder JAX was given is kept
        jax.config.update("jax_compilation_cache_dir", None)
        monkeypatch.setenv("MOTIONGAN_CACHE", str(tmp_path / "root"))
        assert use_compilation_cache() == str(tmp_path / "root" / "xla")
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


# ---- steer mode (demo/steer.py): a walker per tab, fed the path its keys predict ----------------

from motiongan_jax.demo import steer as steer_lib  # noqa: E402


@pytest.fixture()
def steer_app(engine):
    """A fresh app (its own walkers) whose walkers' clock the test moves."""
    app = server.create_app(engine)
    now = [1000.0]
    app.config["walkers"].clock = lambda: now[0]
    return app.test_client(), app.config["walkers"], now


def _ahead(last, heading, n, speed=SPEED, turn=0.0):
    """n points on from `last` (x, z), starting along angle `heading`, turning `turn` rad per sample:
    what the page predicts from its keys."""
    pts, p, h = [], np.asarray(last, float), heading
    for _ in range(n):
        h += turn
        p = p + speed / RATE * np.array([np.cos(h), np.sin(h)])
        pts.append(p)
    return np.array(pts)


def test_steer_streams_what_a_walker_fed_the_same_path_makes(steer_app, engine):
    """Steps through the API emit exactly what generate.stream.Walker emits for the same path
    (to the rounding of the JSON), contiguous from sample 0, on the path that was sent."""
    client, walkers, _ = steer_app
    r = _post(client, "/api/steer/start", {"style": "happy", "speed": SPEED, "start": [1.0, -2.0]})
    assert r.status_code == 200, r.get_json()
    st = r.get_json()
    assert st["style"] == "Happy" and st["next"] == 1 and st["last_point"] == [1.0, -2.0]
    L = st["lookahead"]
    w, _ = engine.style_code("Happy")
    ref = engine.walker(w, (1.0, -2.0), (1.0, 0.0), SPEED)
    J = len(engine.layout.joint_names)
    nxt, last, heading, got, want, curve = st["next"], np.array(st["last_point"]), 0.0, [], [], []
    for k, n in enumerate([4, 1, 16, 7, 5]):
        ahead = _ahead(last, heading, L + n, turn=0.08 if k >= 2 else 0.0)
        r = _post(client, "/api/steer/step", {"session": st["session"], "from": nxt, "samples": n,
                                              "ahead": ahead.tolist()})
        assert r.status_code == 200, r.get_json()
        out = r.get_json()
        assert out["index0"] == sum(len(g) for g in got)  # contiguous, from sample 0
        pos = np.array(out["positions"])
        chex.assert_shape(pos, (n, J, 3))
        chex.assert_shape(np.array(out["curve"]), (n, 2))
        ref.revise_ahead(ahead)
        want.append(ref.advance(n).positions)
        got.append(pos)
        curve.append(np.array(out["curve"]))
        used = out["next"] - 1 - (nxt - 1)  # the sent points the walker has now walked
        assert out["next"] == sum(len(g) for g in got) and out["blend"] == [1.0] * n
        np.testing.assert_allclose(out["last_point"], ahead[used - 1], atol=1e-4)
        heading += 0.08 * used if k >= 2 else 0.0
        nxt, last = out["next"], np.array(out["last_point"])
    np.testing.assert_allclose(np.concatenate(got), np.concatenate(want), atol=0.6 * 10 ** -E.DIGITS)
    walked = np.concatenate(curve)
    np.testing.assert_allclose(walked[0], [1.0, -2.0])
    steps = np.linalg.norm(np.diff(walked, axis=0), axis=1)
    np.testing.assert_allclose(steps, SPEED / RATE, atol=2e-4)  # the sent spacing, every sample
    stats = client.get("/api/steer").get_json()
    assert stats["walkers"] == 1 and stats["emitted"] == [33]
    assert _post(client, "/api/steer/stop", {"session": st["session"]}).get_json() == {"stopped": True}
    assert client.get("/api/steer").get_json()["walkers"] == 0


def test_steer_rotations_pose_the_pages_character_at_the_streamed_joints(steer_app, engine):
    """With "rotations", each streamed sample comes with local joint rotations on the skeleton of
    the page's GLB (its nodes, by name and order): the GLB's rest offsets turned by them (forward
    kinematics written here, with scipy's quaternions) put the root where the step says and point
    every bone that is its parent's only child along the streamed bone (the export's rule; this
    test's random G does not keep bone lengths, so positions further out differ by them)."""
    import pygltflib
    from scipy.spatial.transform import Rotation

    client, _, _ = steer_app
    st = _post(client, "/api/steer/start", {"style": "Sad", "speed": SPEED, "rotations": True}).get_json()
    glb = client.post("/api/export", json={"points": [[0.0, 0.0], [3.0, 0.0]], "styles": ["Sad"], "format": "glb"})
    assert glb.status_code == 200
    gl = pygltflib.GLTF2.load_from_bytes(glb.data)
    skin = gl.skins[0]
    names = [gl.nodes[j].name for j in skin.joints]
    assert st["joints"] == names
    parent = {c: j for j in skin.joints for c in (gl.nodes[j].children or [])}
    offsets = np.array([gl.nodes[j].translation or [0.0, 0.0, 0.0] for j in skin.joints])
    n = 6
    r = _post(client, "/api/steer/step", {"session": st["session"], "from": st["next"], "samples": n,
                                          "ahead": _ahead(st["last_point"], 0.0, st["lookahead"] + n,
                                                          turn=0.1).tolist()}).get_json()
    q = np.array(r["rotations"])
    chex.assert_shape(q, (n, len(names), 4))
    np.testing.assert_allclose(np.linalg.norm(q, axis=-1), 1.0, atol=1e-4)
    pos = np.array(r["positions"])
    index = {j: k for k, j in enumerate(skin.joints)}
    lay = engine.layout
    only = [i for i, p in enumerate(lay.parents) if p >= 0 and list(lay.parents).count(p) == 1]
    assert len(only) >= 10
    unit = lambda v: v / np.linalg.norm(v)  # noqa: E731
    for t in range(n):
        world_R, world_p = {}, {}
        for k, j in enumerate(skin.joints):  # parents first (the export skeleton's order)
            R = Rotation.from_quat(q[t, k]).as_matrix()
            if j in parent:
                pk = index[parent[j]]
                world_p[k] = world_p[pk] + world_R[pk] @ offsets[k]
                world_R[k] = world_R[pk] @ R
            else:
                world_p[k], world_R[k] = pos[t, 0], R
        for i in only:
            k, pk = names.index(lay.joint_names[i]), names.index(lay.joint_names[lay.parents[i]])
            np.testing.assert_allclose(unit(world_p[k] - world_p[pk]), unit(pos[t, i] - pos[t, lay.parents[i]]),
                                       atol=2e-2, err_msg=lay.joint_names[i])  # 1e-4 m rounding, short bones
    plain = _post(client, "/api/steer/start", {"style": "Sad"}).get_json()
    assert "joints" not in plain
    r2 = _post(client, "/api/steer/step", {"session": plain["session"], "from": 1, "samples": 1,
                                           "ahead": _ahead(plain["last_point"], 0.0, plain["lookahead"] + 1).tolist()})
    assert "rotations" not in r2.get_json()
    bad = _post(client, "/api/steer/start", {"style": "Sad", "rotations": "yes"})
    assert bad.status_code == 400 and "'rotations' must be true or false" in bad.get_json()["error"]


def test_steer_style_change_blends_over_a_second(steer_app, engine):
    client, _, _ = steer_app
    st = _post(client, "/api/steer/start", {"style": "Normal"}).get_json()
    L, sid = st["lookahead"], st["session"]
    nxt, last, blends = 1, np.array([0.0, 0.0]), []

    def step(n):
        nonlocal nxt, last
        out = _post(client, "/api/steer/step", {"session": sid, "from": nxt, "samples": n,
                                                "ahead": _ahead(last, 0.0, L + n).tolist()}).get_json()
        nxt, last = out["next"], np.array(out["last_point"])
        return out

    step(6)
    r = _post(client, "/api/steer/style", {"session": sid, "style": "OldMan:0.5,Sad:0.5"})
    assert r.get_json() == {"style": "OldMan:0.5,Sad:0.5", "from": 6, "blend_s": 1.0}
    for _ in range(3):
        out = step(8)
        blends += out["blend"]
        assert out["style"] == "OldMan:0.5,Sad:0.5"
    # sample 6 + k is k / 15 of the way (15 samples a second), then there
    np.testing.assert_allclose(blends, np.minimum(np.arange(24) / RATE, 1.0), atol=1e-4)
    r = _post(client, "/api/steer/style", {"session": sid, "style": "Hapy"})
    assert r.status_code == 400 and r.get_json()["error"] == _style_error("Hapy", engine.style_names)
    assert step(1)["style"] == "OldMan:0.5,Sad:0.5"  # a refused style changes nothing


def test_steer_walkers_are_bounded_in_number_and_dropped_when_idle(steer_app):
    client, walkers, now = steer_app
    ids = []
    for _ in range(steer_lib.MAX_WALKERS):
        r = _post(client, "/api/steer/start", {"style": "Happy"})
        assert r.status_code == 200, r.get_json()
        ids.append(r.get_json()["session"])
    assert len(set(ids)) == steer_lib.MAX_WALKERS
    r = _post(client, "/api/steer/start", {"style": "Happy"})
    assert r.status_code == 503 and r.headers["Retry-After"] == "30"
    assert re.search(r"at most 8 walkers at once", r.get_json()["error"])
    assert _post(client, "/api/steer/stop", {"session": ids.pop()}).status_code == 200
    now[0] += 20.0  # the rest idle 20 s; one of them asks for something: it stays
    assert _post(client, "/api/steer/style", {"session": ids[0], "style": "Sad"}).status_code == 200
    r = _post(client, "/api/steer/start", {"style": "Happy"})  # the stopped one's room
    assert r.status_code == 200
    ids.append(r.get_json()["session"])
    now[0] += steer_lib.IDLE_S - 10.0 + 0.5  # 30.5 s since the others' last request
    stats = client.get("/api/steer").get_json()
    assert stats["walkers"] == 2 and stats["max_walkers"] == 8  # ids[0] (10.5 s) and the new one
    r = _post(client, "/api/steer/style", {"session": ids[1], "style": "Sad"})
    assert r.status_code == 404 and "dropped" in r.get_json()["error"]
    assert _post(client, "/api/steer/style", {"session": ids[0], "style": "Happy"}).status_code == 200


def _started(client):
    st = _post(client, "/api/steer/start", {"style": "Happy"}).get_json()
    return st, {"session": st["session"], "from": 1, "samples": 2,
                "ahead": _ahead([0.0, 0.0], 0.0, st["lookahead"] + 2).tolist()}


@pytest.mark.parametrize("path, change, status, match", [
    ("step", {"session": "nope"}, 404, "no walker 'nope' here"),
    ("step", {"session": 7}, 400, "'session' must be the id"),
    ("step", {"from": 5}, 409, "'from' is 5, but this walker's path ahead starts at sample 1"),
    ("step", {"session": "\ud800"}, 404, "no walker"),
    ("step", {"from": 10 ** 30}, 400, "'from' must be an integer"),
    ("step", {"from": 1.0}, 400, "'from' must be an integer"),
    ("step", {"samples": True}, 400, "'samples' must be an integer 1..16"),
    ("step", {"samples": 0}, 400, "'samples' must be an integer 1..16"),
    ("step", {"samples": 10 ** 6}, 400, "'samples' must be an integer 1..16"),
    ("step", {"ahead": [[0.1, 0.0]] * 5}, 400, "send at least 33"),
    ("step", {"ahead": [[0.08 * (i + 1), 0.0] for i in range(steer_lib.MAX_AHEAD_POINTS + 1)]}, 400,
     "at most 128"),
    ("step", {"ahead": [[0.08, 0.0], [50.0, 0.0]] + [[50.0, 0.0]] * 40}, 400,
     r"the step into entry 1 is 49.9 m, 749 m/s .* at most 3 m/s"),
    ("step", {"ahead": [[0.08, 0.0], ["0.16", 0.0]]}, 400, "'ahead': entry 1 must be a number"),
    ("step", {"ahead": [[0.08, 0.0], [0.16]]}, 400, r"'ahead': entry 1 must be an \[x, z\] pair"),
    ("step", {"ahead": "forward"}, 400, "'ahead' must be a non-empty list"),
    ("step", {"extra": 1}, 400, "unknown field"),
    ("style", {"style": "w.npy"}, 400, "w files are not accepted"),
    ("style", {"style": ""}, 400, "non-empty string"),
    ("style", {"style": "Happy", "z": 3}, 400, "'z' must be 'zero' or 'seed'"),
    ("stop", {"session": "x" * 65}, 400, "'session' must be the id"),
    ("start", {"style": "Happy", "speed": 30.0}, 400, r"'speed' must be 0.3..3 m/s"),
    ("start", {"style": "Happy", "heading": [0, 0]}, 400, "non-zero floor direction"),
    ("start", {"style": "Happy", "start": [1e300, 0]}, 400, "within 1000 km"),
    ("start", {"style": "Happy", "start": [10 ** 400, 0]}, 400, "finite number"),
    ("start", {"style": "Happy", "seed": 2 ** 31}, 400, "'seed' must be an integer"),
    ("start", {"style": ["Happy"]}, 400, "'style' must be a non-empty string"),
    ("start", {}, 400, "missing field\\(s\\) 'style'"),
])
def test_bad_steer_requests_are_4xx_naming_the_problem(steer_app, path, change, status, match):
    client, _, _ = steer_app
    st, good = _started(client)
    body = {**(good if path == "step" else {"session": st["session"]} if path != "start" else {}), **change}
    r = _post(client, f"/api/steer/{path}", body)
    assert r.status_code == status, r.get_json()
    assert re.search(match, r.get_json()["error"]), r.get_json()["error"]
    # the walker still steps after a refused request (unless its walker id, "session", was what was refused)
    assert _post(client, "/api/steer/step", good).status_code == 200


def test_steer_non_finite_and_huge_bodies(steer_app):
    client, _, _ = steer_app
    st, good = _started(client)
    L = st["lookahead"]
    for bad in ("NaN", "Infinity", "-Infinity", "1e999"):
        pts = ", ".join(["[0.08, 0.0]", f"[{bad}, 0.0]"] + ["[0.2, 0.0]"] * L)
        data = f'{{"session": "{st["session"]}", "from": 1, "samples": 2, "ahead": [{pts}]}}'
        r = client.post("/api/steer/step", data=data, content_type="application/json")
        assert r.status_code == 400 and "finite" in r.get_json()["error"], (bad, r.get_json())
    big = json.dumps({**good, "ahead": good["ahead"] * 20000})
    r = client.post("/api/steer/step", data=big, content_type="application/json")
    assert r.status_code == 413 and "too large" in r.get_json()["error"]
    r = client.post("/api/steer/step", data="{" * 100, content_type="application/json")
    assert r.status_code == 400
    assert client.post("/api/steer/dance", json={}).status_code == 404
    assert client.get("/api/steer/step").status_code == 405
    assert _post(client, "/api/steer/step", good).status_code == 200
