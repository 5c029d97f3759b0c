#!/usr/bin/env python
"""Train the style evaluator: motiongan_jax/cli/train_evaluator.py (also `motiongan-train-evaluator`)."""

from motiongan_jax.cli.train_evaluator import main

raise SystemExit(main())
