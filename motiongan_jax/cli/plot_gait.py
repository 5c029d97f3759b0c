"""Toe heights over time, real against generated, per style: does G walk?

  python bin/plot_gait.py --workdir runs/small --out runs/small/gait.png [--seconds 6] [--step N] [--params ema|raw]

For each style, the first held-out clip of that style (left) and G walking that clip's path in its
style (right): the heights of both toes above the floor, the band below the contact height
(calibrated on the training clips) shaded. Exit status: 0 done, 2 bad input.
"""

import argparse
import sys

from motiongan_jax.cli import add_checkpoint_arguments


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workdir", required=True, help="a training run (its latest checkpoint)")
    ap.add_argument("--out", required=True, help="output image (.png, .pdf, .svg)")
    ap.add_argument("--data", default=None, help="the run's data directory (default: as trained)")
    ap.add_argument("--seconds", type=float, default=6.0, help="length of each trace (default 6)")
    add_checkpoint_arguments(ap)
    args = ap.parse_args(argv)

    import dataclasses

    from motiongan_jax import viz
    from motiongan_jax.config import ConfigError
    from motiongan_jax.data import clip_cache, file_labels, gait_stats
    from motiongan_jax.evaluation import clip_metrics
    from motiongan_jax.generate import limits, walk
    from motiongan_jax.model import checkpoint
    from motiongan_jax.motion import representation

    try:
        if not args.seconds > 0:
            raise ConfigError(f"--seconds must be positive, got {args.seconds}")
        state, meta, cfg, layout = checkpoint.load_run(args.workdir, args.step, args.params)
        if args.data is not None:
            cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, data_dir=args.data))
        dataset = clip_cache.load_dataset(cfg.data)
        if not dataset.val:
            raise file_labels.DataError("the validation split is empty: no held-out clip to compare with")
        feet = representation.foot_joints(layout)
        rate = walk.sample_rate(meta, cfg)
        traces = clip_metrics.gait_traces(state, cfg, layout, dataset.val, tuple(meta["style_names"]), feet, rate,
                                        args.seconds)
        if not traces:
            raise file_labels.DataError("no held-out clip is long enough for a trace")
        contact = gait_stats.contact_height(dataset.train, layout, feet)
        viz.plot_gait(traces, args.out, sample_rate=rate, contact_height_m=contact,
                      title=f"{cfg.name}: toe heights above the floor, real held-out clips and G on their paths")
    except (ConfigError, file_labels.DataError, checkpoint.CheckpointError, limits.GenerateError, ValueError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"wrote {args.out}")
    return 0
