#!/usr/bin/env python
"""The README's picture of the demo page: motiongan_jax/cli/demo_screenshot.py (also `motiongan-demo-screenshot`)."""

from motiongan_jax.cli.demo_screenshot import main

raise SystemExit(main())
