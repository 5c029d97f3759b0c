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
