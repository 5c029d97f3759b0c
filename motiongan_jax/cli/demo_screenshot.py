"""The README's picture of the demo page: starts motiongan-demo on a free port, has Debian's
chromium (through Playwright) pick the S-curve and three styles side by side, pause at --frame
and save a PNG.

  python bin/demo_screenshot.py --out docs/demo.png [--model FILE | --workdir RUN] [--styles A,B,C]

Needs `apt-get install chromium` and the test extra (Playwright); never `playwright install`.
"""

import argparse
import os
import re
import subprocess
import sys
from pathlib import Path

ARGS = ["--no-sandbox", "--headless", "--disable-gpu", "--disable-background-networking",
        "--disable-component-update", "--disable-sync", "--no-first-run"]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--out", required=True)
    ap.add_argument("--model", default=None)
    ap.add_argument("--workdir", default=None)
    ap.add_argument("--styles", default="OldMan,Happy,Marching")
    ap.add_argument("--chromium", default="/usr/bin/chromium")
    ap.add_argument("--size", default="1440x860", help="viewport WIDTHxHEIGHT")
    ap.add_argument("--frame", type=int, default=6, help="the frame shown (the walk is paused there)")
    args = ap.parse_args(argv)
    try:
        width, height = (int(v) for v in args.size.split("x"))
    except ValueError:
        ap.error(f"--size must be WIDTHxHEIGHT in pixels, e.g. 1440x860, got {args.size!r}")
    out = Path(args.out)
    if out.is_dir() or not out.parent.is_dir() or not os.access(out.parent, os.W_OK):
        print(f"error: cannot write {out}: {'it is a directory' if out.is_dir() else 'no writable folder'}",
              file=sys.stderr)
        return 2  # before the server and the browser start
    from playwright.sync_api import sync_playwright

    cmd = [sys.executable, "-m", "motiongan_jax.demo", "--port", "0", "--no-warm-up"]
    cmd += ["--model", args.model] if args.model else ["--workdir", args.workdir] if args.workdir else []
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        url = None
        for line in proc.stdout:
            m = re.search(r"serving on (http://\S+)", line)
            if m:
                url = m.group(1)
                break
        if url is None:
            print("error: the demo did not start", file=sys.stderr)
            return 2
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=args.chromium, args=ARGS)
            page = browser.new_page(viewport={"width": width, "height": height})
            page.goto(url)
            page.wait_for_selector("#mode-label .chip")
            page.locator("#auto").uncheck()
            page.locator("#presets button[data-shape=s_curve]").click()
            page.wait_for_timeout(300)
            styles = args.styles.split(",")
            for i, name in enumerate(styles):
                if i:
                    page.locator("#add-panel").click()
                page.locator("#mode-label .chip", has_text=name).first.click()
            seq = page.evaluate("window.demo.state.seq")
            page.locator("#generate").click()
            page.wait_for_function(f"window.demo.state.seq > {seq} && !window.demo.state.inflight",
                                   timeout=300_000)
            page.wait_for_timeout(1500)  # the follow camera settles behind the walkers
            page.evaluate("""f => { const s = document.querySelector('#scrub'); s.value = f;
                                     s.dispatchEvent(new Event('input', {bubbles: true})); }""", args.frame)
            page.wait_for_timeout(500)
            page.screenshot(path=args.out)
            browser.close()
    finally:
        proc.terminate()
        proc.wait(20)
    print(args.out)
    return 0
