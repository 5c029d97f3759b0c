"""Hostile input to the demo's API and the command-line tools: every request gets a 4xx naming
its problem (or a correct answer), every bad argument an exit status 2 and a message, never a
500 or a traceback; the server stays up in bounded memory. Hand-picked cases first, then
property-based fuzzing (Hypothesis, a bounded number of examples) of the style language and the
JSON API.

The model is conftest's random_tiny (as in test_demo.py): the checks run before G, and the few
requests that reach G use the paths and batch sizes test_demo.py compiles.
"""

import json
import math
import re
import socket
import threading
import urllib.error
import urllib.request
from pathlib import Path

import numpy as np
import pytest
from conftest import run_cli
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

pytest.importorskip("flask")

from motiongan_jax.demo import engine as E  # noqa: E402
from motiongan_jax.demo import server  # noqa: E402
from motiongan_jax.generate import limits  # noqa: E402
from motiongan_jax.generate import styles as styles_lib  # noqa: E402
from motiongan_jax.model import apply as model_apply  # noqa: E402
from motiongan_jax.model import checkpoint  # noqa: E402

NAMES = ["Childish", "Drunk", "Happy", "Marching", "Normal", "OldMan", "Sad", "Sneaky", "Strong"]
LINE32 = [[0.0, 0.0], [31.5 * 1.2 / 15.0, 0.0]]  # 32 samples at 1.2 m/s and 15 Hz: test_demo's bucket


@pytest.fixture(scope="module")
def engine(random_tiny):
    return E.Engine(*checkpoint.load_run(random_tiny), title="tiny", details="tiny random")


@pytest.fixture(scope="module")
def client(engine):
    return server.create_app(engine).test_client()


@pytest.fixture()
def no_g(monkeypatch):
    """G must not run: a limit is checked before the work it bounds."""
    def fail(*args, **kwargs):
        raise AssertionError("G ran")

    monkeypatch.setattr(model_apply, "g_apply", fail)


def _style_message(text):
    with pytest.raises(styles_lib.StyleError) as e:
        styles_lib.parse_style(text, NAMES)
    return str(e.value)


def _raw(client, path, data, content_type="application/json"):
    r = client.post(path, data=data, content_type=content_type)
    return r.status_code, (r.get_json(silent=True) or {}).get("error", "")


def _finite_json(text: str):
    """JSON as the page's JSON.parse reads it: NaN and Infinity are not JSON."""
    def refuse(c):
        raise AssertionError(f"non-finite {c} in the answer")

    return json.loads(text, parse_constant=refuse)


# ---------------------------------------------------------------------------------------------
# the style language: bounds, one message for the command line, the API and the page


@pytest.mark.parametrize("text, match", [
    ("1e400*Sad", r"coefficient '1e400' is not a finite number"),
    ("1e30*Sad", r"coefficients Sad 1e\+30 \(sizes add up to 1e\+30\)"),
    ("1e6*Sad - 1e6*Happy", r"sizes add up to 2e\+06"),
    ("Sad:1,Happy:-0.999999", r"the weights nearly cancel, so the normalised weights are Sad 1e\+06"),
    ("Sad:1e308,Happy:1e308", r"weight 1e\+308 of 'Sad' is too large"),
    ("Sad:nan,Happy:1", r"'nan' is not a finite number"),
    ("Sad:1,Happy:-1", r"the weights sum to 0"),
    ("5*Sad + 5.5*Happy", r"sizes add up to 10.5"),
    ("Sad*2", r"a coefficient goes before its style \('2\*Sad'\), not after it"),
    ("Sad * 2 + Happy", r"a coefficient goes before its style"),
    ("Sad + Happy/2", r"expected \+ or - after 'Happy' at position 12, found '/'"),
])
def test_style_bounds_and_messages(text, match):
    msg = _style_message(text)
    assert re.search(match, msg), msg
    if text in ("1e400*Sad", "1e30*Sad", "1e6*Sad - 1e6*Happy", "Sad:1,Happy:-0.999999", "Sad:1e308,Happy:1e308",
                "5*Sad + 5.5*Happy"):  # a refusal for a bound states the bounds
        assert f"at most {styles_lib.MAX_COEFFICIENT_SUM:g}" in msg and f"±{styles_lib.MAX_MIX_WEIGHT:g}" in msg
    assert "did you mean 'Sad'" not in msg


