"""Export a trained model for generation: G's parameters and the meta needed to use them, in one
small .npz with its provenance and a checksum (motiongan_jax/model/pretrained.py).

  python bin/export_model.py --workdir runs/small --out model.npz [--step N] [--params ema|raw]
  python bin/export_model.py --info model.npz          # check a file and print its provenance
  python bin/export_model.py --upgrade old.npz --out model.npz   # an older export in today's schema

The export loads wherever a run's --workdir does: `bin/generate.py --model model.npz`,
`bin/analyze.py --model model.npz`, `motiongan-demo --model model.npz`. Prints the provenance
(config hash, seed, steps, source commit) and the two SHA-256 digests: `params_sha256` (the
weights alone: equal for a bit-for-bit reproduction) and `sha256` (the whole file's contents,
checked on every load).
Exit status: 0 done, 2 bad input (no checkpoint, unwritable output, damaged file).
"""

import argparse
import json
import sys
from pathlib import Path

from motiongan_jax.cli import add_checkpoint_arguments


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    what = ap.add_mutually_exclusive_group(required=True)
    what.add_argument("--workdir", help="a training run's directory (with checkpoints/)")
    what.add_argument("--info", metavar="FILE", help="verify an export and print its provenance")
    what.add_argument("--upgrade", metavar="FILE", help="rewrite an older export's config in today's schema "
                      "(same weights) to --out")
    ap.add_argument("--out", help="the export file to write (.npz)")
    add_checkpoint_arguments(ap)
    args = ap.parse_args(argv)
    if (args.workdir is not None or args.upgrade is not None) and not args.out:
        ap.error("--workdir and --upgrade need --out FILE.npz")
    if args.out and not args.out.endswith(".npz"):
        ap.error(f"--out must end in .npz, got {args.out!r}")

    from motiongan_jax.model import pretrained
    from motiongan_jax.model.checkpoint import CheckpointError

    try:
        if args.info:
            export = pretrained.read_export(args.info)
            info = {**export.provenance, "params_sha256": export.params_sha256, "sha256": export.sha256,
                    "style_names": export.meta["style_names"]}
        elif args.upgrade:
            info = pretrained.upgrade_export(args.upgrade, args.out)
        else:
            info = pretrained.export_run(args.workdir, args.out, step=args.step, params=args.params)
    except (CheckpointError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(json.dumps(info, indent=1))
    if args.out:
        print(f"wrote {args.out} ({Path(args.out).stat().st_size / 1e6:.2f} MB)")
    return 0
