"""Loss curves of a training run: a PNG and a Markdown table of running means at a few steps.

  python bin/plot_metrics.py --workdir runs/small --out runs/small/losses.png [--every 500]
"""

import argparse
import sys

from motiongan_jax.model import health

KEYS = ("d_total", "g_adv", "g_cls", "g_curve", "g_bone", "d_cls_acc_real", "g_cls_acc_fake")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--out", required=True)
    ap.add_argument("--every", type=int, default=500, help="table rows every N steps (mean of the last N)")
    args = ap.parse_args(argv)
    records = health.read_log(args.workdir)
    if not records:
        print(f"error: no metrics.jsonl records in {args.workdir}", file=sys.stderr)
        return 2
    from motiongan_jax import viz

    viz.plot_metrics(records, args.out, keys=KEYS, title=str(args.workdir))
    print("| steps | " + " | ".join(KEYS) + " |")
    print("|---" * (len(KEYS) + 1) + "|")
    last = records[-1]["step"]
    start = 0
    for end in list(range(args.every, last + 1, args.every)) + ([last] if last % args.every else []):
        rows = [r for r in records if start < r["step"] <= end]
        means = [sum(r[k] for r in rows) / len(rows) for k in KEYS]
        print(f"| {start + 1}-{end} | " + " | ".join(f"{m:.3g}" for m in means) + " |")
        start = end
    return 0
