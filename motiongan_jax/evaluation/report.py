"""The evaluation report: its rows, markdown, JSON and the confusion plots, and its files.
"""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np

from motiongan_jax import atomic
from motiongan_jax.analysis import style_space
from motiongan_jax.evaluation import clip_metrics
from motiongan_jax.evaluation.protocol import Context
from motiongan_jax.evaluation.realism import FOLDS
from motiongan_jax.generate import stream

ROWS = [
    ("sra_top1", "style accuracy top-1 (evaluator)"),
    ("sra_top3", "style accuracy top-3"),
    ("fmd", "Fréchet motion distance (real: two halves of the held-out windows)"),
    ("diversity", "diversity (feature distance)"),
    ("multimodality", "multimodality (across z)"),
    ("traj_error_original_m", "trajectory error, original (m)"),
    ("traj_error_symmetric_m", "trajectory error, symmetric arc length (m)"),
    ("endpoint_error_m", "end-point error (m)"),
    ("path_length_ratio", "path length ratio"),
    ("foot_skate_original_m", "foot skate, original (m per sample)"),
    ("skate_ratio", "skating ratio (contacts faster than 0.5 m/s)"),
    ("bone_length_error", "bone-length error (relative)"),
    ("facing_error_deg", "facing vs travel direction (degrees)"),
    ("ground_penetration", f"frames with a toe > {clip_metrics.PENETRATION_TOLERANCE_M * 100:.0f} cm below the floor"),
    ("jerk_ratio", "jerk ratio (generated / real)"),
    ("support", "support: frames with a toe within the contact height of the floor"),
    ("lower_foot_height_m", "lower toe's mean height above the floor (m)"),
    ("alternation", "alternation: −corr(left, right toe height)"),
    ("step_frequency_hz", "step frequency (gait cycles/s; L−R toe height)"),
    ("step_amplitude_m", "step amplitude (std of L−R toe height, m)"),
    ("root_height_range_m", "root height range per clip (m)"),
    ("long_support", "long curve: support"),
    ("long_lower_foot_height_m", "long curve: lower toe's mean height (m)"),
    ("long_alternation", "long curve: alternation"),
    ("long_root_height_range_m", "long curve: root height range (m; real: the largest of a clip)"),
    ("nearest_centroid_accuracy", "w nearest-centroid accuracy"),
    ("pca_explained_1", "w PCA: variance explained by 1 component"),
    ("pca_explained_2", "w PCA: variance explained by 2 components"),
    ("interp_monotonicity", "interpolation monotonicity (Spearman)"),
    ("arithmetic_agreement", "arithmetic A-B+C classified as A or C"),
    ("sra_top1_own_speed", "realism: style top-1, held-out paths in their own style and speed (evaluator)"),
    ("sra_top1_speed_free_own_speed", "realism: the same, by the speed-free evaluator"),
    ("sra_top1_default_speed", "realism: style top-1, every style on the held-out paths at 1.2 m/s (evaluator)"),
    ("sra_top1_speed_free_default_speed", "realism: the same, by the speed-free evaluator"),
    ("two_sample_gait", "realism: two-sample accuracy, gait features (0.5 = indistinguishable; real: two halves)"),
    ("two_sample_posture", "realism: two-sample accuracy, posture features"),
    ("two_sample_speed", "realism: two-sample accuracy, speed features"),
    ("two_sample_all", "realism: two-sample accuracy, all named features"),
    ("two_sample_evaluator", "realism: two-sample accuracy, the evaluator's features"),
    ("stride_speed_slope", "realism: step frequency vs speed, slope (Hz per m/s; mean of styles)"),
]


