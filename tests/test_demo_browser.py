"""The demo page in a real browser: Debian's chromium driven by Playwright (never `playwright
install`). The server is `python -m motiongan_jax.demo` on a free port with the shipped model.

Draws a path with mouse events, picks a style, then a mix of two, checks that the animation
runs and that the canvas shows the skeleton (pixels of the bones' colours that were not there
before), downloads the BVH and reads it with bvh.py, and types a bad expression to see generate's
message on the page. The character view: three.js draws the downloaded GLB's skinned body, and the
rig picker changes the skeleton. The steer mode: a minute of walking steered by key presses, in
two styles. Walk like this clip: drops a BVH clip on the page and walks its recovered style.
Without chromium or Playwright it fails under CI (which installs both, see .ci/run) and skips
elsewhere, saying what to install.
"""

import math
import os
import re
import shutil
import subprocess
import sys
import time

import chex
import numpy as np
import pytest
from conftest import SERVE_DEMO

from motiongan_jax.generate import styles
from motiongan_jax.model import pretrained
from motiongan_jax.motion import bvh

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
ARGS = ["--no-sandbox", "--headless", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]
LEFT_RGB, RIGHT_RGB = (94, 200, 255), (255, 176, 103)  # the page's bone colours (app.js)


def _need(what: str, hint: str):
    msg = f"the browser test needs {what}: {hint}"
    if os.environ.get("CI"):
        pytest.fail(msg)
    pytest.skip(msg)


@pytest.fixture(scope="module")
def playwright_api():
    try:
        from playwright.sync_api import sync_playwright
    except ImportError:
        _need("Playwright", "pip install -e '.[test]'")
    if not os.path.isfile(CHROMIUM):
        _need("Debian's chromium", "apt-get install chromium")
    return sync_playwright


@pytest.fixture(scope="module")
def demo_server():
    """`python -m motiongan_jax.demo --port 0`: (the URL it prints, its process); stopped afterwards."""
    # the tests' unoptimised XLA (conftest.FAST) runs G's steps slowly: a clip's search takes 3,
    # compiled at level 1 as in the tests' own processes (conftest.SERVE_DEMO)
    proc = subprocess.Popen([sys.executable, "-c", SERVE_DEMO, "--port", "0", "--no-warm-up", "--search-steps", "3"],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    url, lines, deadline = None, [], time.monotonic() + 180
    try:
        while time.monotonic() < deadline:
            line = proc.stdout.readline()
            if not line:
                break
            lines.append(line)
            m = re.search(r"serving on (http://127\.0\.0\.1:\d+/)", line)
            if m:
                url = m.group(1)
                break
        assert url, "the demo did not print its URL:\n" + "".join(lines)
        yield url, proc
    finally:
        proc.terminate()
        try:
            proc.wait(20)
        except subprocess.TimeoutExpired:
            proc.kill()


@pytest.fixture(scope="module")
def demo_url(demo_server):
    return demo_server[0]


def _bone_pixels(png: bytes) -> int:
    """Pixels within a few levels of the left or right bone colour."""
    import io

    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), np.int32)
    near = [np.abs(rgb - np.array(c)).max(-1) <= 12 for c in (LEFT_RGB, RIGHT_RGB)]
    return int(sum(n.sum() for n in near))


def _open(browser, demo_url):
    """(page, the page's uncaught errors) of the demo, loaded: its style chips are there."""
    page = browser.new_page(viewport={"width": 1280, "height": 860}, accept_downloads=True)
    errors = []
    page.on("pageerror", lambda e: errors.append(str(e)))
    page.goto(demo_url)
    page.wait_for_selector("#mode-label .chip")
    return page, errors


def _wait_generated(page, previous: int, timeout=300_000):  # the first one compiles G
    page.wait_for_function(f"window.demo.state.seq > {previous} && !window.demo.state.inflight", timeout=timeout)


