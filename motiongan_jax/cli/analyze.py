"""Analyse a trained model's style space, and optionally search the style of a motion.

  python bin/analyze.py [--workdir DIR | --model FILE.npz] --out OUTDIR [--k 10] [--seed 0] [--step N]
                        [--search CLIP.bvh|CLIP.npz [--search-curve SHAPE|CURVE.csv|.json]
                         [--search-steps N] [--search-keep K]]

Writes into OUTDIR:
  pca.png       2-D PCA of the style codes w (K per style from z ~ N(0, I); crosses: z = 0),
                coloured by style, names at the centroids (the paper's Fig. 5)
  heatmap.png   Euclidean distances between the style centroids (mean of the K codes)
  nearest.md    each style's three nearest styles by centroid distance (the paper's Table 1)
  analysis.json explained variance ratios, centroids, z = 0 codes, the distance matrix, the
                nearest styles, and, for a model of the embedded dataset, the cross-validated R²
                of linear probes from w to the known gait parameters
With --search (a BVH clip, or an .npz of world positions in metres with the model's joints):
  search.json   the clip's style as a mix of the known styles (analysis/search.py: each style's
                loss as it is, the searches from the best, the mix found, its loss, its nearest
                styles); the clip's windows, frame step and speed
  search.npz    the recovered w, and a walk with it along --search-curve (default s_curve) at the
                clip's speed: positions (T, J, 3) metres, root, pose rows, curve, joint_names,
                parents, fps; plus the model's reconstruction of the clip's windows
Without --workdir or --model: the model shipped with the package.
Exit status: 0 done, 2 bad input (no checkpoint, unreadable clip, unwritable OUTDIR).
"""

import argparse
import sys

from motiongan_jax.cli import add_model_arguments


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    add_model_arguments(ap)
    ap.add_argument("--out", required=True, help="output directory (created)")
    ap.add_argument("--k", type=int, default=10, help="codes per style from z ~ N(0, I)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--search", default=None, metavar="CLIP", help="a .bvh clip or an .npz of world positions")
    ap.add_argument("--search-curve", default="s_curve",
                    help="walk the recovered style along this shape or .csv/.json curve file")
    ap.add_argument("--search-steps", type=int, default=None, help="Adam steps of each search (default: the search's)")
    ap.add_argument("--search-keep", type=int, default=None,
                    help="the best screened styles each start a search (default: the search's)")
    args = ap.parse_args(argv)
    if args.k < 2:
        ap.error("--k must be >= 2")
    if (args.search_steps is not None and args.search_steps < 1) or (args.search_keep is not None
                                                                     and args.search_keep < 1):
        ap.error("--search-steps and --search-keep must be >= 1")

    from motiongan_jax.analysis.report import Search, write_analysis
    from motiongan_jax.analysis.style_space import AnalysisError
    from motiongan_jax.data.curves import CurveFileError, DegenerateCurveError
    from motiongan_jax.model.checkpoint import CheckpointError
    from motiongan_jax.motion.bvh import BVHError

    given = {k: v for k, v in (("steps", args.search_steps), ("keep", args.search_keep)) if v is not None}
    search = None if not args.search else Search(args.search, args.search_curve, **given)
    try:
        report = write_analysis(args.out, workdir=args.workdir, model=args.model, step=args.step,
                                params=args.params, k=args.k, seed=args.seed, search=search)
    except (CheckpointError, AnalysisError, BVHError, CurveFileError, DegenerateCurveError,
            PermissionError) as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    evr = report["pca"]["explained_variance_ratio"]
    print(f"explained variance ratio (PC1..3): {', '.join(f'{v:.3f}' for v in evr[:3])}")
    if report["probe"]:
        ps, pw = report["probe"]["per_style"], report["probe"]["per_sample"]
        print(f"probe mean R² (leave-one-style-out): per style {ps['mean_r2_cv']:.3f}, "
              f"per sample {pw['mean_r2_cv']:.3f}")
    if "search" in report:
        s = report["search"]
        print(f"search: style {s['style']}, loss {s['final_loss']:.4g}, nearest "
              + ", ".join(f"{n} ({d:.3g})" for n, d in s["nearest"]))
    print(f"wrote {args.out}")
    return 0
