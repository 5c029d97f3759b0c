"""The command-line tools, one module each with `main(argv=None) -> int` (the exit status).

They live in the package so that an installed copy has them as console scripts (`motiongan-X`,
pyproject.toml) and `bin/X.py` needs no path set-up: each is a thin wrapper around `main`.
The tools parse arguments, call the library and print; the work is in the library's modules.
"""