def test_draw_pick_a_style_and_a_mix_watch_download_and_see_errors(playwright_api, demo_url, tmp_path):
    names = pretrained.read_export(pretrained.SHIPPED_MODEL).meta["style_names"]
    with playwright_api() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page, errors = _open(browser, demo_url)
            assert page.locator("#mode-label .chip").all_inner_texts() == names
            page.locator("#auto").uncheck()
            # the stick figure's bone colours (the character: below); set whether or not three.js loaded
            page.evaluate("(() => { const e = document.getElementById('look'); e.value = 'stick'; "
                          "e.dispatchEvent(new Event('change')); })()")
            empty = _bone_pixels(page.locator("#view").screenshot())

            # draw a wave on the floor canvas (300 px = 16 m: 3.2 m across, under 4.4 m long)
            box = page.locator("#floor").bounding_box()
            x0, y0 = box["x"] + 120, box["y"] + 150
            page.mouse.move(x0, y0)
            page.mouse.down()
            for i in range(1, 31):
                t = i / 30
                page.mouse.move(x0 + 60 * t, y0 + 8 * np.sin(2 * np.pi * t), steps=2)
            page.mouse.up()
            length = float(page.locator("#path-length").inner_text().split(" m")[0])
            assert 3.0 < length < 4.4, length

            page.locator("#mode-label .chip", has_text="OldMan").click()
            seq = page.evaluate("window.demo.state.seq")
            page.locator("#generate").click()
            _wait_generated(page, seq)
            assert page.locator("#error").is_hidden(), page.locator("#error").inner_text()
            frames = page.evaluate("window.demo.frames")
            # the whole path is walked: one frame per 0.08 m sample (1.2 m/s at 15 Hz), the shown
            # length rounded to 0.1 m
            assert abs(frames - length / 0.08) <= 2.5, (frames, length)
            result = page.evaluate("window.demo.state.result")
            assert [m["title"] for m in result["motions"]] == ["OldMan"]
            assert len(result["motions"][0]["positions"]) == frames

            # a mix of two styles with the weight sliders
            page.locator(".tab[data-mode=mix]").click()  # starts as OldMan:1
            for name, key, presses in (("OldMan", "ArrowLeft", 12), ("Happy", "ArrowRight", 12)):
                page.locator(f".mixrow[data-name={name}] input").focus()
                for _ in range(presses):  # 0.05 a step
                    page.keyboard.press(key)
            assert page.locator("#style-string").inner_text() == "style: OldMan:0.4,Happy:0.6"
            seq = page.evaluate("window.demo.state.seq")
            page.locator("#generate").click()
            _wait_generated(page, seq)
            result = page.evaluate("window.demo.state.result")
            assert [m["title"] for m in result["motions"]] == ["OldMan:0.4,Happy:0.6"]

            # the animation runs: frames are drawn and the clock moves
            t0, d0 = page.evaluate("[window.demo.state.time, window.demo.drawn]")
            page.wait_for_timeout(600)
            t1, d1 = page.evaluate("[window.demo.state.time, window.demo.drawn]")
            assert d1 > d0 + 5 and t1 != t0
            shown = _bone_pixels(page.locator("#view").screenshot())
            assert empty < 20 and shown > 300, (empty, shown)

            # BVH of what is shown, read back by bvh.py
            with page.expect_download() as dl:
                page.locator("#dl-bvh").click()
            path = tmp_path / dl.value.suggested_filename
            dl.value.save_as(path)
            motion = bvh.read_bvh(path)
            assert path.name == "motiongan_OldMan_0.4_Happy_0.6.bvh"
            assert motion.num_frames == frames
            meta = pretrained.read_export(pretrained.SHIPPED_MODEL).meta
            rate = float(meta["fps"]) / meta["config"]["data"]["frame_step"]
            assert motion.frame_time == pytest.approx(1 / rate)

            # a bad expression: generate.py's message, on the page
            page.locator(".tab[data-mode=expr]").click()
            page.locator("#expr").fill("OldMan - Normal + Marchng")
            try:
                styles.parse_style("OldMan - Normal + Marchng", names)
            except styles.StyleError as e:
                want = str(e)
            page.wait_for_function("document.querySelector('#expr-check').classList.contains('bad')")
            assert page.locator("#expr-check").inner_text() == want
            page.locator("#generate").click()
            page.wait_for_selector("#error:not([hidden])")
            assert page.locator("#error").inner_text() == want

            # undoing the only stroke takes its walk away with it
            page.locator("#undo").click()
            assert page.evaluate("window.demo.state.result === null && window.demo.frames === 0")
            assert not errors, errors
        finally:
            browser.close()


