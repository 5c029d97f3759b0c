"""Train MotionGAN, or resume the run in --workdir.

  python bin/train.py --config configs/small.py --workdir runs/small [--data DATA_DIR] [--seed N]
                      [--steps N] [--set section.field=value ...] [--dry-run]

Without --data it trains on the embedded default dataset (procedural styled walks, generated
on first use into the cache). Writes DIR/metrics.jsonl, DIR/checkpoints/, DIR/previews/*.gif,
DIR/config.json and DIR/{train,val}_files.txt.

Several processes (hosts, or one process per GPU): start the same command in each, with
--coordinator HOST:PORT --num-processes N --process-id I, or the variables JAX_COORDINATOR_ADDRESS,
JAX_NUM_PROCESSES, JAX_PROCESS_ID; under SLURM's srun or Open MPI's mpirun (more than one task)
jax reads the launcher's own variables and no flag is needed. The workdir must be one shared
directory; process 0 writes everything but the checkpoints, which all write together.
"""

import argparse
import sys


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--config", required=True, help="a configs/*.py file")
    ap.add_argument("--workdir", required=True)
    ap.add_argument("--data", default=None, help="BVH directory (default: the embedded dataset)")
    ap.add_argument("--seed", type=int, default=None)
    ap.add_argument("--steps", type=int, default=None, help="total training steps (train.num_steps)")
    ap.add_argument("--set", nargs="+", action="extend", default=[], metavar="FIELD=VALUE",
                    help="override config fields (repeatable: --set a=1 b=2 --set c=3)")
    ap.add_argument("--dry-run", action="store_true", help="print parameter counts and shapes, then exit")
    ap.add_argument("--no-progress", action="store_true", help="no progress bar")
    ap.add_argument("--coordinator", default=None, metavar="HOST:PORT",
                    help="several processes: process 0's address (with --num-processes, --process-id)")
    ap.add_argument("--num-processes", type=int, default=None)
    ap.add_argument("--process-id", type=int, default=None)
    args = ap.parse_args(argv)
    from motiongan_jax.generate.limits import MAX_SEED

    if args.seed is not None and not 0 <= args.seed <= MAX_SEED:  # the seeds generate.py and the demo take
        ap.error(f"--seed must be an integer 0..{MAX_SEED}, got {args.seed}")

    from motiongan_jax.config import ConfigError, load_config, override, validate
    from motiongan_jax.data.file_labels import DataError
    from motiongan_jax.model.checkpoint import CheckpointError
    from motiongan_jax.motion.bvh import BVHError
    from motiongan_jax.train import parallel

    try:
        cfg = load_config(args.config, check=False)
        sets = list(args.set)
        if args.data is not None:
            sets.append(f"data.data_dir={args.data}")
        if args.seed is not None:
            sets.append(f"train.seed={args.seed}")
        if args.steps is not None:
            sets.append(f"train.num_steps={args.steps}")
        cfg = validate(override(cfg, sets), need_data=not args.dry_run)
        if args.dry_run:
            from motiongan_jax.train.summary import describe

            print(describe(cfg))
            return 0
        from motiongan_jax.cli import use_compilation_cache
        from motiongan_jax.generate.preview import previewer
        from motiongan_jax.train.loop import NonFiniteError, train

        use_compilation_cache()  # a resumed run loads the step its first run compiled

        # several processes: from the flags, the variables or the launcher (docs/PERFORMANCE.md)
        parallel.initialize_distributed(args.coordinator, args.num_processes, args.process_id)
        last = train(cfg, args.workdir, progress=not args.no_progress, preview=previewer)
        primary = parallel.is_primary()
    except (ConfigError, DataError, BVHError, CheckpointError, parallel.DistributedError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    except NonFiniteError as err:
        print(f"error: {err}", file=sys.stderr)
        return 3
    if primary:
        if last:
            print("final " + " ".join(f"{k}={v:.4g}" for k, v in sorted(last.items())))
        print(f"done: {args.workdir}")
    return 0
