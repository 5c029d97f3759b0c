"""The command-line tools, one module each with `main(argv=None) -> int` (the exit status).

They live in the package so that an installed copy has them as console scripts (`motiongan-X`,
pyproject.toml) and `bin/X.py` needs no path set-up: each is a thin wrapper around `main`.
The tools parse arguments, call the library and print; the work is in the library's modules.
"""


def add_model_arguments(ap) -> None:
    """--workdir or --model (neither: the shipped model), then `add_checkpoint_arguments`."""
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--workdir", default=None,
                     help="a training run's directory (with checkpoints/); default: the shipped model")
    src.add_argument("--model", default=None, help="an export file (bin/export_model.py) instead of a run")
    add_checkpoint_arguments(ap)


def add_checkpoint_arguments(ap) -> None:
    """--step and --params: which of a run's checkpoints, and which of G's parameters in it."""
    ap.add_argument("--step", type=int, default=None,
                    help="checkpoint step (default: the run's model, the latest clear of an upset of D)")
    ap.add_argument("--params", choices=("ema", "raw"), default="ema",
                    help="G's parameters: ema (default; the moving average when the run keeps one) or raw")


COMPILE_CACHE_ENV = "MOTIONGAN_COMPILE_CACHE"


def use_compilation_cache() -> str | None:
    """Keep compiled programs across processes: JAX's persistent compilation cache in
    $MOTIONGAN_COMPILE_CACHE (`off`: none), default `<cache root>/xla`, i.e.
    ~/.cache/motiongan_jax/xla ($MOTIONGAN_CACHE moves the root). A folder JAX was already given
    (JAX_COMPILATION_CACHE_DIR) is kept. Entries are keyed by the program, the compile options and
    the jax/jaxlib versions, so a hit computes what a compile would; the folder is safe to delete.
    Returns the folder in use (None: off)."""
    import os

    import jax

    wanted = os.environ.get(COMPILE_CACHE_ENV, "").strip()
    if wanted.lower() in ("off", "0", "none"):
        return None
    if not wanted and jax.config.jax_compilation_cache_dir:
        return jax.config.jax_compilation_cache_dir
    if not wanted:
        from motiongan_jax.cache import cache_root

        wanted = str(cache_root() / "xla")
    jax.config.update("jax_compilation_cache_dir", wanted)
    # every program, not only those over JAX's default 1 s: the few dozen small ones around G
    # (IK, the floor, the codes) cost a fresh motiongan-generate about 1 s of CPU (measured,
    # docs/PERFORMANCE.md), and the folder stays under a megabyte per model
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    return wanted
