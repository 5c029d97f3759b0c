#!/usr/bin/env python
"""Evaluate a trained run: motiongan_jax/cli/evaluate.py (also `motiongan-evaluate`)."""

from motiongan_jax.cli.evaluate import main

raise SystemExit(main())