def test_styles_inside_the_bounds_are_exact():
    # weights of 1e-300 are not 0: normalised exactly (math.fsum), half and half
    spec = styles_lib.parse_style("Sad:1e-300,Happy:1e-300", NAMES)
    assert spec.terms == (("Sad", 0.5), ("Happy", 0.5))
    spec = styles_lib.parse_style("Sad:1000,Happy:-500", NAMES)  # shares 2 and -1: sizes 3
    assert spec.terms == (("Sad", 2.0), ("Happy", -1.0))
    assert styles_lib.parse_style("5*Sad + 5*Happy", NAMES).terms == (("Sad", 5.0), ("Happy", 5.0))
    assert "did you mean" not in _style_message("Sadd*2") or "Sadd" in _style_message("Sadd*2")


STYLE_ATOMS = st.sampled_from(NAMES + ["sad", "Sadd", "x", "random", " ", "+", "-", "*", ":", ",", "e", ".", "0",
                                       "1", "2.5", "1e308", "1e400", "-1e-300", "nan", "inf", "1_0", "\x00", "é"])


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.one_of(st.text(max_size=40), st.lists(STYLE_ATOMS, max_size=12).map("".join)))
def test_fuzz_style_parser_bounded_or_style_error(text):
    """Any text: a style whose coefficients are finite and within the bounds, or a StyleError."""
    try:
        spec = styles_lib.parse_style(text, NAMES)
    except styles_lib.StyleError as e:
        assert str(e)
        return
    assert spec.kind in ("label", "mix", "expr", "file")
    coefs = [c for _, c in spec.terms]
    assert all(math.isfinite(c) for c in coefs)
    assert math.fsum(abs(c) for c in coefs) <= styles_lib.MAX_COEFFICIENT_SUM
    assert all(n in NAMES for n, _ in spec.terms)


# ---------------------------------------------------------------------------------------------
# the API, hand-picked


BIG_INT = "1" + "0" * 400  # beyond float range: JSON has no limit on digits


@pytest.mark.parametrize("path, data, status, match", [
    ("/api/generate", '{"points": [[0, 0], [%s, 0]], "styles": ["Happy"]}' % BIG_INT, 400, "finite number"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "speed": %s}' % BIG_INT, 400,
     "'speed' must be a finite number"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "speed": 1e400}', 400, "finite"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "seed": %s}' % BIG_INT, 400,
     r"'seed' must be an integer 0..2147483647"),
    ("/api/generate", "[" * 100_000 + "]" * 100_000, 400, "nested too deeply"),
    ("/api/style", '{"style": ' + "[" * 100_000 + "]" * 100_000 + "}", 400, "nested too deeply"),
    ("/api/generate", "[" * 20 + "]" * 20, 400, "nested too deeply"),
    ("/api/generate", '{"points": [[[[[[[[[[0]]]]]]]]]], "styles": ["Happy"]}', 400, "nested too deeply"),
    ("/api/generate", b"\xff\xfe\x00garbage", 400, "not valid JSON"),
    ("/api/generate", "", 400, "not valid JSON"),
    ("/api/generate", "null", 400, "must be a JSON object"),
    ("/api/generate", '"points"', 400, "must be a JSON object"),
    ("/api/generate", '{"points": null, "styles": ["Happy"]}', 400, "must be a list"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": [null]}', 400, "non-empty list of style strings"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["\\ud800"]}', 400, "unknown style"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "z": "\\u00b2"}', 400, "'z' must be"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "z": "%s"}' % ("9" * 5000), 400,
     "'z' must be"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "z": 0}', 400, "integer 1..4"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "seed": -1}', 400, "'seed' must be"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "seed": 2147483648}', 400, "'seed'"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "seed": 1.5}', 400, "'seed'"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["Happy"], "speed": true}', 400, "'speed'"),
    ("/api/generate", '{"points": [[0, 0], [2, 0]], "styles": ["1e400*Sad"]}', 400, "not a finite number"),
    ("/api/style", '{"style": "1e400*Sad"}', 400, "coefficient '1e400' is not a finite number"),
    ("/api/style", '{"style": "Sad*2"}', 400, "a coefficient goes before its style"),
    ("/api/style", '{"style": 5}', 400, "'style' must be a string"),
    ("/api/style", '{"style": "/etc/passwd.txt"}', 400, "w files are not accepted"),
    ("/api/style", '{}', 400, "expected"),
])
def test_hostile_requests_are_400s_naming_the_problem(client, no_g, path, data, status, match):
    code, msg = _raw(client, path, data)
    assert code == status, msg
    assert re.search(match, msg), msg


