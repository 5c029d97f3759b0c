"""A model's style space as files: pca.png, heatmap.png, nearest.md and analysis.json, and with a
style search search.json and search.npz (bin/analyze.py describes each).

The numerics are analysis.py's and the figures viz.py's; this module loads the model, puts their
results together as one report and writes it (every file atomically), so that the tool only
parses its arguments and prints a summary.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from pathlib import Path

import jax
import numpy as np

from motiongan_jax import atomic, viz
from motiongan_jax.analysis import clips, style_space
from motiongan_jax.analysis import probe as probe_lib
from motiongan_jax.analysis import search as search_lib
from motiongan_jax.data import curves
from motiongan_jax.model import pretrained


@dataclasses.dataclass(frozen=True)
class Search:
    """A style search: the clip (.bvh, or .npz of world positions), the curve the recovered style
    then walks (a shape or a .csv/.json curve file), and the search's settings."""

    clip: str
    curve: str
    steps: int = search_lib.STEPS
    keep: int = search_lib.KEEP  # the best screened styles each start a search


def _check_writable(out: Path) -> None:
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(dir=out, prefix=".analyze-probe-")
        os.close(fd)
        os.unlink(probe)
    except OSError as err:
        raise PermissionError(f"cannot write into {out}: {err.strerror or err}") from None


def _search_curve(text: str, spacing: float, T: int):
    if text in curves.SHAPES:
        pts = curves.shape_curve(text, num_points=400)
        total = float(sum(((pts[1:] - pts[:-1]) ** 2).sum(1) ** 0.5))
        if total < spacing * 2 * T:  # at least two windows' worth of walking
            pts = curves.shape_curve(text, length=spacing * 2 * T, num_points=400)
        return pts
    path = Path(text)
    if path.suffix.lower() in (".csv", ".txt", ".json"):
        return curves.load_curve_file(path)
    raise style_space.AnalysisError(f"--search-curve: {text!r} is neither a shape ({', '.join(curves.SHAPES)}) nor a "
                          ".csv/.json curve file")



