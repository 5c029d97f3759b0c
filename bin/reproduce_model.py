#!/usr/bin/env python
"""Reproduce an exported model: motiongan_jax/cli/reproduce_model.py (also `motiongan-reproduce-model`)."""

from motiongan_jax.cli.reproduce_model import main

raise SystemExit(main())