def _body_pixels(png: bytes) -> int:
    """Pixels of the lit body (motion.gltf.BODY_COLOR, a light grey under a bluish sky light):
    bright and nearly neutral, unlike the page's dark blue floor and sky, its grid and the path."""
    import io

    from PIL import Image

    rgb = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), np.int32)
    return int(np.sum((rgb.min(-1) > 75) & (rgb.max(-1) - rgb.min(-1) < 25)))


def test_the_character_is_the_glb_and_the_rig_picker_changes_it(playwright_api, demo_url, tmp_path):
    """three.js draws the GLB of /api/export (pixels of the skinned body, not only lines); the
    GLB button downloads the same bytes; the rig picker loads the walk on another skeleton."""
    import urllib.request

    with playwright_api() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS + ["--use-angle=swiftshader",
                                                                           "--enable-unsafe-swiftshader"])
        try:
            page, errors = _open(browser, demo_url)
            page.wait_for_function("window.demoCharacter !== undefined")
            assert page.evaluate("window.demoCharacter && window.demoCharacter.version") == "187", \
                page.evaluate("window.demoCharacterError || null")
            assert page.locator("#three-hint").is_hidden() and page.locator("#look").input_value() == "character"
            page.locator("#auto").uncheck()
            before = _body_pixels(page.locator("#view").screenshot())
            # a 3.5 m line: 44 samples, the 48-sample bucket the first test compiles too (not the
            # 128 of the next test, which must find its bucket not compiled yet)
            page.locator("#preset-length").fill("3.5")
            page.locator("#presets button", has_text="Line").click()
            page.wait_for_function("window.demo.state.strokes.length === 1")
            seq = page.evaluate("window.demo.state.seq")
            page.locator("#generate").click()
            _wait_generated(page, seq)
            page.wait_for_function("window.demo.character !== null", timeout=120_000)
            char = page.evaluate("window.demo.character")
            assert char["animations"] == ["Normal"] and char["meshes"] == 1 and char["rig"] == ""
            page.wait_for_timeout(300)
            shown = _body_pixels(page.locator("#view").screenshot())
            assert shown > 2000 and shown > 10 * max(before, 1), (before, shown)

            # the GLB button: the bytes the engine writes for the same request
            with page.expect_download() as dl:
                page.locator("#dl-glb").click()
            path = tmp_path / dl.value.suggested_filename
            dl.value.save_as(path)
            body = page.evaluate("JSON.stringify({...window.demo.state.request, format: 'glb'})").encode()
            req = urllib.request.Request(demo_url + "api/export", body, {"Content-Type": "application/json"})
            with urllib.request.urlopen(req, timeout=120) as r:
                assert path.read_bytes() == r.read()
            assert path.read_bytes()[:4] == b"glTF" and char["bytes"] == path.stat().st_size

            # the rig picker: the same walk on SMPL's skeleton
            page.select_option("#rig", "smpl")
            page.wait_for_function("window.demo.character && window.demo.character.rig === 'smpl'", timeout=120_000)
            assert page.evaluate("window.demo.character.bytes") != char["bytes"]
            with page.expect_download() as dl:
                page.locator("#dl-glb").click()
            assert dl.value.suggested_filename == "motiongan_Normal_smpl.glb"
            page.wait_for_timeout(300)
            assert _body_pixels(page.locator("#view").screenshot()) > 2000
            assert not errors, errors
        finally:
            browser.close()


