#!/usr/bin/env python
"""Generate styled walks along a curve: motiongan_jax/cli/generate.py (also `motiongan-generate`)."""

from motiongan_jax.cli.generate import main

raise SystemExit(main())
