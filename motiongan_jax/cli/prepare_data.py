"""BVH files as world joint positions (metres, Y up) in one .npz for your own code.

  python bin/prepare_data.py DATA_DIR --out FILE.npz [--labels paper|bandai|cmu]

Arrays: positions (frames x joints x 3, every joint incl. End Sites, all clips concatenated),
joint_names, parents, clip_start, clip_length, clip_style, style_names, fps, source_files.
Errors (a malformed file, an unwritable --out, a skeleton of implausible height in the unit
assumed): a message on stderr, exit status 2, and nothing written.
"""

import argparse
import sys

from motiongan_jax.config import LabelRule, choices
from motiongan_jax.data.file_labels import DataError
from motiongan_jax.data.positions_npz import write_positions_npz
from motiongan_jax.motion.bvh import BVHError


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("data_dir")
    ap.add_argument("--out", required=True)
    ap.add_argument("--labels", choices=choices(LabelRule), default="paper",
                    help="file-name rule for style labels (also picks the unit: bandai cm, else CMU units)")
    ap.add_argument("--units-to-m", type=float, default=None, help="metres per file unit (overrides --labels)")
    ap.add_argument("--skip-bad", action="store_true", help="report malformed files and go on with the rest")
    args = ap.parse_args(argv)
    if args.units_to_m is not None and not (0 < args.units_to_m < float("inf")):
        ap.error(f"--units-to-m must be a positive number of metres, got {args.units_to_m}")
    try:
        info = write_positions_npz(args.data_dir, args.out, args.labels, args.units_to_m, args.skip_bad,
                                log=lambda s: print(s, file=sys.stderr))
    except (BVHError, DataError, OSError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}: {info['clips']} clips, {info['frames']} frames, {info['joints']} joints, "
          f"{len(info['styles'])} styles ({', '.join(info['styles'])})")
    return 0
