"""Reproduce an exported model from its own record: train the config stored in the export (its
seed and steps included) on the embedded dataset, export the result, and compare the weights.

  python bin/reproduce_model.py --workdir runs/shipped                 # the shipped model
  python bin/reproduce_model.py --workdir runs/repro --model model.npz  # any export

A run already in --workdir is resumed (a killed reproduction continues where it stopped and
ends the same). Prints both exports' provenance and `params_sha256`; exit status 0 when the
weights are bit for bit the same, 1 when they differ (e.g. another jax version or machine: the
provenance lists the versions used), 2 for bad input. The new export is --workdir/model.npz.
"""

import argparse
import sys
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workdir", required=True, help="where to train (resumed if present)")
    ap.add_argument("--model", default=None, help="the export to reproduce (default: the shipped model)")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)

    from motiongan_jax.config import ConfigError, from_dict, validate
    from motiongan_jax.data.file_labels import DataError
    from motiongan_jax.model import pretrained
    from motiongan_jax.model.checkpoint import CheckpointError
    from motiongan_jax.train.loop import train

    try:
        target = pretrained.read_export(pretrained.SHIPPED_MODEL if args.model is None else args.model)
        cfg = validate(from_dict(target.meta["config"]))
        if cfg.data.data_dir is not None:
            raise ConfigError(f"{target.path.name} was trained on {cfg.data.data_dir}, not the embedded "
                              "dataset: reproduce it with bin/train.py --data and bin/export_model.py")
        print(f"reproducing {target.describe()}", flush=True)
        train(cfg, args.workdir, progress=not args.no_progress)
        out = Path(args.workdir) / "model.npz"
        info = pretrained.export_run(args.workdir, out, params=target.provenance["params"])
    except (CheckpointError, ConfigError, DataError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    for what, digest, prov in (("target    ", target.params_sha256, target.provenance),
                               ("reproduced", info["params_sha256"], info)):
        print(f"{what} params_sha256 {digest} (jax {prov['jax']}, commit {prov['source_commit']})")
    same = info["params_sha256"] == target.params_sha256
    print("the same weights, bit for bit" if same else "the weights differ")
    return 0 if same else 1
