"""Analyse a trained model's style space, and optionally search the style of a motion.

  python bin/analyze.py [--workdir DIR | --model FILE.npz] --out OUTDIR [--k 10] [--seed 0] [--step N]
                        [--search CLIP.bvh|CLIP.npz [--search-curve SHAPE|CURVE.csv|.json]
                         [--search-steps 200] [--search-keep 4] [--search-random 4]
                         [--search-windows 4] [--search-T T] [--search-lr 0.1]]

Writes into OUTDIR:
  pca.png       2-D PCA of the style codes w (K per style from z ~ N(0, I); crosses: z = 0),
                coloured by style, names at the centroids (the paper's Fig. 5)
  heatmap.png   Euclidean distances between the style centroids (mean of the K codes)
  nearest.md    each style's three nearest styles by centroid distance (the paper's Table 1)
  analysis.json explained variance ratios, centroids, z = 0 codes, the distance matrix, the
                nearest styles, and, for a model of the embedded dataset, the cross-validated R²
                of linear probes from w to the known gait parameters
With --search (a BVH clip, or an .npz of world positions in metres with the model's joints):
  search.json   per start: loss as is / after the search; the best code, its loss, its nearest
                styles; the clip's windows, frame step and speed
  search.npz    the recovered w, and a walk with it along --search-curve (default s_curve) at the
                clip's speed: positions (T, J, 3) metres, root, pose rows, curve, joint_names,
                parents, fps; plus the model's reconstruction of the clip's windows
Without --workdir or --model: the model shipped with the package.
Exit status: 0 done, 2 bad input (no checkpoint, unreadable clip, unwritable OUTDIR).
"""

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path


