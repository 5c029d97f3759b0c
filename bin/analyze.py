#!/usr/bin/env python
"""Style-space analysis and style search: motiongan_jax/cli/analyze.py (also `motiongan-analyze`)."""

from motiongan_jax.cli.analyze import main

raise SystemExit(main())