@pytest.mark.parametrize("style", ["1e30*Sad", "1e6*Sad - 1e6*Happy", "Sad:1,Happy:-0.999999",
                                   "Sad:1e308,Happy:1e308"])
def test_style_refusals_are_the_same_from_the_api_as_from_the_parser(client, no_g, style):
    want = _style_message(style)
    for path, body in (("/api/style", {"style": style}), ("/api/generate", {"points": LINE32, "styles": [style]})):
        r = client.post(path, json=body)
        assert r.status_code == 400 and r.get_json()["error"] == want


def test_wrong_methods_routes_and_content_types_are_json_4xx(client):
    r = client.get("/api/generate")
    assert r.status_code == 405 and r.get_json()["error"]
    r = client.get("/api/nothing")
    assert r.status_code == 404 and r.get_json()["error"]
    assert _raw(client, "/api/generate", '{"points": []}', "text/plain")[0] == 400
    for query, match in (("name=line&length=1e999", "finite"), ("name=line&length=nan", "finite"),
                         (f"name=line&length={BIG_INT}", "finite"), ("name=circle&scale=0", "'scale'"),
                         ("name=line&length=-1", "'length'"), ("length=3", "unknown shape"),
                         ("name=line&scale=x", "must be a number")):
        r = client.get(f"/api/shape?{query}")
        assert r.status_code == 400 and re.search(match, r.get_json()["error"]), (query, r.get_json())


def test_export_limits_are_checked_before_generating(client, no_g, monkeypatch):
    long = [[0.0, 0.0], [(E.GIF_MAX_FRAMES + 10) * 1.2 / 15.0, 0.0]]
    r = client.post("/api/export", json={"points": long, "styles": ["Happy"], "format": "gif"})
    assert r.status_code == 400 and f"at most {E.GIF_MAX_FRAMES} frames" in r.get_json()["error"]
    r = client.post("/api/export", json={"points": LINE32, "styles": ["Happy", "Sad"], "format": "bvh", "index": 2})
    assert r.status_code == 400 and "'index' must be an integer 0..1" in r.get_json()["error"]
    r = client.post("/api/export", json={"points": LINE32, "styles": ["Happy"], "format": "exe"})
    assert r.status_code == 400 and "'format' must be one of" in r.get_json()["error"]


