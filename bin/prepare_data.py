#!/usr/bin/env python
"""Export BVH files as world joint positions: motiongan_jax/cli/prepare_data.py (also `motiongan-prepare-data`)."""

from motiongan_jax.cli.prepare_data import main

raise SystemExit(main())
