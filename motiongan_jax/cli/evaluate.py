"""Evaluate a trained run with the project's protocol (docs/DESIGN.md §7).

  python bin/evaluate.py --workdir runs/small --out runs/small/eval
                         [--data DATA_DIR] [--evaluator runs/small/evaluator.npz]
                         [--speed-free-evaluator runs/small/evaluator_speed_free.npz]
                         [--cmu-curves DATA_DIR/cmu] [--seeds 0,1,2] [--k 3] [--step N]
  python bin/evaluate.py [--model FILE.npz] --evaluator EV.npz --out OUT   # an export (default: the shipped model)
  python bin/evaluate.py --workdir runs/small --out OUT --search-only [--search-clips N] [--data DATA_DIR]

Generates for every (unseen curve × style) with K noise draws and each seed; unseen curves are
the run's held-out real root paths (straight and turning), the root paths of the BVH files in
--cmu-curves (another lab: only their floor path is used), and the synthetic shapes. Scores
generated and real held-out data side by side with the evaluator (bin/train_evaluator.py).
Realism, like for like: every held-out path walked in its clip's style at its speed against the
clip (a classifier two-sample test per feature group, stride frequency, step height and skating
per style), the stride-speed relation, and style accuracy by the speed-free evaluator
(bin/train_evaluator.py --speed-free; WORKDIR/evaluator_speed_free.npz is used when it exists).
Writes OUT/report.json, OUT/report.md, OUT/confusion.png and OUT/pca_w.png.

--search-only: the style search alone, on every held-out clip (or --search-clips per style) and on
G's own walk of each clip's path in that clip's style (w known): the recovered style's nearest known
styles against the label, top-1 and top-3 over clips and per style, and the search's time
(evaluation/style_recovery.py). Needs no evaluator. Writes OUT/style_search.json and
OUT/style_search.md.
"""

import argparse
import sys
from pathlib import Path

from motiongan_jax.cli import add_model_arguments


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_arguments(ap)
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--data", default=None, help="the run's data directory (default: as trained)")
    ap.add_argument("--evaluator", default=None, help="evaluator .npz (default WORKDIR/evaluator.npz)")
    ap.add_argument("--speed-free-evaluator", default=None,
                    help="speed-free evaluator .npz (default WORKDIR/evaluator_speed_free.npz if it exists)")
    ap.add_argument("--cmu-curves", default=None, help="directory of BVH files whose root paths are used as curves")
    ap.add_argument("--seeds", default="0,1,2")
    ap.add_argument("--k", type=int, default=3, help="noise draws per (curve, style), >= 3 in the protocol")
    ap.add_argument("--search-steps", type=int, default=None,
                    help="style-search optimisation steps (0: skip the search; default the search's own)")
    ap.add_argument("--search-clips", type=int, default=None,
                    help="held-out clips searched per style (default 1, with --search-only every clip)")
    ap.add_argument("--search-only", action="store_true",
                    help="only the style search on the held-out clips and G's walks of their paths")
    ap.add_argument("--max-curves", type=int, default=12, help="held-out real curves at most")
    ap.add_argument("--realism-curves", type=int, default=48,
                    help="held-out paths walked like for like in the realism part, at most (0: skip it)")
    ap.add_argument("--stream-curves", type=int, default=6,
                    help="of those, paths also walked as a live stream, whole and streamed compared (0: skip)")
    ap.add_argument("--shapes", default=",".join(("line", "circle", "s_curve", "figure8", "corner")),
                    help="synthetic curve shapes (comma-separated)")
    args = ap.parse_args(argv)
    if (args.search_steps is not None and args.search_steps < 0) or (args.search_clips is not None
                                                                      and args.search_clips < 1):
        ap.error("--search-steps must be >= 0 and --search-clips >= 1")
    if args.search_only:
        if args.search_steps == 0:
            ap.error("--search-only with --search-steps 0 has nothing to do")
        return _search_only(args)

    from motiongan_jax.config import ConfigError
    from motiongan_jax.data import curves, file_labels
    from motiongan_jax.evaluation import evaluator, protocol, realism
    from motiongan_jax.evaluation import report as eval_report
    from motiongan_jax.generate import limits
    from motiongan_jax.model import checkpoint
    from motiongan_jax.motion.bvh import BVHError

    try:
        try:
            seeds = tuple(int(s) for s in args.seeds.split(",") if s.strip())
        except ValueError:
            raise ConfigError(f"--seeds must be comma-separated integers, got {args.seeds!r}") from None
        if not seeds or args.k < 2:
            raise ConfigError("need at least one seed and --k >= 2 (multimodality compares the draws of a curve "
                              "and style)")
        shapes = tuple(s.strip() for s in args.shapes.split(",") if s.strip())
        bad = [s for s in shapes if s not in curves.SHAPES]
        if bad:
            raise ConfigError(f"--shapes: unknown shape(s) {bad}; known: {', '.join(curves.SHAPES)}")
        search = {} if args.search_steps is None else {"search_steps": args.search_steps}
        if args.search_steps == 0:
            search["search_clips"] = 0
        elif args.search_clips is not None:
            search["search_clips"] = args.search_clips
        settings = protocol.Settings(seeds=seeds, k=args.k, max_heldout_curves=args.max_curves,
                                     realism_max_curves=args.realism_curves,
                                     stream_curves=max(0, args.stream_curves), **search)
        report, ctx = protocol.evaluate_run(args.workdir, settings, shapes, step=args.step, params=args.params,
                                              data_dir=args.data, evaluator_path=args.evaluator,
                                              cmu_curves=args.cmu_curves,
                                              speed_free_evaluator_path=args.speed_free_evaluator, model=args.model)
    except (ConfigError, file_labels.DataError, BVHError, checkpoint.CheckpointError, evaluator.EvaluatorError,
            protocol.EvaluationError, limits.GenerateError, realism.RealismError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2

    out = Path(args.out)
    digest = eval_report.write_report(out, report, ctx)
    print(f"wrote {out / 'report.md'}, report.json, confusion.png, pca_w.png")
    print(f"evaluator checksum {ctx.ev.checksum[:16]}…, {digest[:12]}")
    return 0


def _search_only(args) -> int:
    import json

    from motiongan_jax import atomic
    from motiongan_jax.config import ConfigError
    from motiongan_jax.data import file_labels
    from motiongan_jax.evaluation import protocol, style_recovery
    from motiongan_jax.model import checkpoint
    from motiongan_jax.motion.bvh import BVHError

    settings = style_recovery.Settings(clips_per_style=args.search_clips,
                                       **({} if args.search_steps is None else {"steps": args.search_steps}))
    try:
        result, header = protocol.search_run(args.workdir, settings, step=args.step, params=args.params,
                                             data_dir=args.data, model=args.model)
    except (ConfigError, file_labels.DataError, BVHError, checkpoint.CheckpointError, protocol.EvaluationError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        atomic.write_json(out / "style_search.json", {"header": header, "results": result})
        title = f"Style search: {header['workdir']} (step {header['checkpoint_step']}), held-out split"
        atomic.write_text(out / "style_search.md", style_recovery.markdown(result, f"# {title}"))
    except OSError as err:
        print(f"error: cannot write {out}: {err.strerror or err}", file=sys.stderr)
        return 2
    real, own = result["real"], result["own"]
    print(json.dumps({"real_top1": real.get("top1"), "real_top3": real.get("top3"),
                      "weakest": [real.get("weakest_style"), real.get("weakest_top1")],
                      "own_top1": own.get("top1"), "seconds_median": result["seconds"]["median"]}))
    print(f"wrote {out / 'style_search.md'}, style_search.json")
    return 0
