#!/usr/bin/env python
"""Train MotionGAN, or resume a run: motiongan_jax/cli/train.py (also `motiongan-train`)."""

from motiongan_jax.cli.train import main

raise SystemExit(main())
