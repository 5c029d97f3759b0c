"""Benchmarks, run by hand from the repository root as modules: `python -m bench.bench_X` (README).

A package so that the benchmarks import each other and `bench.timing` by name, with no path
set-up of their own; the library itself comes from the installed motiongan_jax.
"""
