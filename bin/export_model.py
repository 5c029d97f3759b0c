#!/usr/bin/env python
"""Export a trained model for generation: motiongan_jax/cli/export_model.py (also `motiongan-export-model`)."""

from motiongan_jax.cli.export_model import main

raise SystemExit(main())