def _drop_file(page, selector: str, name: str, data: bytes) -> None:
    """Drop a file on an element as a user's drag and drop does: a drop event carrying it."""
    page.evaluate("""([selector, name, bytes]) => {
        const dt = new DataTransfer();
        dt.items.add(new File([new Uint8Array(bytes)], name, {type: "application/octet-stream"}));
        const el = document.querySelector(selector);
        el.dispatchEvent(new DragEvent("dragover", {dataTransfer: dt, bubbles: true, cancelable: true}));
        el.dispatchEvent(new DragEvent("drop", {dataTransfer: dt, bubbles: true, cancelable: true}));
    }""", [selector, name, list(data)])


def _boxes(page) -> list[dict]:
    """The page boxes of every visible control and text line (hidden ones have none)."""
    return page.evaluate(f"""() => [...document.querySelectorAll({CONTROLS!r})].map((e) => {{
        const r = e.getBoundingClientRect();
        return {{name: e.id || e.dataset.shape || e.dataset.mode || e.textContent.trim().slice(0, 16) || e.tagName,
                 x: r.x, y: r.y, w: r.width, h: r.height}};
    }}).filter((b) => b.w > 0 && b.h > 0)""")


def _overlap(a, b) -> float:
    dx = min(a["x"] + a["w"], b["x"] + b["w"]) - max(a["x"], b["x"])
    dy = min(a["y"] + a["h"], b["y"] + b["h"]) - max(a["y"], b["y"])
    return max(dx, 0) * max(dy, 0) if dx > 1 and dy > 1 else 0.0


def test_no_control_covers_another_from_800_to_2560_px(playwright_api, demo_url):
    """A wait for a compile is explained on the page. The longest status line and motion title the
    page can show (a mix of six styles, z = 4 samples) make the bottom bar wrap; nothing may then be
    drawn over anything else, and every control stays inside the window's width."""
    with playwright_api() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 900})
            page.goto(demo_url)
            page.wait_for_selector("#mode-label .chip")
            page.locator("#auto").uncheck()
            page.locator("#presets button", has_text="Figure-8").click()
            page.wait_for_function("window.demo.state.strokes.length === 1")

            # a generation that waits says for what: held here before it reaches the server, so
            # the 10 m figure-8's bucket (126 samples -> 128, one walk) is not compiled yet
            held = []
            page.route("**/api/generate", lambda route: held.append(route))
            page.locator("#generate").click()
            page.wait_for_function("document.getElementById('status').textContent.includes('compiling')")
            assert re.fullmatch(r"generating… compiling the generator for paths of 128 samples × 1 walk, once "
                                r"\((about \d+ s|a few seconds)\); warmed up \d+ of 60",
                                page.locator("#status").inner_text()), page.locator("#status").inner_text()
            held[0].abort()
            page.unroute("**/api/generate")

            title = "Childish:0.167,Drunk:0.167,Happy:0.167,Marching:0.167,Normal:0.167,OldMan:0.167 z3"
            page.evaluate(f"""() => {{
                const o = document.createElement("option"); o.textContent = {title!r};
                document.getElementById("motion").appendChild(o);
                document.getElementById("status").textContent =
                    "generating… compiling the generator for paths of 1024 samples × 8 walks, once (about 12 s); " +
                    "warmed up 17 of 60";
                document.querySelectorAll(".dl").forEach((b) => {{ b.disabled = false; }});
            }}""")
            for width in (800, 1280, 2560):
                page.set_viewport_size({"width": width, "height": 900})
                boxes = _boxes(page)
                names = {b["name"] for b in boxes}
                assert {"status", "motion", "dl-bvh", "dl-gif", "play", "scrub", "generate", "floor"} <= names, names
                for i, a in enumerate(boxes):
                    assert a["x"] >= -1 and a["x"] + a["w"] <= width + 1, (width, a)
                    for b in boxes[i + 1:]:
                        assert _overlap(a, b) == 0, (width, a, b)
        finally:
            browser.close()