def test_exports_draw_outside_the_generation_slot(engine, monkeypatch):
    """While an export writes its file, the generation slot is free."""
    seen = {}

    def write(path, *args, **kwargs):
        # the generation slots: a fresh generate must get one at once
        t0 = threading.Event()
        th = threading.Thread(target=lambda: (client.post("/api/generate", json={"points": LINE32, "styles":
                                                                                  ["Happy"]}), t0.set()))
        th.start()
        seen["generate_done"] = t0.wait(60)
        raise limits.GenerateError("stop here")

    monkeypatch.setattr(E.writers, "write_outputs", write)
    monkeypatch.setattr(server, "MAX_CONCURRENT", 1)  # one slot: held by the export, the generate would wait
    monkeypatch.setattr(server, "QUEUE_TIMEOUT_S", 60.0)
    client = server.create_app(engine).test_client()
    r = client.post("/api/export", json={"points": LINE32, "styles": ["Happy"], "format": "npz"})
    assert r.status_code == 400 and seen["generate_done"]


# ---------------------------------------------------------------------------------------------
# uploaded clips (/api/clip): bounded, parsed in memory by the strict reader, a 400 naming the problem


@pytest.fixture(scope="module")
def clip_bvh(engine) -> str:
    """A held-out clip of the embedded dataset (the engine's skeleton and units), as text."""
    return (Path(engine.meta["data_dir"]) / "Sad_05.bvh").read_text()


def _frames(text: str) -> tuple[str, list[str]]:
    head, _, frames = text.partition("Frame Time:")
    time_line, _, body = frames.partition("\n")
    return head + "Frame Time:" + time_line + "\n", body.strip("\n").split("\n")


def _with_frames(text: str, fn) -> str:
    head, lines = _frames(text)
    return head + "\n".join(fn(lines)) + "\n"


def _still(lines):  # the root's translation held at its first frame's: a walker that stands
    first = lines[0].split()[:3]
    return [" ".join(first + line.split()[3:]) for line in lines]


def _scaled_offsets(text: str, k: float) -> str:
    def scale(m):
        return "OFFSET " + " ".join(f"{k * float(v):.4f}" for v in m.group(1).split())

    return re.sub(r"OFFSET ([-\d. ]+)", scale, text)


def _many_joints(n: int) -> str:
    body = "".join(f"JOINT J{i}\n{{\nOFFSET 0 1 0\nCHANNELS 3 Zrotation Yrotation Xrotation\n" for i in range(n))
    return ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation "
            "Xrotation\n" + body + "}\n" * (n + 1) + "MOTION\nFrames: 1\nFrame Time: 0.1\n" + "0 " * (6 + 3 * n) + "\n")