def _check_writable(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=out, prefix=".analyze-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        raise PermissionError(f"cannot write into {out}: {err.strerror or err}") from None


def _search_curve(text: str, spacing: float, T: int):
    from motiongan_jax import curves

    if text in curves.SHAPES:
        pts = curves.shape_curve(text, num_points=400)
        total = float(sum(((pts[1:] - pts[:-1]) ** 2).sum(1) ** 0.5))
        if total < spacing * 2 * T:  # at least two windows' worth of walking
            pts = curves.shape_curve(text, length=spacing * 2 * T, num_points=400)
        return pts
    path = Path(text)
    if path.suffix.lower() in (".csv", ".txt", ".json"):
        return curves.load_curve_file(path)
    from motiongan_jax.analysis import AnalysisError

    raise AnalysisError(f"--search-curve: {text!r} is neither a shape ({', '.join(curves.SHAPES)}) nor a "
                     ".csv/.json curve file")


def _write_json(path: Path, obj) -> None:
    from motiongan_jax import atomic, evaluation

    atomic.write_text(path, json.dumps(evaluation.to_jsonable(obj), indent=1, allow_nan=False) + "\n")


def run(args, log=print) -> dict:
    import jax
    import numpy as np

    from motiongan_jax import analysis as A
    from motiongan_jax import atomic, pretrained, viz
    from motiongan_jax.representation import LENGTH_UNIT_M

    out = Path(args.out)
    state, meta, cfg, layout = pretrained.load_model(args.workdir, args.step, args.params, args.model)
    _check_writable(out)
    names = list(meta["style_names"])
    C = len(names)
    key = jax.random.key(args.seed)
    k_codes, k_search = jax.random.split(key)
    codes = A.label_codes(state, names, args.k, k_codes)
    X, labels = codes.flat_samples
    p = A.pca(X)
    pts = A.pca_transform(p, X)
    two = (lambda a: np.asarray(a)[:, :2] if np.asarray(a).shape[1] >= 2 else
           np.pad(np.asarray(a), ((0, 0), (0, 2 - np.asarray(a).shape[1]))))
    evr = np.asarray(p.explained_variance_ratio_K)
    dist = np.asarray(A.pairwise_distances(codes.centroids_CxD))
    nearest = A.nearest_styles(dist, names, k=min(3, C - 1))

    report = {
        "workdir": None if args.workdir is None else str(args.workdir),
        "model": None if args.workdir is not None else str(args.model or pretrained.SHIPPED_MODEL.name),
        "step": int(state.step), "style_names": names, "k": args.k,
        "seed": args.seed, "w_dim": int(X.shape[1]),
        "pca": {"fit_on": f"{C} x {args.k} codes w = LT(label, z), z ~ N(0, I)",
                "explained_variance_ratio": evr, "explained_variance": np.asarray(p.explained_variance_K)},
        "distance": {"metric": "Euclidean between centroids (mean of the K codes)", "matrix": dist,
                     "mean_offdiagonal": float(dist[~np.eye(C, dtype=bool)].mean()) if C > 1 else 0.0,
                     "mean_within_style_spread": float(np.mean(np.linalg.norm(
                         np.asarray(codes.samples_CxKxD - codes.centroids_CxD[:, None]), axis=-1)))},
        "nearest": nearest,
        "centroids": np.asarray(codes.centroids_CxD), "w_zero": np.asarray(codes.zero_CxD),
    }
    gait = A.gait_parameters(meta, cfg)
    if gait is not None and C >= 3:
        report["probe"] = {"targets": "gait parameters of the embedded dataset (styles.json)",
                           "method": "least squares with an intercept on the training fold's leading "
                                     "principal components; R² of out-of-fold predictions",
                           **A.probe_report(codes, gait)}
    else:
        report["probe"] = None

    marks = {}
    if args.search:
        log(f"style search: {args.search}")
        target = A.motion_windows(args.search, meta, cfg, layout, max_windows=args.search_windows,
                                  T=args.search_T)
        found = A.search_motion(state, codes, target, num_random=args.search_random, keep=args.search_keep,
                                steps=args.search_steps, lr=args.search_lr, key=k_search)
        res = found["result"]
        marks[f"search: {Path(args.search).stem}"] = tuple(two(A.pca_transform(p, res.w_D[None]))[0])
        rv, pose = A.reconstruct(state, target, res.w_D)
        spacing = target.spacing_m
        height = float(np.mean(np.asarray(target.root_NxTx3[:, :, 1])))
        curve_pts = _search_curve(args.search_curve, spacing, cfg.data.window_T)
        walk = A.generate_along(state, layout, res.w_D, curve_pts, spacing_m=spacing, start_height_m=height)
        sample_rate = float(meta["fps"]) / cfg.data.frame_step
        stem = Path(args.search).stem
        true_style = stem.split("_", 1)[0] if stem.split("_", 1)[0] in names else None
        search = {
            "source": str(args.search), "windows": int(target.root_NxTx3.shape[0]),
            "window_T": int(target.root_NxTx3.shape[1]), "frame_step": target.frame_step,
            "start_frames": target.start_frames, "speed_m_per_sample": spacing,
            "loss": f"0.01 MSE(root velocity) + MSE(pose rows), lengths in CMU units ({LENGTH_UNIT_M} m)",
            "steps": args.search_steps, "lr": args.search_lr,
            "screen_loss": found["screen"],
            "starts": [{"start": n, "initial_loss": float(a), "final_loss": float(b)}
                       for n, a, b in zip(res.start_names, res.initial_loss_S, res.final_loss_S)],
            "best_start": res.start_names[res.best_start], "final_loss": res.loss, "w": res.w_D,
            "nearest": found["nearest"], "nearest_in_spread_units": found["nearest_scaled"],
            "file_name_style": true_style,
            "loss_history_best": res.history_HxS[:, res.best_start], "history_every": res.record_every,
            "walk": {"curve": args.search_curve, "samples": int(walk["root_Tx3"].shape[0]),
                     "start_height_m": height},
        }
        if true_style is not None:
            order = [n for n, _ in A.nearest_to(res.w_D, codes, k=C)]
            search["file_name_style_rank"] = order.index(true_style) + 1
        _write_json(out / "search.json", search)
        with atomic.atomic_path(out / "search.npz") as tmp, open(tmp, "wb") as fh:
            np.savez(fh, w=res.w_D, positions=walk["positions_TxJx3"], root=walk["root_Tx3"],
                     pose=walk["pose_TxR"], curve=walk["curve_Tx3"], joint_names=np.array(layout.joint_names),
                     parents=np.array(layout.parents, np.int32), fps=np.float64(sample_rate),
                     target_root=np.asarray(target.root_NxTx3), target_pose=np.asarray(target.pose_NxTxR),
                     target_curve=np.asarray(target.curve_NxTx3), recon_root_vel=np.asarray(rv),
                     recon_pose=np.asarray(pose))
        report["search"] = {"file": "search.json", "best_start": search["best_start"],
                            "final_loss": res.loss, "nearest": found["nearest"]}

    viz.plot_style_pca(two(pts), np.asarray(labels), names, out / "pca.png",
                       centroids_Cx2=two(A.pca_transform(p, codes.centroids_CxD)),
                       zero_Cx2=two(A.pca_transform(p, codes.zero_CxD)), explained=evr[:2], marks=marks,
                       title=f"Style codes w, {C} styles x {args.k} (step {int(state.step)})")
    viz.plot_distance_heatmap(dist, names, out / "heatmap.png")
    atomic.write_text(out / "nearest.md", A.nearest_markdown(nearest))
    _write_json(out / "analysis.json", report)
    return report


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    src = ap.add_mutually_exclusive_group()
    src.add_argument("--workdir", default=None,
                     help="a training run's directory (with checkpoints/); default: the shipped model")
    src.add_argument("--model", default=None, help="an export file (bin/export_model.py) instead of a run")
    ap.add_argument("--out", required=True, help="output directory (created)")
    ap.add_argument("--step", type=int, default=None, help="checkpoint step (default: the latest)")
    ap.add_argument("--params", choices=("ema", "raw"), default="ema",
                    help="G's parameters: ema (default; the moving average when the run keeps one) or raw")
    ap.add_argument("--k", type=int, default=10, help="codes per style from z ~ N(0, I)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--search", default=None, metavar="CLIP", help="a .bvh clip or an .npz of world positions")
    ap.add_argument("--search-curve", default="s_curve",
                    help="walk the recovered style along this shape or .csv/.json curve file")
    ap.add_argument("--search-steps", type=int, default=200)
    ap.add_argument("--search-lr", type=float, default=0.1, help="peak Adam rate, in units of the codes' spread")
    ap.add_argument("--search-keep", type=int, default=4, help="starts optimised (the best as they are)")
    ap.add_argument("--search-random", type=int, default=4, help="random starts besides the centroids")
    ap.add_argument("--search-windows", type=int, default=4, help="at most this many windows of the clip")
    ap.add_argument("--search-T", type=int, default=None,
                    help="samples per window (a multiple of 8; default the model's T). Longer windows "
                         "give G's instance norms more samples and a smoother loss over w")
    args = ap.parse_args(argv)
    if args.k < 2:
        ap.error("--k must be >= 2")
    if args.search_steps < 1 or args.search_keep < 1 or args.search_windows < 1 or args.search_random < 0:
        ap.error("--search-steps, --search-keep and --search-windows must be >= 1, --search-random >= 0")

    from motiongan_jax.analysis import AnalysisError
    from motiongan_jax.bvh import BVHError
    from motiongan_jax.checkpoint import CheckpointError
    from motiongan_jax.curves import CurveFileError, DegenerateCurveError

    try:
        report = run(args)
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
        print(f"search: best start {s['best_start']}, loss {s['final_loss']:.4g}, nearest "
              + ", ".join(f"{n} ({d:.3g})" for n, d in s["nearest"]))
    print(f"wrote {args.out}")
    return 0
