"""Train the style evaluator (a temporal CNN, not the discriminator) on real training windows.

  python bin/train_evaluator.py --config configs/small.py --out runs/small/evaluator.npz
                                [--data DATA_DIR] [--set field=value ...] [--steps N] [--seed N]
  python bin/train_evaluator.py --workdir runs/small            # the run's config and data
  python bin/train_evaluator.py --workdir runs/small --speed-free   # -> runs/small/evaluator_speed_free.npz

Uses the config's data settings and training split (the validation split is held out), with the
training sampler's FPS augmentation. Writes OUT (.npz) and OUT with .json (meta and the weights'
SHA-256 checksum), and prints the accuracy on real held-out windows: the ceiling for generated
motion. --speed-free trains the variant that scores each frame's pose alone (evaluation/evaluator.py):
no travel speed, cadence or joint speed among what it reads.
"""

import argparse
import json
import sys
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group(required=True)
    src.add_argument("--config", help="a configs/*.py file")
    src.add_argument("--workdir", help="a training run: use its config.json")
    ap.add_argument("--out", default=None, help="evaluator .npz (default: WORKDIR/evaluator.npz)")
    ap.add_argument("--data", default=None, help="BVH directory (default: the config's)")
    ap.add_argument("--set", nargs="+", action="extend", default=[], metavar="FIELD=VALUE",
                    help="override config fields (repeatable)")
    ap.add_argument("--steps", type=int, default=None, help="evaluator training steps (default 1500)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--speed-free", action="store_true",
                    help="the speed-free variant (per-frame poses; default out WORKDIR/evaluator_speed_free.npz)")
    args = ap.parse_args(argv)

    import dataclasses

    import jax

    from motiongan_jax.config import (
        ConfigError,
        from_dict,
        load_config,
        override,
        validate,
    )
    from motiongan_jax.data import clip_cache, file_labels, sampling
    from motiongan_jax.evaluation import evaluator, metrics
    from motiongan_jax.motion.bvh import BVHError

    try:
        if args.workdir:
            cfg_file = Path(args.workdir) / "config.json"
            if not cfg_file.is_file():
                raise ConfigError(f"{cfg_file}: no such file (is {args.workdir} a training run?)")
            cfg = from_dict(json.loads(cfg_file.read_text())["config"])
        else:
            cfg = load_config(args.config, check=False)
        sets = list(args.set) + ([f"data.data_dir={args.data}"] if args.data else [])
        cfg = validate(override(cfg, sets))
        default = "evaluator_speed_free.npz" if args.speed_free else "evaluator.npz"
        out = Path(args.out) if args.out else (Path(args.workdir) / default if args.workdir else None)
        if out is None:
            raise ConfigError("--out is required with --config")
        ecfg = evaluator.EvaluatorConfig(seed=args.seed, speed_free=args.speed_free,
                                         **({"steps": args.steps} if args.steps else {}))
        if ecfg.steps < 1:
            raise ConfigError("--steps must be positive")

        dataset = clip_cache.load_dataset(cfg.data)
        if not dataset.val:
            raise file_labels.DataError("the validation split is empty: nothing to measure the evaluator on "
                                 "(check data.val_modulus / data.val_remainder)")
        arrays = sampling.build_arrays(dataset.train, dataset.style_names, cfg.data)
        sample = jax.jit(sampling.make_sample_batch(dataclasses.replace(cfg.data, rotate=False), ecfg.batch_size))
        T, step = cfg.data.window_T, cfg.data.frame_step
        ev = evaluator.train(lambda k, i: sample(arrays, k, i), dataset.layout.num_rows, dataset.style_names, ecfg,
                             log=print, meta={
                                 "data_config_hash": _data_hash(cfg),
                                 "data_dir": dataset.data_dir,
                                 "joint_names": list(dataset.layout.joint_names),
                                 "window_T": T, "frame_step": step, "fps": dataset.fps,
                                 "train_files": sorted(Path(c.source).name for c in dataset.train),
                                 "val_files": sorted(Path(c.source).name for c in dataset.val)})
        root, pose, labels, _ = evaluator.real_windows(dataset.val, dataset.style_names, T, step)
        if len(root) == 0:
            raise file_labels.DataError(f"no validation clip is long enough for one window of {T} samples")
        logits, _ = evaluator.classify(ev, root, pose)
        sra = metrics.style_recognition(logits, labels)
        ev.meta["real_heldout"] = {"windows": int(len(labels)), "top1": sra["top1"], "top3": sra["top3"],
                                   "chance": 1.0 / dataset.num_styles}
        npz, side = evaluator.save(ev, out)
    except (ConfigError, file_labels.DataError, BVHError, evaluator.EvaluatorError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    print(f"real held-out windows: {len(labels)}; top-1 {sra['top1']:.3f}, top-3 {sra['top3']:.3f} "
          f"(chance {1.0 / dataset.num_styles:.3f})")
    print(f"checksum {ev.checksum}")
    print(f"wrote {npz} and {side}")
    return 0


def _data_hash(cfg) -> str:
    import hashlib

    from motiongan_jax.config import to_dict

    return hashlib.sha256(json.dumps(to_dict(cfg)["data"], sort_keys=True).encode()).hexdigest()[:16]