@pytest.mark.parametrize("case, status, match", [
    ("empty", 400, r"empty file"),
    ("junk", 400, r"clip\.bvh:1: expected HIERARCHY"),
    ("truncated", 400, r"clip\.bvh:\d+: (fewer frames than declared|wrong number of values)"),
    ("nan", 400, r"clip\.bvh:\d+: NaN or infinite value 'nan' in frame 3"),
    ("inf offset", 400, r"clip\.bvh:\d+: NaN or infinite OFFSET value"),
    ("huge", 413, r"too large: the demo takes at most 4096 KiB \(a BVH file\)"),
    ("many frames", 400, r"clip\.bvh:\d+: 1000000000 frames; at most 18000 are read"),
    ("many joints", 400, r"clip\.bvh:\d+: more than 128 joints"),
    ("wrong skeleton", 400, r"not the model's skeleton: of the \d+ joints the model moves .* it lacks LeftUpLeg; "
                            r"has LeftThigh besides"),
    ("wrong unit", 400, r"the walker is [\d.e+]+ m tall at 0.056444 m per file unit, not 0.5-3 m"),
    ("standing", 400, r"the root moves 0 m/s on average: not a walk"),
    ("too short", 400, r"shorter than one window \(\d+ samples x step 4 = \d+ frames, [\d.]+ s\)"),
])
def test_hostile_clips_are_4xx_naming_the_problem(client, no_g, clip_bvh, case, status, match):
    head, lines = _frames(clip_bvh)
    data = {
        "empty": "",
        "junk": "\x00\xff binary junk",
        "truncated": clip_bvh[: len(clip_bvh) * 3 // 5],
        "nan": _with_frames(clip_bvh, lambda ls: ls[:2] + [" ".join(ls[2].split()[:7] + ["nan"] + ls[2].split()[8:])]
                            + ls[3:]),
        "inf offset": clip_bvh.replace("OFFSET 0.0000 -7.5000 0.0000", "OFFSET 0.0000 inf 0.0000", 1),
        "huge": clip_bvh * (E.MAX_CLIP_BYTES // len(clip_bvh) + 1),
        "many frames": re.sub(r"Frames: \d+", "Frames: 1000000000", clip_bvh),
        "many joints": _many_joints(E.MAX_CLIP_JOINTS + 10),
        "wrong skeleton": clip_bvh.replace("JOINT LeftUpLeg", "JOINT LeftThigh"),
        "wrong unit": _scaled_offsets(clip_bvh, 100.0),
        "standing": _with_frames(clip_bvh, _still),
        "too short": re.sub(r"Frames: \d+", "Frames: 40", head) + "\n".join(lines[:40]) + "\n",
    }[case]
    r = client.post("/api/clip?name=clip.bvh", data=data.encode("latin-1", "replace") if case == "junk"
                    else data.encode(), content_type="application/octet-stream")
    assert r.status_code == status, r.get_json()
    msg = r.get_json()["error"]
    assert re.search(match, msg), msg
    assert "Traceback" not in msg


def test_clip_names_are_sanitised_and_bodies_not_json_are_fine(client, no_g):
    r = client.post("/api/clip?name=" + "../" * 50 + "%00<b>.bvh", data=b"HIERARCHY\n", content_type="text/plain")
    msg = r.get_json()["error"]
    name = msg.split(":")[0]
    assert r.status_code == 400 and name.endswith("b_.bvh") and not set("/<>\x00") & set(name), msg


# ---------------------------------------------------------------------------------------------
# the real server (waitress): chunked bodies, bursts, memory, the command line


@pytest.fixture(scope="module")
def live(engine):
    srv = server.make_server(server.create_app(engine), "127.0.0.1", 0)
    thread = threading.Thread(target=srv.serve, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{srv.port}"
    srv.close()
    thread.join(10)


def _send(url, data: bytes, headers=None, method="POST"):
    req = urllib.request.Request(url, data=data, headers={"Content-Type": "application/json", **(headers or {})},
                                 method=method)
    try:
        with urllib.request.urlopen(req, timeout=120) as resp:
            return resp.status, resp.read()
    except urllib.error.HTTPError as e:
        return e.code, e.read()


def _chunked(url_base: str, path: str, body: bytes) -> tuple[int, bytes]:
    host, port = url_base.split("//")[1].split(":")
    with socket.create_connection((host, int(port)), timeout=60) as s:
        s.sendall(f"POST {path} HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\n"
                  "Transfer-Encoding: chunked\r\nConnection: close\r\n\r\n".encode())
        step = 1 << 16
        for i in range(0, len(body), step):
            part = body[i:i + step]
            s.sendall(f"{len(part):x}\r\n".encode() + part + b"\r\n")
        s.sendall(b"0\r\n\r\n")
        data = b""
        while chunk := s.recv(1 << 16):
            data += chunk
    head, _, rest = data.partition(b"\r\n\r\n")
    return int(head.split()[1]), rest


def _rss_mib() -> float:
    with open("/proc/self/status") as fh:
        return int(re.search(r"VmRSS:\s+(\d+)", fh.read()).group(1)) / 1024


def test_the_live_server_answers_hostile_bodies_and_stays_up(live, engine):
    pad = json.dumps({"points": LINE32, "styles": ["Happy"], "pad": "x" * server.MAX_BODY_BYTES}).encode()
    code, body = _chunked(live, "/api/generate", pad)
    assert code == 413 and b"too large" in body
    code, body = _send(live + "/api/generate", pad)
    assert code == 413 and b"too large" in body
    code, body = _chunked(live, "/api/style", b'{"style": "Sad*2"}')
    assert code == 400 and b"coefficient goes before" in body
    rss0 = _rss_mib()
    deep = b"[" * 500_000 + b"]" * 500_000
    for _ in range(20):
        for data in (deep, b'{"points": [[0, 0], [%s, 0]], "styles": ["Happy"]}' % BIG_INT.encode(),
                     b'{"style": "1e400*Sad"}'):
            code, _ = _send(live + "/api/generate", data)
            assert code == 400
    assert _rss_mib() - rss0 < 200  # MiB: nothing piles up
    code, body = _send(live + "/api/generate", json.dumps({"points": LINE32, "styles": ["Happy"]}).encode())
    assert code == 200 and len(_finite_json(body.decode())["motions"]) == 1


def test_busy_port_and_debug_on_a_public_address_exit_2(capsys):
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen(1)
        port = s.getsockname()[1]
        assert server.main(["--port", str(port), "--no-warm-up"]) == 2
    err = capsys.readouterr().err
    assert f"cannot listen on 127.0.0.1:{port}" in err and "Traceback" not in err
    with pytest.raises(SystemExit) as e:
        server.main(["--debug", "--host", "0.0.0.0"])
    assert e.value.code == 2
    assert "--debug serves through Flask's development server" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# the command-line tools


@pytest.mark.parametrize("extra, match", [
    (["--seed", "-1"], r"--seed must be an integer 0..2147483647"),
    (["--seed", "99999999999999999999999"], r"--seed must be an integer 0..2147483647"),
    (["--length", "nan"], r"length must be a positive number of metres, got nan"),
    (["--scale", "nan"], r"scale must be a positive number of metres, got nan"),
    (["--scale", "-2"], r"scale must be a positive number of metres"),
    (["--speed", "1e-300"], r"speed must be 0.05..15 m/s"),
    (["--speed", "nan"], r"speed must be 0.05..15 m/s"),
    (["--speed", "inf"], r"speed must be 0.05..15 m/s"),
    (["--z", "1e9"], r"--z must be 'zero', 'seed' or a number of samples"),
])
def test_generate_cli_refuses_bad_numbers_with_exit_2(tmp_path, extra, match):
    out = tmp_path / "w.npz"
    code, _, err = run_cli("generate", ["--style", "Sad", "--curve", "line", "--out", out, *extra])
    assert code == 2 and re.search(match, err), err
    assert "Traceback" not in err and not out.exists()


@pytest.mark.parametrize("case, match", [
    ("missing", r"no such file"),
    ("nan", r"bad\.bvh:\d+: NaN or infinite value"),
    ("wrong skeleton", r"bad\.bvh: not the model's skeleton"),
    ("standing", r"bad\.bvh: the root moves 0 m/s on average: not a walk"),
])
def test_generate_style_from_a_bad_clip_exits_2_naming_the_problem(tmp_path, clip_bvh, no_g, case, match):
    """The shipped model (the embedded skeleton): every refusal comes before G."""
    bad = tmp_path / "bad.bvh"
    if case != "missing":
        bad.write_text({"nan": _with_frames(clip_bvh, lambda ls: ["nan " + ls[0].split(" ", 1)[1]] + ls[1:]),
                        "wrong skeleton": clip_bvh.replace("JOINT LeftUpLeg", "JOINT LeftThigh"),
                        "standing": _with_frames(clip_bvh, _still)}[case])
    out = tmp_path / "w.npz"
    code, _, err = run_cli("generate", ["--style-from", bad, "--curve", "line", "--out", out])
    assert code == 2 and re.search(match, err), err
    assert "Traceback" not in err and not out.exists()
    code, _, err = run_cli("generate", ["--style-from", bad, "--style", "Sad", "--curve", "line", "--out", out])
    assert code == 2 and "--style-from gives the style: use it without --style" in err


@pytest.mark.parametrize("style", ["Sad:1e308,Happy:1e308", "Sad*2"])  # the others: the API test above
def test_generate_cli_gives_the_parsers_message_for_a_style(tmp_path, style):
    out = tmp_path / "w.npz"
    code, _, err = run_cli("generate", ["--style", style, "--curve", "line", "--out", out])
    assert code == 2 and err.strip() == f"error: {_style_message(style)}"
    assert not out.exists()


def test_other_tools_refuse_a_bad_seed_and_an_unwritable_picture(repo, tmp_path):
    code, _, err = run_cli("train", ["--config", repo / "configs" / "tiny.py", "--workdir", tmp_path, "--seed",
                                     "99999999999999999999999", "--dry-run"])
    assert code == 2 and "--seed must be an integer 0..2147483647" in err
    code, _, err = run_cli("demo_screenshot", ["--out", tmp_path / "missing" / "a.png"])
    assert code == 2 and "cannot write" in err and "Traceback" not in err
    code, _, err = run_cli("demo_screenshot", ["--out", tmp_path / "a.png", "--size", "big"])
    assert code == 2 and "--size must be WIDTHxHEIGHT" in err


BVH_170 = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Head
  {
    OFFSET 0 80 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 10 0
    }
  }
  JOINT Foot
  {
    OFFSET 0 -80 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    End Site
    {
      OFFSET 0 -5 0
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.0333333
0 85 0 0 0 0 0 0 0 0 0 0
1 85 0 0 0 0 0 0 0 0 0 0
"""


def test_prepare_data_exits_2_on_a_wrong_unit_and_an_unwritable_out(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "Sad_01.bvh").write_text(BVH_170)  # 175 file units tall: centimetres
    out = tmp_path / "o.npz"
    code, _, err = run_cli("prepare_data", [data, "--out", out])  # --labels paper: CMU units, 9.9 m
    assert code == 2 and re.search(r"the skeleton is 9.88 m tall .*\(--labels bandai\)", err), err
    assert not out.exists()
    blocker = tmp_path / "a_file"
    blocker.write_text("")
    code, _, err = run_cli("prepare_data", [data, "--out", blocker / "o.npz", "--units-to-m", "0.01"])
    assert code == 2 and f"cannot write {blocker / 'o.npz'}" in err and "Traceback" not in err
    code, _, err = run_cli("prepare_data", [data, "--out", out, "--units-to-m", "nan"])
    assert code == 2 and "--units-to-m must be a positive number" in err
    code, _, err = run_cli("prepare_data", [tmp_path / "missing", "--out", out])
    assert code == 2 and "data directory not found" in err
    code, stdout, err = run_cli("prepare_data", [data, "--out", out, "--units-to-m", "0.01"])
    assert code == 0 and out.exists(), err
    z = np.load(out)
    assert np.ptp(z["positions"][0, :, 1]) == pytest.approx(1.75)


# ---------------------------------------------------------------------------------------------
# the API, fuzzed

NUMBERS = st.one_of(st.floats(allow_nan=False, allow_infinity=False), st.integers(-10**30, 10**30),
                    st.sampled_from([0, -0.0, 1e-300, 1e308, 10**400]))
JSON = st.recursive(st.none() | st.booleans() | NUMBERS | st.text(max_size=20),
                    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4),
                    max_leaves=12)
POINT = st.tuples(st.floats(0, 0.6), st.floats(0, 0.6)).map(list)  # paths of at most 1.7 m: 32 samples
STYLE = st.one_of(st.sampled_from(NAMES), st.lists(STYLE_ATOMS, min_size=1, max_size=8).map("".join),
                  st.text(max_size=12))
GENERATE = st.fixed_dictionaries(
    {"points": st.one_of(st.lists(POINT, min_size=2, max_size=3), JSON),
     "styles": st.one_of(st.lists(st.sampled_from(NAMES), min_size=1, max_size=2), st.lists(STYLE, min_size=1,
                                                                                           max_size=2), JSON)},
    optional={"z": st.one_of(st.sampled_from(["zero", "seed", 1, 2, "2", 0, 5, "x", -1]), JSON),
              "seed": st.one_of(st.integers(-5, 2**32), JSON),
              "speed": st.one_of(st.none(), st.sampled_from([1.2, 3.0, 0.1, -1.0]), JSON)})
# near-valid bodies, so that a good share reaches G: a path of 0.5-1.7 m, known styles or style text
NEAR_VALID = st.fixed_dictionaries(
    {"points": st.tuples(st.just([0.0, 0.0]), st.tuples(st.floats(0.5, 1.2), st.floats(0, 1.2)).map(list)).map(list),
     "styles": st.lists(st.one_of(st.sampled_from(NAMES), STYLE), min_size=1, max_size=2)},
    optional={"z": st.sampled_from(["zero", "seed", 1, 2]), "seed": st.integers(0, 2**31 - 1)})
FUZZ = settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow,
                                                                      HealthCheck.function_scoped_fixture])


def _answer(client, path, body):
    """The answer to `body`: 200 with finite JSON, or a 4xx whose JSON names the problem."""
    r = client.post(path, data=json.dumps(body), content_type="application/json")
    assert r.status_code in (200, 400, 413), (r.status_code, r.data[:300])
    event(f"{path} {r.status_code}")  # --hypothesis-show-statistics: how many got through
    answer = _finite_json(r.data.decode())
    if r.status_code != 200:
        assert isinstance(answer["error"], str) and answer["error"]
    return r.status_code, answer


@FUZZ
@given(body=st.one_of(NEAR_VALID, GENERATE, JSON))
def test_fuzz_generate_200_with_finite_json_or_a_4xx_naming_the_problem(client, body):
    """Any JSON body: never a 500. Short paths (at most 32 samples), at most 2 styles x 2 samples,
    so G runs on a few small programs."""
    if isinstance(body, dict) and isinstance(body.get("z"), int) and not isinstance(body.get("z"), bool):
        body["z"] = min(body["z"], 2)
    status, answer = _answer(client, "/api/generate", body)
    if status == 200:
        assert answer["motions"] and all(np.isfinite(np.array(m["positions"])).all() for m in answer["motions"])


@FUZZ
@given(body=st.one_of(st.fixed_dictionaries({"style": st.one_of(STYLE, JSON)}), JSON))
def test_fuzz_style_200_with_finite_json_or_a_4xx_naming_the_problem(client, body):
    status, answer = _answer(client, "/api/style", body)
    if status == 200:
        assert all(math.isfinite(c) for _, c in answer["terms"])


NUMBER_TEXT = st.one_of(st.floats().map(repr), st.integers(-10**400, 10**400).map(str), st.text(max_size=6))


@FUZZ
@given(name=st.one_of(st.sampled_from(["line", "circle", "s_curve", "figure8", "corner"]), st.text(max_size=8)),
       length=st.one_of(st.none(), NUMBER_TEXT), scale=st.one_of(st.none(), NUMBER_TEXT))
def test_fuzz_shape_200_with_finite_points_or_a_400(client, name, length, scale):
    query = {"name": name, **({"length": length} if length is not None else {}),
             **({"scale": scale} if scale is not None else {})}
    r = client.get("/api/shape", query_string=query)
    assert r.status_code in (200, 400), (query, r.status_code, r.data[:300])
    answer = _finite_json(r.data.decode())
    event(f"/api/shape {r.status_code}")
    if r.status_code == 200:
        pts = np.array(answer["points"])
        assert pts.shape[1] == 2 and len(pts) >= 2
        assert np.sum(np.linalg.norm(np.diff(pts, axis=0), axis=1)) <= E.MAX_PATH_M * 1.001
    else:
        assert answer["error"]