def _fmt(x, digits=3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    return f"{x:.{digits}g}" if abs(x) >= 1e-3 or x == 0 else f"{x:.2e}"


def markdown(report: dict) -> str:
    h = report["header"]
    r = report["results"]
    lines = [f"# Evaluation: {h['config_name']} (step {h['checkpoint_step']})", "",
             f"- workdir: `{h['workdir']}`", f"- config hash: `{h['config_hash']}`",
             f"- checkpoint step: {h['checkpoint_step']}, G's parameters: {h.get('g_params', 'raw')}",
             f"- evaluator: `{h['evaluator']}`, checksum `{h['evaluator_checksum']}`",
             f"- evaluator accuracy on real held-out windows: "
             f"{_fmt((h.get('evaluator_real_heldout') or {}).get('top1'))} "
             f"(chance {_fmt(1.0 / len(h['style_names']))})",
             f"- seeds {h['settings']['seeds']}, K = {h['settings']['k']} noise draws per (curve, style), "
             f"{r['num_generated_clips_per_seed']} generated clips per seed, "
             f"{r['num_real_windows']} real held-out windows",
             "- curves: " + ", ".join(f"{k} {v}" for k, v in h["curve_counts"].items()),
             f"- files: training {len(h['train_files'])}, held-out {len(h['val_files'])} (lists in report.json)", "",
             "## Metrics (generated: mean ± 95% CI over seeds; real held-out data)", "",
             "| metric | generated | real |", "|---|---|---|"]
    for key, label in ROWS:
        g = r["generated"].get(key)
        real = r["real"].get(key)
        gs = "—" if g is None else f"{_fmt(g['mean'])} ± {_fmt(g['ci95'])}"
        lines.append(f"| {label} | {gs} | {_fmt(real)} |")
    kinds = sorted(k[len("traj_error_original_m["):-1] for k in r["generated"]
                   if k.startswith("traj_error_original_m["))
    if kinds:
        lines += ["", "Trajectory error by curve kind (m, generated):", "",
                  "| curve kind | original | symmetric |", "|---|---|---|"]
        for kind in kinds:
            a, b = r["generated"][f"traj_error_original_m[{kind}]"], r["generated"][f"traj_error_symmetric_m[{kind}]"]
            lines.append(f"| {kind} | {_fmt(a['mean'])} ± {_fmt(a['ci95'])} | {_fmt(b['mean'])} ± {_fmt(b['ci95'])} |")
    if r.get("search"):
        s = r["search"]
        lines += ["", f"Style search: the recovered style's nearest known style is the clip's own for "
                      f"{_fmt(s['search_recovery'])} of {s['search_clips']} held-out clips (top-3 "
                      f"{_fmt(s['search_recovery_top3'])}; G's walks of their paths, w known: "
                      f"{_fmt(s['search_recovery_own_walks'])}; median search {_fmt(s['search_seconds_median'])} s)."]
    lines += ["", "## Per style", "",
              "| style | SRA gen | SRA real | FMD gen | traj. orig. (m) | skate gen | skate real | bone err gen |",
              "|---|---|---|---|---|---|---|---|"]
    for name, v in r["per_style"].items():
        g, re_ = v["generated"], v["real"]
        lines.append(f"| {name} | {_fmt(g['sra_top1']['mean'])} | {_fmt(re_['sra_top1'])} | {_fmt(g['fmd']['mean'])} | "
                     f"{_fmt(g['traj_error_original_m']['mean'])} | {_fmt(g['foot_skate_original_m']['mean'])} | "
                     f"{_fmt(re_['foot_skate_original_m'])} | {_fmt(g['bone_length_error']['mean'])} |")
    lines += ["", f"Gait per style (contact height {_fmt(r['contact_height_m'])} m, calibrated on the real training "
                  "clips; step frequency in gait cycles/s, on the paths of held-out clips of the same style against "
                  "those clips):", "",
              "| style | support gen | support real | lower toe gen (m) | lower toe real (m) | alternation gen | "
              "alternation real | step freq. gen | step freq. real | ratio |",
              "|---|---|---|---|---|---|---|---|---|---|"]
    for name, v in r["per_style"].items():
        g, re_ = v["generated"], v["real"]
        lines.append(f"| {name} | {_fmt(g['support']['mean'])} | {_fmt(re_['support'])} | "
                     f"{_fmt(g['lower_foot_height_m']['mean'])} | {_fmt(re_['lower_foot_height_m'])} | "
                     f"{_fmt(g['alternation']['mean'])} | {_fmt(re_['alternation'])} | "
                     f"{_fmt(g['step_frequency_same_curve_hz']['mean'])} | "
                     f"{_fmt(re_['step_frequency_same_curve_hz'])} | "
                     f"{_fmt(g['step_frequency_ratio']['mean'])} |")
    lines += realism_markdown(r, h)
    lines += streaming_markdown(r)
    if r.get("discriminator_probe"):
        lines += ["", "The trained D's verdict (mean P(real), share judged real) on real training windows and "
                      "on the same windows altered:", "", "| D's input | P(real) | judged real |", "|---|---|---|"]
        for name, v in r["discriminator_probe"].items():
            lines.append(f"| {name} | {_fmt(v['p_real'])} | {_fmt(v['judged_real'])} |")
    lines += ["", "Plots: `confusion.png` (generated and real), `pca_w.png`.", ""]
    return "\n".join(lines)


STREAM_ROWS = [("support", "support"), ("lower_foot_height_m", "lower toe (m)"), ("skate_ratio", "skating ratio"),
               ("alternation", "alternation"), ("step_frequency_hz", "step frequency (Hz)"),
               ("step_amplitude_m", "step amplitude (m)"), ("jerk_mps3", "jerk (m/s³)"),
               ("sra_top1", "style top-1 (evaluator)"),
               ("seam_toe_speed_ratio", "seams: planted-toe speed, seam / rest"),
               ("seam_jerk_ratio", "seams: joint jerk, seam / rest"),
               ("seam_phase_ratio", "seams: phase-step deviation, seam / rest")]


def streaming_markdown(r: dict) -> list[str]:
    """The streaming part (streaming.py): whole-path against streamed walks of the same paths,
    styles, codes and phases, per seed."""
    seeds = r.get("streaming") or []
    if not seeds:
        return []
    lines = ["", f"## Streaming: {seeds[0]['curves']} held-out paths walked whole and as a live stream "
                 f"(the path known {stream.LOOKAHEAD} samples ahead, {stream.MAX_STEP} samples per advance); "
                 "seams at the advances' boundaries "
                 "(1 = not seen; the whole walk cut at the same samples is the control)", "",
             "| measure | " + " | ".join(f"whole s{b['seed']} | stream s{b['seed']}" for b in seeds) + " |",
             "|---|" + "---|---|" * len(seeds)]
    for key, label in STREAM_ROWS:
        lines.append(f"| {label} | " + " | ".join(f"{_fmt(b.get('whole_' + key))} | {_fmt(b.get('stream_' + key))}"
                                                   for b in seeds) + " |")
    lines.append("| largest relative difference, stream vs whole (gait, skate, jerk, style rows) | "
                 + " | ".join(f"| {_fmt(b.get('stream_max_rel_diff'))}" for b in seeds) + " |")
    return lines


def realism_markdown(r: dict, h: dict) -> list[str]:
    """The realism part's tables (own_paths.py): per feature group, the features that separate
    most, per style, the stride-speed sweep and the stride measurements."""
    z = r.get("realism") or {}
    if not z:
        return []
    first, ref = z.get("generated_tests_first_seed") or {}, (z["real_reference"] or {}).get("tests", {})
    sf = z.get("speed_free_evaluator")
    lines = ["", "## Realism, like for like", "",
             f"{z['paths']} held-out paths ({z['real_windows']} real windows), each walked in its clip's style at "
             f"its speed (K draws per seed) and cut into the same windows. Two-sample test: logistic regression, "
             f"real against generated, {FOLDS}-fold by path; balanced accuracy, 0.5 = indistinguishable. Real: "
             "the real windows in two halves by path, tested the same way (styles with two or more paths; "
             "none when fewer than 4 such paths).",
             "- speed-free evaluator: " + ("none given" if not sf else
                                          f"checksum `{sf['checksum']}`, real held-out top-1 "
                                          f"{_fmt((sf.get('real_heldout') or {}).get('top1'))}"), "",
             "| features (count) | generated vs real (first seed) | real vs real |", "|---|---|---|"]
    for g, v in (first.get("tests") or {}).items():
        lines.append(f"| {g} ({v['features']}) | {_fmt(v['accuracy'])} | {_fmt(ref.get(g, {}).get('accuracy'))} |")
    if first:
        lines += ["", "Features that separate most (first seed; d: generated − real mean in real standard "
                      "deviations; accuracy of that feature alone):", "",
                  "| feature | real | generated | d | accuracy alone |", "|---|---|---|---|---|"]
        for e in first["top_features"]:
            lines.append(f"| {e['feature']} | {_fmt(e['real'])} | {_fmt(e['generated'])} | {_fmt(e['d'])} | "
                         f"{_fmt(e.get('accuracy'))} |")
        lines += ["", "Largest standardised coefficients of the all-features model: "
                  + ", ".join(f"{e['feature']} {e['coef']:+.2f}" for e in first["tests"]["all"]["top_coefficients"]),
                  "", "Gait and speed features (first seed; lengths in leg lengths):", "",
                  "| feature | real | generated | d |", "|---|---|---|---|"]
        for name, e in first["gait_features"].items():
            lines.append(f"| {name} | {_fmt(e['real'])} | {_fmt(e['generated'])} | {_fmt(e['d'])} |")
    lines += ["", "Per style, on its own held-out paths at their speed (generated: mean over seeds; step height: "
                  "std of left − right toe height; skating ratio at the contact height):", "",
              "| style | step freq. gen (Hz) | real | ratio | step height gen (m) | real | skating gen | real | "
              "lower toe gen (m) | real | top-1 own speed | speed-free own speed | real speed-free | "
              "top-1 at 1.2 m/s | speed-free at 1.2 m/s |", "|" + "---|" * 15]
    for name, v in r["per_style"].items():
        g, re_ = v["generated"], v["real"]
        if "own_step_frequency_hz" not in g:
            continue
        m = {k: g[k]["mean"] for k in g}
        ratio = (m["own_step_frequency_hz"] / re_["own_step_frequency_hz"]
                 if re_.get("own_step_frequency_hz") else float("nan"))
        lines.append(f"| {name} | {_fmt(m['own_step_frequency_hz'])} | {_fmt(re_['own_step_frequency_hz'])} | "
                     f"{_fmt(ratio)} | {_fmt(m['own_step_height_m'])} | {_fmt(re_['own_step_height_m'])} | "
                     f"{_fmt(m['own_skate_ratio'])} | {_fmt(re_['own_skate_ratio'])} | "
                     f"{_fmt(m['own_lower_foot_height_m'])} | {_fmt(re_['own_lower_foot_height_m'])} | "
                     f"{_fmt(m['sra_top1_own_speed'])} | {_fmt(m['sra_top1_speed_free_own_speed'])} | "
                     f"{_fmt(re_.get('sra_top1_speed_free_own_speed'))} | {_fmt(m['sra_top1_default_speed'])} | "
                     f"{_fmt(m['sra_top1_speed_free_default_speed'])} |")
    speeds = z["speeds_m_per_s"]
    lo, hi = z["fit_band_m_per_s"]
    lines += ["", f"Step frequency (Hz) against speed on a straight line, one draw per style and seed (mean over "
                  f"seeds); slope fitted over {lo:g}-{hi:g} m/s; real: held-out clips of the style in that band "
                  f"(within styles, pooled: {_fmt(z['real_slope_within_styles'])}; one line across styles: "
                  f"{_fmt(z['real_slope_across_styles'])}):", "",
              "| style | " + " | ".join(f"{v:g} m/s" for v in speeds) + " | slope gen | slope real |",
              "|" + "---|" * (len(speeds) + 3)]
    for name, v in r["per_style"].items():
        g = v["generated"]
        if "stride_speed_slope" not in g:
            continue
        lines.append(f"| {name} | " + " | ".join(_fmt(g[f"step_frequency_hz@{s:g}"]["mean"]) for s in speeds)
                     + f" | {_fmt(g['stride_speed_slope']['mean'])} | {_fmt(v['real'].get('stride_speed_slope'))} |")
    lines += ["", "Stride measured three ways on the held-out clips (median per style, metres per gait cycle): "
                  "the training's target (the root path averaged over one gait cycle: its speed over the "
                  "step frequency), path length over duration over the step frequency, and the path between "
                  "the first and last counted half-cycle over the cycles counted:", "",
              "| style | clips | training's measure | distance per cycle | counted | speed (m/s) |",
              "|---|---|---|---|---|---|"]
    for name in h["style_names"]:
        rows = [c for c in z["stride_clips"] if c["style"] == name]
        if not rows:
            continue

        def med(k, rows=rows):
            v = np.asarray([c[k] for c in rows if c[k] is not None], np.float64)
            v = v[np.isfinite(v)]
            return float(np.median(v)) if v.size else float("nan")
        lines.append(f"| {name} | {len(rows)} | {_fmt(med('training_stride_m'))} | "
                     f"{_fmt(med('distance_per_cycle_m'))} | {_fmt(med('counted_stride_m'))} | "
                     f"{_fmt(med('speed_mps'))} |")
    return lines


def plot_confusion(conf_gen, conf_real, style_names, path) -> Path:
    from motiongan_jax import viz

    plt = viz._pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(12, 5.5))
    for ax, conf, title in ((axes[0], conf_gen, "generated"), (axes[1], conf_real, "real held-out")):
        m = np.asarray(conf, np.float64)
        m = m / np.maximum(m.sum(1, keepdims=True), 1)
        im = ax.imshow(m, vmin=0, vmax=1, cmap="Blues")
        ax.set_xticks(range(len(style_names)), style_names, rotation=90, fontsize=7)
        ax.set_yticks(range(len(style_names)), style_names, fontsize=7)
        ax.set_xlabel("predicted")
        ax.set_ylabel("requested" if title == "generated" else "true")
        ax.set_title(f"evaluator confusion, {title}")
    fig.colorbar(im, ax=axes, shrink=0.8)
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def dumps(report: dict) -> str:
    return json.dumps(atomic.to_jsonable(report), indent=1, allow_nan=False) + "\n"


def write_report(out, report: dict, ctx: Context) -> str:
    """Writes OUT/report.json, report.md, confusion.png and pca_w.png (OUT created); returns the
    SHA-256 of report.json as written."""
    from motiongan_jax import viz

    out = Path(out)
    results = report["results"]
    out.mkdir(parents=True, exist_ok=True)
    atomic.write_text(out / "report.json", dumps(report))
    atomic.write_text(out / "report.md", markdown(atomic.to_jsonable(report)))
    plot_confusion(results["confusion_generated"], results["confusion_real"], ctx.style_names,
                   out / "confusion.png")
    codes = style_space.label_codes(ctx.state, ctx.style_names, k=10)
    X, y = codes.flat_samples
    p = style_space.pca(X, 2)
    viz.plot_style_pca(np.asarray(style_space.pca_transform(p, X)), np.asarray(y), ctx.style_names, out / "pca_w.png",
                       centroids_Cx2=np.asarray(style_space.pca_transform(p, codes.centroids_CxD)),
                       explained=np.asarray(p.explained_variance_ratio_K)[:2])
    return hashlib.sha256((out / "report.json").read_bytes()).hexdigest()