def write_analysis(out, *, workdir=None, model=None, step: int | None = None, params: str = "ema", k: int = 10,
                   seed: int = 0, search: Search | None = None, log=print) -> dict:
    """Analyses the run `workdir` (its checkpoint `step`, G's `params`), else the export `model`,
    else the shipped model, with `k` codes per style; writes the files into `out` (created) and
    returns the report of analysis.json. Raises CheckpointError, AnalysisError, BVHError,
    CurveFileError, DegenerateCurveError, or PermissionError when `out` cannot be written."""
    out = Path(out)
    state, meta, cfg, layout = pretrained.load_model(workdir, step, params, model)
    _check_writable(out)
    names = list(meta["style_names"])
    C = len(names)
    key = jax.random.key(seed)
    k_codes = jax.random.split(key)[0]  # (the second half of the split once seeded a search's random starts)
    codes = style_space.label_codes(state, names, k, k_codes)
    X, labels = codes.flat_samples
    p = style_space.pca(X)
    pts = style_space.pca_transform(p, X)

    def two(a):  # the first two PCs, zero-padded when w has fewer
        a = np.asarray(a)
        return a[:, :2] if a.shape[1] >= 2 else np.pad(a, ((0, 0), (0, 2 - a.shape[1])))

    evr = np.asarray(p.explained_variance_ratio_K)
    dist = np.asarray(style_space.pairwise_distances(codes.centroids_CxD))
    nearest = style_space.nearest_styles(dist, names, k=min(3, C - 1))

    report = {
        "workdir": None if workdir is None else str(workdir),
        "model": None if workdir is not None else str(model or pretrained.SHIPPED_MODEL.name),
        "step": int(state.step), "style_names": names, "k": k,
        "seed": seed, "w_dim": int(X.shape[1]),
        "pca": {"fit_on": f"{C} x {k} codes w = LT(label, z), z ~ N(0, I)",
                "explained_variance_ratio": evr, "explained_variance": np.asarray(p.explained_variance_K)},
        "distance": {"metric": "Euclidean between centroids (mean of the K codes)", "matrix": dist,
                     "mean_offdiagonal": float(dist[~np.eye(C, dtype=bool)].mean()) if C > 1 else 0.0,
                     "mean_within_style_spread": float(np.mean(np.linalg.norm(
                         np.asarray(codes.samples_CxKxD - codes.centroids_CxD[:, None]), axis=-1)))},
        "nearest": nearest,
        "centroids": np.asarray(codes.centroids_CxD), "w_zero": np.asarray(codes.zero_CxD),
    }
    gait = probe_lib.gait_parameters(meta, cfg)
    if gait is not None and C >= 3:
        report["probe"] = {"targets": "gait parameters of the embedded dataset (styles.json)",
                           "method": "least squares with an intercept on the training fold's leading "
                                     "principal components; R² of out-of-fold predictions",
                           **probe_lib.probe_report(codes, gait)}
    else:
        report["probe"] = None

    marks = {}
    if search is not None:
        log(f"style search: {search.clip}")
        root, pose, fps = clips.load_motion(search.clip, meta, cfg, layout)
        target = clips.model_rate_windows(root, pose, fps, meta, cfg, layout, spread=search_lib.WINDOWS, phase=True,
                                          source=str(search.clip))
        found = search_lib.search_style(state, codes.zero_CxD, names, target, keep=search.keep, steps=search.steps)
        marks[f"search: {Path(search.clip).stem}"] = tuple(two(style_space.pca_transform(p, found.w_D[None]))[0])
        rv, pose = search_lib.reconstruct(state, target, found.w_D)
        spacing = target.spacing_m
        height = float(np.mean(np.asarray(target.root_NxTx3[:, :, 1])))
        curve_pts = _search_curve(search.curve, spacing, cfg.data.window_T)
        walk = search_lib.generate_along(state, layout, found.w_D, curve_pts, spacing_m=spacing, start_height_m=height)
        sample_rate = float(meta["fps"]) / cfg.data.frame_step
        stem = Path(search.clip).stem
        true_style = stem.split("_", 1)[0] if stem.split("_", 1)[0] in names else None
        found_report = {
            "source": str(search.clip), "windows": int(target.root_NxTx3.shape[0]),
            "window_T": int(target.root_NxTx3.shape[1]), "frame_step": target.frame_step,
            "start_frames": target.start_frames, "speed_m_per_sample": spacing,
            "loss": found.loss_kind, "steps": search.steps, "keep": search.keep,
            "screen_loss": {n: float(v) for n, v in zip(names, found.screen_C)},
            "starts": [{"start": n, "final_loss": float(b)} for n, b in zip(found.starts, found.final_loss_K)],
            "final_loss": found.loss, "style": found.mix_text(), "mix": found.mix(), "w": found.w_D,
            "nearest": found.nearest[:3], "file_name_style": true_style, "seconds": found.seconds,
            "loss_history_best": found.history_KxS[int(np.argmin(found.final_loss_K))],
            "walk": {"curve": search.curve, "samples": int(walk["root_Tx3"].shape[0]),
                     "start_height_m": height},
        }
        if true_style is not None:
            found_report["file_name_style_rank"] = [n for n, _ in found.nearest].index(true_style) + 1
        atomic.write_json(out / "search.json", found_report)
        with atomic.atomic_path(out / "search.npz") as tmp, open(tmp, "wb") as fh:
            np.savez(fh, w=found.w_D, mix_weights=found.weights_C, positions=walk["positions_TxJx3"],
                     root=walk["root_Tx3"], pose=walk["pose_TxR"], curve=walk["curve_Tx3"],
                     joint_names=np.array(layout.joint_names), parents=np.array(layout.parents, np.int32),
                     fps=np.float64(sample_rate), target_root=np.asarray(target.root_NxTx3),
                     target_pose=np.asarray(target.pose_NxTxR), target_curve=np.asarray(target.curve_NxTx3),
                     recon_root_vel=np.asarray(rv), recon_pose=np.asarray(pose))
        report["search"] = {"file": "search.json", "style": found.mix_text(), "final_loss": found.loss,
                            "nearest": found.nearest[:3]}

    viz.plot_style_pca(two(pts), np.asarray(labels), names, out / "pca.png",
                       centroids_Cx2=two(style_space.pca_transform(p, codes.centroids_CxD)),
                       zero_Cx2=two(style_space.pca_transform(p, codes.zero_CxD)), explained=evr[:2], marks=marks,
                       title=f"Style codes w, {C} styles x {k} (step {int(state.step)})")
    viz.plot_distance_heatmap(dist, names, out / "heatmap.png")
    atomic.write_text(out / "nearest.md", style_space.nearest_markdown(nearest))
    atomic.write_json(out / "analysis.json", report)
    return report
