"""Style search measured on the held-out split (the protocol's search part, `bin/evaluate.py
--search-only`): for every held-out real clip, the style search's recovered mix and the known
styles nearest to it, against the clip's label; beside it the same for G's own walk of that clip's
path in that clip's style at a code drawn for it (w known), so the search is also measured where
the right answer is certain. Top-1 and top-3 over clips and per style, and the search's time.

G's walk: the clip's path (smoothed) at its own speed, walked with w = LT(label, z), z ~ N(0, I),
from a gait phase φ0 ~ U[0, 2π) (one key per clip, split once), padded straight on to one of
WALK_BUCKETS samples (so that few lengths compile) and cut back to the path's samples; it is then
searched exactly as a real clip is, at the model's sample rate.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable, Sequence

import jax
import numpy as np
from scipy.ndimage import gaussian_filter1d

from motiongan_jax.analysis import clips as clips_lib
from motiongan_jax.analysis import search as search_lib
from motiongan_jax.analysis import style_space
from motiongan_jax.data import curves
from motiongan_jax.generate import styles, walk
from motiongan_jax.model import apply as model_apply
from motiongan_jax.motion import trajectory

WALK_BUCKETS = (128, 256, 512, 1024)  # G's walks of the clips' paths are padded to one of these


@dataclasses.dataclass(frozen=True)
class Settings:
    windows: int = search_lib.WINDOWS
    keep: int = search_lib.KEEP
    steps: int = search_lib.STEPS
    clips_per_style: int | None = None  # None: every held-out clip
    own_walks: bool = True  # also G's walk of each clip's path (w known)
    seed: int = 0  # G's walks: codes and phase offsets


def clip_order(val_clips, per_style: int | None) -> list:
    """The held-out clips round robin over styles (sorted by name), at most `per_style` of each."""
    by_style: dict[str, list] = {}
    for clip in val_clips:
        by_style.setdefault(clip.label.style, []).append(clip)
    order, taken = [], {s: 0 for s in by_style}
    while any(by_style.values()):
        for s in sorted(by_style):
            if by_style[s] and (per_style is None or taken[s] < per_style):
                order.append(by_style[s].pop(0))
                taken[s] += 1
            else:
                by_style[s] = []
    return order


PATH_SMOOTHING_S = 0.5  # G's walks follow the clip's pelvis path smoothed over this (Gaussian sigma): no sway


def own_walk(state, layout, clip, cfg, w_D, phase_offset: float) -> tuple[np.ndarray, np.ndarray]:
    """(root_Mx3, pose_MxR) at the model's sample rate: G walking the clip's path (its pelvis's floor
    path smoothed, PATH_SMOOTHING_S, at equal arc length over the clip's duration: its speed) with
    code w from gait phase `phase_offset`."""
    n = (len(clip.root_Fx3) - 1) // cfg.data.frame_step + 1
    xz = gaussian_filter1d(np.asarray(clip.root_Fx3, np.float64)[:, [0, 2]], PATH_SMOOTHING_S * clip.fps, axis=0,
                           mode="nearest")
    curve = trajectory.on_floor(curves.resample_polyline(xz, num_points=n)).astype(np.float32)
    bucket = next((b for b in WALK_BUCKETS if b >= n), n)
    offset = np.asarray([phase_offset], np.float32) if model_apply.has_gait_phase(state) else None
    gen = walk.generate_motion(state, layout, walk.extend_straight(curve, bucket - n),
                               np.asarray(w_D, np.float32)[None], offset)
    pos = gen.positions[0, :n]
    root = pos[:, 0]
    return root, (pos[:, 1:] - root[:, None]).reshape(n, -1)


def _row(found: search_lib.StyleFound, label: int, names: Sequence[str]) -> dict:
    ranked = [n for n, _ in found.nearest]
    return {"style": names[label], "nearest": ranked[:3], "top1": ranked[0] == names[label],
            "top3": names[label] in ranked[:3], "rank": ranked.index(names[label]) + 1,
            "screen_top1": names[int(np.argmin(found.screen_C))] == names[label],
            "mix": found.mix(), "loss": found.loss, "loss_kind": found.loss_kind, "seconds": found.seconds}


def _summary(rows: list[dict], names: Sequence[str]) -> dict:
    if not rows:
        return {"clips": 0}
    per = {}
    for n in names:
        mine = [r for r in rows if r["style"] == n]
        per[n] = {"clips": len(mine), "top1": float(np.mean([r["top1"] for r in mine])) if mine else float("nan"),
                  "top3": float(np.mean([r["top3"] for r in mine])) if mine else float("nan")}
    seen = [v["top1"] for v in per.values() if v["clips"]]
    worst = min(seen)
    return {"clips": len(rows), "top1": float(np.mean([r["top1"] for r in rows])),
            "top3": float(np.mean([r["top3"] for r in rows])),
            "screen_top1": float(np.mean([r["screen_top1"] for r in rows])),
            "weakest_style": [n for n, v in per.items() if v["clips"] and v["top1"] == worst][0],
            "weakest_top1": worst, "per_style": per}


def recovery(state, meta: dict, cfg, layout, val_clips, style_names: Sequence[str], settings: Settings = Settings(),
             log: Callable[[str], None] = print) -> dict:
    """The search on every held-out clip (and G's walk of its path): per-clip rows and the summaries
    {"real": ..., "own": ..., "seconds": ...}. Clips too short for one window are counted and skipped."""
    names = tuple(style_names)
    codes = np.asarray(style_space.label_codes(state, names, k=1).zero_CxD)
    rate = walk.sample_rate(meta, cfg)
    key = jax.random.key(settings.seed)
    rows: dict[str, list] = {"real": [], "own": []}
    skipped = []
    clips = clip_order(val_clips, settings.clips_per_style)
    opts = dict(keep=settings.keep, steps=settings.steps)
    for i, clip in enumerate(clips):
        label = names.index(clip.label.style)
        try:
            target = clips_lib.model_rate_windows(clip.root_Fx3, clip.pose_FxR, clip.fps, meta, cfg, layout,
                                                  spread=settings.windows, phase=True, source=clip.source)
            found = search_lib.search_style(state, codes, names, target, **opts)
        except style_space.AnalysisError as err:
            skipped.append({"clip": Path(clip.source).name, "why": str(err)})
            continue
        row = {"clip": Path(clip.source).name, **_row(found, label, names)}
        rows["real"].append(row)
        msg = f"[{i + 1}/{len(clips)}] {row['clip']}: {row['style']} -> {', '.join(row['nearest'])}"
        if settings.own_walks:
            k_z, k_phase = jax.random.split(jax.random.fold_in(key, i))
            z = jax.random.normal(k_z, (1, model_apply.z_dim(state)))
            w = np.asarray(styles.latent_codes(state, np.array([label], np.int32), z))[0]
            phi0 = float(jax.random.uniform(k_phase, (), maxval=2 * np.pi))
            root, pose = own_walk(state, layout, clip, cfg, w, phi0)
            g_target = clips_lib.model_rate_windows(root, pose, rate, meta, cfg, layout, spread=settings.windows,
                                                    phase=True, source=f"G's walk of {row['clip']}")
            g_found = search_lib.search_style(state, codes, names, g_target, **opts)
            rows["own"].append({"clip": row["clip"], **_row(g_found, label, names),
                                "w_distance": float(np.linalg.norm(g_found.w_D - w))})
            msg += f"; G's walk -> {', '.join(rows['own'][-1]['nearest'])}"
        log(f"{msg} ({found.seconds:.1f} s)")
    secs = np.array([r["seconds"] for r in rows["real"] + rows["own"]])
    kinds = sorted({r["loss_kind"] for r in rows["real"] + rows["own"]})
    return {"settings": dataclasses.asdict(settings), "loss": kinds, "style_names": list(names),
            "real": _summary(rows["real"], names), "own": _summary(rows["own"], names),
            "seconds": {"median": float(np.median(secs)) if len(secs) else float("nan"),
                        "max": float(np.max(secs)) if len(secs) else float("nan"),
                        "first": float(secs[0]) if len(secs) else float("nan")},
            "clips": rows, "skipped": skipped}


def _f(row: dict, key: str, digits: int = 2) -> str:
    return f"{row.get(key, float('nan')):.{digits}f}"


def markdown(result: dict, header: str = "") -> str:
    """The result as a Markdown table: per style and over clips, real clips and G's walks."""
    names = result["style_names"]
    real, own = result["real"], result["own"]
    lines = [header, "", "| style | real clips | top-1 | top-3 | G's walks top-1 | top-3 |",
             "|---|---|---|---|---|---|"]
    for n in names:
        r, g = real.get("per_style", {}).get(n, {}), own.get("per_style", {}).get(n, {})
        lines.append(f"| {n} | {r.get('clips', 0)} | {_f(r, 'top1')} | {_f(r, 'top3')} | {_f(g, 'top1')} "
                     f"| {_f(g, 'top3')} |")
    lines.append(f"| **all** | {real.get('clips', 0)} | {_f(real, 'top1', 3)} | {_f(real, 'top3', 3)} | "
                 f"{_f(own, 'top1', 3)} | {_f(own, 'top3', 3)} |")
    s = result["seconds"]
    lines += ["", f"Search time: median {s['median']:.2f} s, max {s['max']:.2f} s (first, compiling: "
                  f"{s['first']:.2f} s); skipped clips: {len(result['skipped'])}.", ""]
    return "\n".join(lines)
