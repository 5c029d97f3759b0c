#!/usr/bin/env python
"""Toe heights, real against generated: motiongan_jax/cli/plot_gait.py (also `motiongan-plot-gait`)."""

from motiongan_jax.cli.plot_gait import main

raise SystemExit(main())
