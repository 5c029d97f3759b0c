"""The learned style space: codes, PCA, distances, blending, a linear probe, and style search.

docs/DESIGN.md §5.2 (analysis) and §5.3 (style search), with the reference's bugs fixed (§6).
All numerics are jnp; plots live in `viz.py`, files are written by `analysis.report`.
"""