# The steer test's script, in seconds of the page's clock: (time, "down"/"up", key) and the style change
STEER_SECONDS = 60.0
STEER_KEYS = [(3.0, "down", "ArrowUp"), (3.5, "up", "ArrowUp"),  # +0.4 m/s (0.8 m/s per second held)
              (6.0, "down", "ArrowRight"), (7.5, "up", "ArrowRight"),
              (10.0, "down", "KeyS"), (10.5, "up", "KeyS"),  # back to 1.2 m/s
              (13.0, "down", "KeyA"), (14.5, "up", "KeyA"),
              (36.0, "down", "ArrowLeft"), (37.5, "up", "ArrowLeft"),
              (45.0, "down", "KeyD"), (46.5, "up", "KeyD")]
STEER_TURNS = [(t, next(u for u, how_u, k_u in STEER_KEYS if how_u == "up" and k_u == k and u > t), k)
               for t, how, k in STEER_KEYS if how == "down" and k in ("ArrowRight", "KeyD", "ArrowLeft", "KeyA")]
STEER_STYLE_AT = 30.0  # Normal, then OldMan
TURN_RATE = 1.2  # rad/s with a turn key held (app.js), positive to the right: the floor angle atan2(z, x) grows
MAX_TURN_DELAY_S = 1.5  # key down to a visible turn of 20 degrees, stated in the README
HEADING_SPAN = 8  # samples over which the shown heading is the root's direction of travel (0.53 s)


def test_drop_a_clip_see_its_style_as_a_mix_and_walk_it(playwright_api, demo_url, tmp_path):
    """Walk like this clip: a held-out clip of the embedded dataset dropped on the page shows its
    recovered style as a mix of the known styles (the server's answer, drawn as bars), and the
    active panel walks that mix on the drawn path at the clip's speed. A bad file gets the
    server's message on the page, and the walk stays as it was."""
    from motiongan_jax.data import synthetic

    names = pretrained.read_export(pretrained.SHIPPED_MODEL).meta["style_names"]
    clip = synthetic.default_dataset_dir() / "OldMan_05.bvh"  # held out: trial 5 of 5
    with playwright_api() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page = browser.new_page(viewport={"width": 1280, "height": 860})
            errors = []
            page.on("pageerror", lambda e: errors.append(str(e)))
            page.goto(demo_url)
            page.wait_for_selector("#mode-label .chip")
            page.locator("#presets button", has_text="Circle").click()
            page.wait_for_function("window.demo.state.strokes.length === 1")
            _wait_generated(page, 0)  # the circle, walked in the first style
            with page.expect_response("**/api/clip?name=OldMan_05.bvh", timeout=300_000) as answer:
                _drop_file(page, "#clip-drop", clip.name, clip.read_bytes())
            assert answer.value.status == 200, answer.value.text()
            res = answer.value.json()
            page.wait_for_selector("#clip-mix")
            shown = page.locator("#clip-mix span").all_inner_texts()
            assert shown[0::3] == [n for n, _ in res["mix"]] and set(shown[0::3]) <= set(names)
            assert shown[2::3] == [f"{math.floor(100 * a + 0.5)}%" for _, a in res["mix"]]  # JS's Math.round
            assert res["nearest"][0][0] == "OldMan", res  # the shipped model knows this style
            head = page.locator("#clip-result .muted").inner_text()
            assert head.startswith(f"OldMan_05.bvh: {res['seconds']:.1f} s at {res['speed']:.2f} m/s · nearest OldMan")
            # the active panel now walks the mix, at the clip's speed, on the circle
            want = ",".join(f"{n}:{a:g}" for n, a in res["mix"] if a > 0)
            assert page.locator("#style-string").inner_text() == f"style: {want}"
            shown_speed = float(page.locator("#speed-value").inner_text().split()[0])
            assert abs(shown_speed - res["speed"]) <= 0.025 + 1e-6  # the clip's, on the slider's 0.05 m/s steps
            page.wait_for_function(f"window.demo.state.result && !window.demo.state.inflight && "
                                   f"window.demo.state.result.motions[0].title === {want!r}", timeout=300_000)
            assert page.locator("#error").is_hidden(), page.locator("#error").inner_text()

            # a file on another skeleton, chosen with the file input: the server's 400, on the page
            bad = tmp_path / "other.bvh"
            bad.write_text(clip.read_text().replace("JOINT LeftUpLeg", "JOINT LeftThigh"))
            page.set_input_files("#clip-file", str(bad))
            page.wait_for_function("document.getElementById('clip-result').classList.contains('bad')")
            msg = page.locator("#clip-result").inner_text()
            assert msg.startswith("other.bvh: not the model's skeleton") and "LeftThigh" in msg, msg
            assert page.evaluate("window.demo.state.result.motions[0].title") == want
            assert not errors, errors
        finally:
            browser.close()


