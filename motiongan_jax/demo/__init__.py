"""A local web page: draw a path, pick a style (a label, a mix or an expression), watch the
skeleton walk it in 3-D, download BVH / NPZ / GIF. `motiongan-demo` or `python -m
motiongan_jax.demo`; engine.py checks and runs requests, server.py is the HTTP side, static/
the page (no file from outside the package)."""
