"""Evaluate a trained run with the project's protocol (docs/DESIGN.md §7).

  python bin/evaluate.py --workdir runs/small --out runs/small/eval
                         [--data DATA_DIR] [--evaluator runs/small/evaluator.npz]
                         [--cmu-curves DATA_DIR/cmu] [--seeds 0,1,2] [--k 3] [--step N]

Generates for every (unseen curve × style) with K noise draws and each seed; unseen curves are
the run's held-out real root paths (straight and turning), the root paths of the BVH files in
--cmu-curves (another lab: only their floor path is used), and the synthetic shapes. Scores
generated and real held-out data side by side with the evaluator (bin/train_evaluator.py).
Writes OUT/report.json, OUT/report.md, OUT/confusion.png and OUT/pca_w.png.
"""

import argparse
import sys
from pathlib import Path


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--workdir", required=True, help="a training run (its latest checkpoint)")
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--data", default=None, help="the run's data directory (default: as trained)")
    ap.add_argument("--evaluator", default=None, help="evaluator .npz (default WORKDIR/evaluator.npz)")
    ap.add_argument("--cmu-curves", default=None, help="directory of BVH files whose root paths are used as curves")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--k", type=int, default=3, help="noise draws per (curve, style), >= 3 in the protocol")
    ap.add_argument("--step", type=int, default=None, help="checkpoint step (default: latest)")
    ap.add_argument("--params", choices=("ema", "raw"), default="ema",
                    help="G's parameters: ema (default; the moving average when the run keeps one) or raw")
    ap.add_argument("--search-steps", type=int, default=200, help="style-search optimisation steps (0: skip)")
    ap.add_argument("--max-curves", type=int, default=12, help="held-out real curves at most")
    ap.add_argument("--shapes", default=",".join(("line", "circle", "s_curve", "figure8", "corner")),
                    help="synthetic curve shapes (comma-separated)")
    args = ap.parse_args(argv)

    import dataclasses
    import hashlib

    import jax
    import numpy as np

    from motiongan_jax import checkpoint, curves, data, evaluation, evaluator, generate, representation
    from motiongan_jax.bvh import BVHError
    from motiongan_jax.config import ConfigError, config_hash

    out = Path(args.out)
    try:
        try:
            seeds = tuple(int(s) for s in args.seeds.split(",") if s.strip())
        except ValueError:
            raise ConfigError(f"--seeds must be comma-separated integers, got {args.seeds!r}") from None
        if not seeds or args.k < 1:
            raise ConfigError("need at least one seed and --k >= 1")
        shapes = tuple(s.strip() for s in args.shapes.split(",") if s.strip())
        bad = [s for s in shapes if s not in curves.SHAPES]
        if bad:
            raise ConfigError(f"--shapes: unknown shape(s) {bad}; known: {', '.join(curves.SHAPES)}")
        state, meta, cfg, layout = checkpoint.load_run(args.workdir, args.step, args.params)
        step, _ = checkpoint.read_meta(checkpoint.manager(Path(args.workdir) / "checkpoints"), args.step)
        if args.data is not None:
            cfg = dataclasses.replace(cfg, data=dataclasses.replace(cfg.data, data_dir=args.data))
        ev_path = Path(args.evaluator) if args.evaluator else Path(args.workdir) / "evaluator.npz"
        ev = evaluator.load(ev_path)
        style_names = tuple(meta["style_names"])
        problems = []
        if tuple(ev.style_names) != style_names:
            problems.append(f"styles {list(ev.style_names)} vs the model's {list(style_names)}")
        if tuple(ev.meta.get("joint_names", ())) != tuple(layout.joint_names):
            problems.append("a different skeleton")
        if ev.meta.get("window_T") != cfg.data.window_T:
            problems.append(f"window T {ev.meta.get('window_T')} vs {cfg.data.window_T}")
        if problems:
            raise evaluator.EvaluatorError(f"{ev_path} does not match the run {args.workdir}: " + "; ".join(problems))
        dataset = data.load_dataset(cfg.data)
        if tuple(dataset.style_names) != style_names:
            raise data.DataError(f"the data's styles {list(dataset.style_names)} differ from the model's")
        if not dataset.val:
            raise data.DataError("the validation split is empty: no held-out data to evaluate on")
        settings = evaluation.Settings(seeds=seeds, k=args.k, max_heldout_curves=args.max_curves,
                                       search_steps=args.search_steps, search_clips=1 if args.search_steps > 0 else 0)
        rate = generate.sample_rate(meta, cfg)
        T = cfg.data.window_T
        L = settings.windows_per_curve * T
        speed = evaluation.median_speed(dataset.val, dataset.fps)
        eval_curves = evaluation.heldout_curves(dataset.val, cfg, L, settings.max_heldout_curves)
        if args.cmu_curves:
            files = sorted(Path(args.cmu_curves).glob("*.bvh"))
            if not files:
                raise ConfigError(f"--cmu-curves {args.cmu_curves}: no .bvh files")
            eval_curves += evaluation.file_curves(files[: settings.max_cmu_curves], rate, L, T,
                                                  cfg.data.control_point_interval / dataset.fps, log=print)
        eval_curves += evaluation.shape_curves(rate, speed, L, T, shapes)
        feet = representation.foot_joints(layout)
        contact = data.contact_height(dataset.train, layout, feet)
        print(f"contact height {contact * 100:.1f} cm (calibrated on the training clips)")
        long_curve = evaluation.long_line(rate, speed, settings.long_curve_m)
        probe = jax.jit(data.make_sample_batch(cfg.data, evaluation.PROBE_WINDOWS))(
            data.build_arrays(dataset.train, dataset.style_names, cfg.data), jax.random.key(0), 0)
        ctx = evaluation.Context(state, meta, cfg, layout, ev, style_names, dataset.val, rate, feet,
                                 eval_curves, settings, contact, long_curve, probe)
        results = evaluation.evaluate(ctx)
    except (ConfigError, data.DataError, BVHError, checkpoint.CheckpointError, evaluator.EvaluatorError,
            evaluation.EvaluationError, generate.GenerateError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    counts = {}
    for c in eval_curves:
        counts[c.kind] = counts.get(c.kind, 0) + 1
    header = {
        "workdir": str(args.workdir), "config_name": cfg.name, "config_hash": config_hash(cfg),
        "checkpoint_step": step,
        "g_params": (f"moving average (train.g_ema_decay {cfg.train.g_ema_decay})"
                     if args.params == "ema" and cfg.train.g_ema_decay > 0 else "raw"),
        "evaluator": str(ev_path), "evaluator_checksum": ev.checksum,
        "evaluator_real_heldout": ev.meta.get("real_heldout"), "style_names": list(style_names),
        "settings": dataclasses.asdict(settings), "curve_counts": counts,
        "curves": [{"name": c.name, "kind": c.kind, "samples": len(c.curve_Lx3), "source": c.source} for c in eval_curves],
        "train_files": sorted(Path(c.source).name for c in dataset.train),
        "val_files": sorted(Path(c.source).name for c in dataset.val),
        "data_dir": dataset.data_dir, "walking_speed_m_per_s": speed, "sample_rate_hz": rate,
        "feet": [layout.joint_names[i] for i in feet],
    }
    report = {"header": header, "results": results}
    from motiongan_jax import analysis, atomic, viz

    out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(out / "report.json", evaluation.dumps(report))
    atomic.write_text(out / "report.md", evaluation.markdown(evaluation.to_jsonable(report)))
    evaluation.plot_confusion(results["confusion_generated"], results["confusion_real"], style_names,
                              out / "confusion.png")
    codes = analysis.label_codes(state, style_names, k=10)
    X, y = codes.flat_samples
    p = analysis.pca(X, 2)
    viz.plot_style_pca(np.asarray(analysis.pca_transform(p, X)), np.asarray(y), style_names, out / "pca_w.png",
                       centroids_Cx2=np.asarray(analysis.pca_transform(p, codes.centroids_CxD)),
                       explained=np.asarray(p.explained_variance_ratio_K)[:2])
    print(f"wrote {out / 'report.md'}, report.json, confusion.png, pca_w.png")
    print(f"evaluator checksum {ev.checksum[:16]}…, {hashlib.sha256((out / 'report.json').read_bytes()).hexdigest()[:12]}")
    return 0