CONTROLS = "button, select, input, canvas, #status, #time, #path-length, #style-string, #expr-check, #model-info"


def _rss_mib(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        return next(int(line.split()[1]) for line in f if line.startswith("VmRSS:")) / 1024


def _heading(root_xz, i):
    d = root_xz[i] - root_xz[i - HEADING_SPAN]
    return np.arctan2(d[1], d[0])


def test_steer_a_minute_with_the_keys_in_two_styles(playwright_api, demo_server):
    """The steer mode walked for 60 s of the page's clock, ticked by the test as fast as the server
    answers (every sample is generated by the server; the page asks for it as it would in real
    time). The walker never stops, turns and speeds up with the keys (the delay measured), keeps its
    feet on the floor, blends from Normal to OldMan over a second, and the server holds one walker
    whose state stays flat, its memory too. The character is posed live from the steps' joint
    rotations (three.js draws its body) when picked after the minute, walked as a stick figure."""
    url, proc = demo_server
    with playwright_api() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, args=ARGS)
        try:
            page, errors = _open(browser, url)
            info = page.evaluate("window.demo.state.model")
            rate, toes = info["fps"], [i for i, n in enumerate(info["joint_names"]) if "Toe" in n]
            assert len(toes) >= 2
            page.locator("#walk-steer").click()
            assert page.locator("#steer-go").is_visible() and page.locator("#generate").is_hidden()
            # the minute is walked with the stick figure: chromium's software WebGL drawing the
            # character 60 times a second would take the cores the server's steps need here
            page.select_option("#look", "stick")
            page.evaluate("window.demo.steer.drive(true); window.demo.steer.record(true)")
            page.locator("#mode-label .chip", has_text="Normal").click()
            page.locator("#steer-go").click()
            page.wait_for_function("window.demo.steer.state.session !== null", timeout=300_000)
            ticks = int(STEER_SECONDS * rate)
            keys = sorted(STEER_KEYS)
            views, records, stats, rss = [], [], [], {}
            t_start = time.monotonic()
            for i in range(1, ticks + 1):
                t = i / rate
                while keys and keys[0][0] <= t - 1 / rate + 1e-9:  # the key changes before this tick
                    _, how, key = keys.pop(0)
                    (page.keyboard.down if how == "down" else page.keyboard.up)(key)
                if abs(t - STEER_STYLE_AT) < 0.5 / rate:
                    page.locator("#mode-label .chip", has_text="OldMan").click()
                views.append(page.evaluate("window.demo.steer.tick(1 / %r)" % rate))  # waits for the server
                if i % int(5 * rate) == 0:
                    records += page.evaluate("window.demo.steer.drain()")
                    stats.append((t, page.evaluate("fetch('/api/steer').then((r) => r.json())")))
                    rss[t] = _rss_mib(proc.pid)
            wall = time.monotonic() - t_start
            records += page.evaluate("window.demo.steer.drain()")
            # the stick figure, then the character posed live from the steps' rotations (three.js)
            shown = _bone_pixels(page.locator("#view").screenshot())
            page.select_option("#look", "character")
            page.wait_for_timeout(500)
            body = _body_pixels(page.locator("#view").screenshot())
            posed = page.evaluate("window.demo.steer.state.char.loaded && window.demo.steer.state.rots.length")
            assert not errors, errors
            assert page.locator("#error").is_hidden(), page.locator("#error").inner_text()
        finally:
            browser.close()

    # every sample came from the server, in order, none twice: a minute of walk and the buffer
    index = np.concatenate([np.arange(r["index0"], r["index0"] + len(r["positions"])) for r in records])
    np.testing.assert_array_equal(index, np.arange(len(index)))
    assert len(index) >= ticks + 1
    pos = np.concatenate([np.array(r["positions"]) for r in records])
    curve = np.concatenate([np.array(r["curve"]) for r in records])
    blend = np.concatenate([r["blend"] for r in records])
    style = sum(([r["style"]] * len(r["positions"]) for r in records), [])
    chex.assert_shape(pos, (len(index), len(info["joint_names"]), 3))
    root = pos[:, 0, [0, 2]]
    shown_root = np.array([v["root"] for v in views])[:, [0, 2]]
    print(f"steer: {len(index)} samples in {wall:.0f} s of wall clock, {len(records)} steps; "
          f"buffer target {views[-1]['target']} samples, round trip {1e3 * views[-1]['rtt']:.0f} ms")

    # it never stops: every second of the walk (and of what the page shows) covers at least half
    # the slowest speed asked for (1.2 m/s)
    for r in (root, shown_root):
        second = np.linalg.norm(r[int(rate):] - r[:-int(rate)], axis=1)
        assert second.min() > 0.6, second.min()
    np.testing.assert_allclose([v["clock"] for v in views], np.arange(1, ticks + 1), atol=1e-6)

    # speed keys: the path's spacing is the speed asked for (1.6 m/s after 0.5 s of ArrowUp, 1.2
    # after KeyS) from the first sample asked for after the key (the page's buffer, up to 1.5 round
    # trips, was emitted before it), the root's pace follows within 10 %
    lag = max(v["target"] for v in views)
    for t0, t1, speed in ((4.5, 5.9, 1.2 + 0.8 * 0.5), (11.5, 12.9, 1.2), (20.0, 29.0, 1.2)):
        a, b = int(t0 * rate), int(t1 * rate)
        np.testing.assert_allclose(np.linalg.norm(np.diff(curve[min(a + lag, b - 2):b], axis=0), axis=1),
                                   speed / rate, rtol=0.03)
        pace = np.linalg.norm(root[b] - root[a]) / (t1 - t0)
        assert pace == pytest.approx(speed, rel=0.1), (t0, pace, speed)

    # turn keys: the shown heading (the root's direction over the last 8 samples) turns the key's way
    # by 20 degrees within MAX_TURN_DELAY_S of the key going down, and by about what the key asked for
    assert len(STEER_TURNS) == 4
    for t_down, t_up, key in STEER_TURNS:
        sign = 1.0 if key in ("ArrowRight", "KeyD") else -1.0
        i0 = int(round(t_down * rate)) - 1  # the view before the key went down
        before = _heading(shown_root, i0)
        turned = [sign * np.angle(np.exp(1j * (_heading(shown_root, i) - before)))
                  for i in range(i0, i0 + 3 * int(rate))]
        first = next((k for k, a in enumerate(turned) if a > np.radians(20)), None)
        assert first is not None, (key, np.degrees(max(turned)))
        delay = first / rate
        print(f"steer: {key} at {t_down:g} s turns the shown heading 20 degrees after {delay:.2f} s")
        assert delay <= MAX_TURN_DELAY_S, (key, delay)
        i1 = int(round((t_up + 3.0) * rate))  # settled: 3 s after the key went up
        total = sign * np.angle(np.exp(1j * (_heading(shown_root, i1) - before)))
        asked = TURN_RATE * (t_up - t_down)
        assert 0.7 * asked < total < 1.3 * asked, (key, np.degrees(total), np.degrees(asked))
    # no key, no turn: straight on between the turns
    for t0, t1 in ((20.0, 29.0), (50.0, 59.0)):
        a, b = int(t0 * rate), int(t1 * rate)
        drift = np.angle(np.exp(1j * (_heading(root, b) - _heading(root, a))))
        assert abs(drift) < np.radians(8), (t0, np.degrees(drift))

    # feet on the floor: in every second the lowest toe touches 0 (within 3 cm), and never sinks 5 cm
    toe = pos[:, toes, 1].min(axis=1)
    per_second = np.array([toe[k:k + int(rate)].min() for k in range(len(toe) - int(rate))])
    assert np.abs(per_second).max() < 0.03 and toe.min() > -0.05, (per_second.min(), per_second.max(), toe.min())

    # the style: Normal, then OldMan blended in linearly over a second (15 samples) from the first
    # sample the server had not emitted when the page sent it, within a second of the click
    change = next(k for k, b in enumerate(blend) if b < 1.0)
    assert set(style[:change]) == {"Normal"} and set(style[change + 1:]) == {"OldMan"}
    k = np.arange(len(blend))
    np.testing.assert_allclose(blend, np.clip((k - change) / rate, 0, 1) + (k < change), atol=1e-4)
    assert STEER_STYLE_AT * rate <= change <= (STEER_STYLE_AT + 1.0) * rate, change
    rel = pos - pos[:, :1]  # root-relative joints: the style's posture, wherever it walks

    def posture(t0, t1):
        return rel[int(t0 * rate):int(t1 * rate)].mean(axis=0)

    same = np.sqrt(((posture(17, 23) - posture(23, 29)) ** 2).sum(-1).mean())  # Normal vs Normal
    other = np.sqrt(((posture(23, 29) - posture(39, 45)) ** 2).sum(-1).mean())  # Normal vs OldMan
    print(f"steer: posture change Normal-Normal {100 * same:.1f} cm, Normal-OldMan {100 * other:.1f} cm")
    assert other > 0.03 and other > 3 * same

    # the page draws it continuously and the camera follows: frames drawn all along, the camera's
    # target the shown hips (at the clock of the frame drawn), its eye the follow distance away
    drawn = np.array([v["drawn"] for v in views])
    assert drawn[-1] - drawn[0] > 60 and shown > 300, (drawn[-1] - drawn[0], shown)
    assert posed and body > 2000, (posed, body)
    by_clock = {round(v["clock"]): np.array(v["root"]) for v in views}
    for v in views[int(rate):]:
        cam = v["camera"]
        hips = by_clock.get(round(cam["clock"]))
        if hips is None:
            continue
        assert np.linalg.norm(np.array(cam["target"])[[0, 2]] - hips[[0, 2]]) < 0.02
        assert 2.5 < np.linalg.norm(np.array(cam["eye"]) - np.array(cam["target"])) < 4.5

    # the server: one walker all along, its state flat once its rings are full (by 15 s), and its
    # memory flat after that: the median RSS of 45-60 s within 64 MiB of that of 15-30 s (RSS moves
    # by 10-35 MiB from one 5-s reading to the next here, as the server's request threads take
    # turns; a compile per step would add hundreds of MiB; what a walker keeps, the state numbers bound)
    print(f"steer: server RSS {[round(r) for r in rss.values()]} MiB every 5 s; walker state "
          f"{[s['state_numbers'] for _, s in stats]} numbers")
    assert all(s["walkers"] == 1 and s["max_walkers"] == 8 for _, s in stats), stats
    # (the state moves with each step's size; one that kept 3 numbers a sample would grow 1350 in 30 s)
    early = [s["state_numbers"][0] for t, s in stats if 15 <= t <= 30]
    late = [s["state_numbers"][0] for t, s in stats if t > 45]
    emitted = [s["emitted"][0] for _, s in stats]
    assert emitted[-1] > 3 * emitted[2] and max(late) <= max(early) + 500, (early, late, emitted)
    early_rss = np.median([r for t, r in rss.items() if 15 <= t <= 30])
    late_rss = np.median([r for t, r in rss.items() if t >= 45])
    assert late_rss - early_rss < 64, rss
