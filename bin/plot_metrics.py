#!/usr/bin/env python
"""Loss curves of a training run: motiongan_jax/cli/plot_metrics.py (also `motiongan-plot-metrics`)."""

from motiongan_jax.cli.plot_metrics import main

raise SystemExit(main())
