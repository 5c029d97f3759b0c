"""Headless matplotlib figures and animations of skeletons (Agg backend; artists updated in place)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np

from motiongan_jax import atomic


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


LEFT_COLOR, RIGHT_COLOR = "tab:orange", "tab:cyan"  # left and right limbs, toes, steps


def _bones(parents):
    return [(int(p), c) for c, p in enumerate(parents) if p >= 0]


def gif_durations_ms(frames: int, fps: float) -> list[int]:
    """Per-frame GIF delays in ms: GIFs count in hundredths of a second, so 1/15 s cannot be one
    delay (66 ms is stored as 60: a walk 10 % fast); whole hundredths that add up to frame i's
    time, rounded, after every frame keep the clock right (15 Hz: 70, 60, 70, 70, 60, ...)."""
    ticks = [round(i * 100 / fps) for i in range(frames + 1)]
    return [10 * (b - a) for a, b in zip(ticks, ticks[1:])]


def _gif_writer_class():
    from matplotlib.animation import PillowWriter

    class GifWriter(PillowWriter):
        """matplotlib's Pillow writer with delays that keep the frame rate (gif_durations_ms)."""

        def finish(self):
            self._frames[0].save(self.outfile, save_all=True, append_images=self._frames[1:],
                                 duration=gif_durations_ms(len(self._frames), self.fps), loop=0)

    return GifWriter


def video_writer(path, fps: float):
    """A matplotlib writer for `path`'s suffix: .gif (Pillow) or .mp4 (ffmpeg: the one on PATH,
    else imageio-ffmpeg's if that is installed). RuntimeError naming the fix when there is none."""
    import shutil

    from matplotlib import rcParams
    from matplotlib.animation import FFMpegWriter

    suffix = Path(path).suffix.lower()
    if suffix == ".gif":
        return _gif_writer_class()(fps=fps)
    if suffix == ".mp4":
        exe = shutil.which("ffmpeg")
        if exe is None:
            try:
                import imageio_ffmpeg

                exe = imageio_ffmpeg.get_ffmpeg_exe()
            except Exception:  # not installed, or its binary is missing
                exe = None
        if exe is None:
            raise RuntimeError(f"{path}: writing .mp4 needs ffmpeg: install it (e.g. apt-get install "
                               "ffmpeg) or `pip install imageio-ffmpeg`, or write a .gif instead")
        rcParams["animation.ffmpeg_path"] = exe
        # "h264" (ffmpeg's default H.264 encoder, libx264 in imageio-ffmpeg's and distributions'
        # builds), not "libx264": only for "h264" does matplotlib round the frame to even pixel
        # sizes, which yuv420p needs (an odd size makes ffmpeg exit with nothing written)
        return FFMpegWriter(fps=fps, codec="h264", extra_args=["-pix_fmt", "yuv420p"])
    raise ValueError(f"{path}: unsupported animation format {suffix!r} (use .gif or .mp4)")


def _in_view(points, cx, cz, half):
    """Floor points outside the camera's box set to NaN (3-D axes do not clip lines)."""
    pts = np.array(points, np.float64)
    pts[(np.abs(pts[:, 0] - cx) > half) | (np.abs(pts[:, 2] - cz) > half)] = np.nan
    return pts


def _bone_colors(parents, joint_names) -> list[str]:
    """One colour per bone (as `_bones` orders them): the left limbs' LEFT_COLOR, the right limbs'
    RIGHT_COLOR, the trunk dark grey; without names every bone is dark grey."""
    if joint_names is None:
        return ["0.25"] * len(_bones(parents))
    from motiongan_jax.motion.representation import joint_side

    side = {"left": LEFT_COLOR, "right": RIGHT_COLOR}
    return [side.get(joint_side(joint_names[c]), "0.25") for _, c in _bones(parents)]


def _shade(tri_NxKx3: np.ndarray, base_Nx3: np.ndarray) -> np.ndarray:
    """RGBA face colours: `base` lit by a light from above and behind the camera's side (Lambert,
    with an ambient floor), from the faces' normals (data axes x, y up, z)."""
    n = np.cross(tri_NxKx3[:, 1] - tri_NxKx3[:, 0], tri_NxKx3[:, 2] - tri_NxKx3[:, 0])
    n /= np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-12)
    light = np.array([0.35, 0.85, 0.4]) / np.linalg.norm([0.35, 0.85, 0.4])
    k = 0.38 + 0.62 * np.clip(n @ light, 0.0, 1.0)
    return np.concatenate([np.clip(base_Nx3 * k[:, None], 0, 1), np.ones((len(k), 1))], axis=1)


def _follow_azimuth(root_Tx3: np.ndarray, span: int = 8, offset_deg: float = 35.0) -> np.ndarray:
    """Per frame, the azimuth (degrees, matplotlib's) of a camera behind the walker and to its side:
    the heading of the root's floor travel over +-span frames, unwrapped and smoothed."""
    T = len(root_Tx3)
    a, b = np.clip(np.arange(T) - span, 0, T - 1), np.clip(np.arange(T) + span, 0, T - 1)
    d = root_Tx3[b] - root_Tx3[a]
    heading = np.unwrap(np.arctan2(d[:, 2], d[:, 0]))  # in the axes' (x, y) = data (x, z) plane
    if T > 1 and np.all(np.hypot(d[:, 0], d[:, 2]) < 1e-6):
        heading[:] = 0.0
    k = np.ones(2 * span + 1) / (2 * span + 1)
    smooth = np.convolve(np.pad(heading, span, mode="edge"), k, mode="valid")
    return np.degrees(smooth) + 180.0 + offset_deg


def animate_motions(joints_list, parents, titles, path, *, fps: float = 15.0, curves=None, joint_names=None,
                    size: float = 4.0, dpi: int = 90, view: float = 2.2, trail: int = 32, bodies=None) -> Path:
    """Side-by-side 3-D animations with a chase camera, written atomically as .gif or .mp4.

    joints_list: list of (T, J, 3) arrays in metres, Y up (the floor is y = 0); parents: joint
    parents (-1 root); joint_names (optional): left limbs are drawn in LEFT_COLOR and right ones in
    RIGHT_COLOR, so that steps can be told apart; curves: optional list of (P, 3) input curves
    (None entries allowed), drawn in red for `trail` samples either side of the current one (the
    reference's ±32); the root's floor trail of the last `trail` samples in blue. Panels are
    `size` inches at `dpi` (360 pixels by default). The camera looks at a `view`-metre cube
    centred on the current root's floor position, so long paths keep the character large.
    bodies (optional, one per panel or None): (triangles (N, 3), face colours (N, 3), a function
    frame -> vertices (V, 3)) of a skinned body, drawn shaded instead of the bones; then the camera
    follows behind the walker's side, the cube fits the body (it fills most of the frame) and a
    floor grid is drawn around it. Artists are updated in place; the figure is closed afterwards.
    """
    from mpl_toolkits.mplot3d.art3d import Poly3DCollection

    plt = _pyplot()
    path = Path(path)
    writer = video_writer(path, fps)
    n = len(joints_list)
    T = min(len(j) for j in joints_list)
    bones = _bones(parents)
    colors = _bone_colors(parents, joint_names)
    fig = plt.figure(figsize=(size * n, size))
    panels = []
    for i, joints in enumerate(joints_list):
        joints = np.asarray(joints, np.float64)
        body = None if bodies is None else bodies[i]
        half = view / 2
        if body is not None:  # the cube around the body: its height and a little floor
            half = 0.5 * max(1.2, float(np.max(joints[..., 1])) + 0.2)
            fig.subplots_adjust(left=0, right=1, bottom=0, top=0.94, wspace=0)
        ax = fig.add_subplot(1, n, i + 1, projection="3d")
        ax.set_title(titles[i], fontsize=9)
        ax.set_zlim(0, 2 * half)
        ax.set_box_aspect((1, 1, 1), zoom=1.5 if body is not None else 1.0)
        for set_labels in (ax.set_xticklabels, ax.set_yticklabels, ax.set_zticklabels):
            set_labels([])
        ax.view_init(elev=15, azim=-60)
        curve = None if curves is None or curves[i] is None else np.asarray(curves[i], np.float64)
        red = ax.plot([], [], [], color="red", lw=1.2)[0]
        blue = ax.plot([], [], [], color="tab:blue", lw=1)[0]
        if body is None:
            lines = [ax.plot([], [], [], color=col, lw=2.2)[0] for col in colors]
            mesh, azim, grid = None, None, []
        else:
            ax.set_axis_off()
            lines = []
            grid = [ax.plot([], [], [], color="0.72", lw=0.6)[0] for _ in range(2 * 9)]
            mesh = Poly3DCollection([], edgecolor="none")
            ax.add_collection3d(mesh)
            azim = _follow_azimuth(joints[:, 0])
        panels.append((ax, joints, curve, red, blue, lines, half, body, mesh, azim, grid))

    def draw(t):
        for ax, joints, curve, red, blue, lines, half, body, mesh, azim, grid in panels:
            cx, cz = joints[t, 0, 0], joints[t, 0, 2]
            ax.set_xlim(cx - half, cx + half)
            ax.set_ylim(cz - half, cz + half)
            for line, (p, c) in zip(lines, bones):
                seg = joints[t, [p, c]]
                line.set_data(seg[:, 0], seg[:, 2])
                line.set_3d_properties(seg[:, 1])
            if body is not None:
                ax.view_init(elev=12, azim=azim[t])
                # floor grid every 0.5 m inside the cube, fixed to the floor (it slides past as the camera follows)
                ticks = np.arange(np.ceil((cx - half) * 2) / 2, cx + half, 0.5)[:9]
                zt = np.arange(np.ceil((cz - half) * 2) / 2, cz + half, 0.5)[:9]
                for k, line in enumerate(grid):
                    if k < 9 and k < len(ticks):
                        line.set_data([ticks[k]] * 2, [cz - half, cz + half])
                    elif k >= 9 and k - 9 < len(zt):
                        line.set_data([cx - half, cx + half], [zt[k - 9]] * 2)
                    else:
                        line.set_data([], [])
                    line.set_3d_properties(np.zeros(len(line.get_xdata())))
                tris_idx, base, vertices_at = body
                tri = vertices_at(t)[tris_idx]  # (N, 3, 3) in data axes x, y (up), z
                mesh.set_verts(tri[:, :, [0, 2, 1]])
                mesh.set_facecolor(_shade(tri, base))
            root = _in_view(joints[max(0, t - trail): t + 1, 0], cx, cz, half)
            blue.set_data(root[:, 0], root[:, 2])
            blue.set_3d_properties(np.zeros(len(root)))
            if curve is not None:
                k = min(t, len(curve) - 1)
                seg = _in_view(curve[max(0, k - trail): k + trail + 1], cx, cz, half)
                red.set_data(seg[:, 0], seg[:, 2])
                red.set_3d_properties(np.zeros(len(seg)))

    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic.atomic_path(path) as tmp:
            with writer.saving(fig, str(tmp), dpi=dpi):
                for t in range(T):
                    draw(t)
                    writer.grab_frame()
    except subprocess.CalledProcessError as err:  # ffmpeg failed; atomic_path removed its file
        lines = (err.stderr or "").strip().splitlines()
        raise RuntimeError(f"{path}: ffmpeg ({err.cmd[0]}) failed with exit status {err.returncode}"
                           + (f": {lines[-1]}" if lines else "")) from None
    finally:
        plt.close(fig)
    return path


def pose_strips(joints_list, parents, titles, path, *, curves=None, num_poses: int = 8,
                ncols: int | None = None, size: float = 3.2, dpi: int = 100) -> Path:
    """Stroboscopic figure (the paper's Figs. 4, 6, 7): one 3-D panel per motion, `num_poses`
    poses evenly spaced in time drawn along the path (light to dark = early to late), the input
    curve in red and the root's floor trail in blue; equal scale on every axis. PNG (or any
    format matplotlib saves by suffix), written atomically.
    """
    plt = _pyplot()
    path = Path(path)
    n = len(joints_list)
    ncols = min(n, 5) if ncols is None else int(ncols)
    nrows = -(-n // ncols)
    bones = _bones(parents)
    fig = plt.figure(figsize=(size * ncols * 1.3, size * nrows))
    for i, joints in enumerate(joints_list):
        joints = np.asarray(joints, np.float64)
        T = len(joints)
        ax = fig.add_subplot(nrows, ncols, i + 1, projection="3d")
        ax.set_title(titles[i], fontsize=9)
        pts = joints.reshape(-1, 3)
        if curves is not None and curves[i] is not None:
            c = np.asarray(curves[i], np.float64)
            ax.plot(c[:, 0], c[:, 2], np.zeros(len(c)), color="red", lw=1)
            pts = np.concatenate([pts, c])
        ax.plot(joints[:, 0, 0], joints[:, 0, 2], np.zeros(T), color="tab:blue", lw=0.8)
        times = np.unique(np.linspace(0, T - 1, max(1, min(num_poses, T))).round().astype(int))
        for k, t in enumerate(times):
            shade = str(0.7 - 0.7 * k / max(len(times) - 1, 1))
            for p, c in bones:
                seg = joints[t, [p, c]]
                ax.plot(seg[:, 0], seg[:, 2], seg[:, 1], color=shade, lw=1.2)
        lo, hi = pts.min(0), pts.max(0)
        lo[1] = min(lo[1], 0.0)
        span = np.maximum(hi - lo, 0.1)
        ax.set_xlim(lo[0], lo[0] + span[0])
        ax.set_ylim(lo[2], lo[2] + span[2])
        ax.set_zlim(lo[1], lo[1] + span[1])
        ax.set_box_aspect((span[0], span[2], span[1]))
        ax.view_init(elev=25, azim=-70)
        for set_labels in (ax.set_xticklabels, ax.set_yticklabels, ax.set_zticklabels):
            set_labels([])
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic.atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format=path.suffix.lstrip(".").lower() or "png",
                        bbox_inches="tight")
    finally:
        plt.close(fig)
    return path


# ---------------------------------------------------------------------------------------------
# Style-space figures (bin/analyze.py): PCA scatter (paper Fig. 5), centroid-distance heatmap
# ---------------------------------------------------------------------------------------------

def _save_style_figure(fig, path, dpi: int) -> Path:
    """Write a figure atomically (PNG, or what the suffix names) and close it."""
    plt = _pyplot()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic.atomic_path(path) as tmp:
            fig.savefig(str(tmp), dpi=dpi, format=path.suffix.lstrip(".") or "png", bbox_inches="tight")
    finally:
        plt.close(fig)
    return path


def plot_style_pca(points_Nx2, labels_N, style_names, path, *, centroids_Cx2=None, zero_Cx2=None,
                   explained=None, marks=None, title: str = "Style codes w (PCA)",
                   dpi: int = 120) -> Path:
    """2-D PCA scatter of style codes coloured by style (hsv(c/C), as the reference), each style's
    name at its centroid. zero_Cx2: the z = 0 codes (crosses); explained: the two components'
    explained variance ratios for the axis labels; marks: {label: (x, y)} extra starred points
    (e.g. a style-search result)."""
    plt = _pyplot()
    pts = np.asarray(points_Nx2, np.float64)
    labels = np.asarray(labels_N)
    C = len(style_names)
    cmap = plt.get_cmap("hsv")
    fig, ax = plt.subplots(figsize=(6.5, 5.5))
    for c, name in enumerate(style_names):
        colour = cmap(c / max(C, 1))
        sel = pts[labels == c]
        ax.scatter(sel[:, 0], sel[:, 1], s=14, color=colour, alpha=0.6, label=name)
        if zero_Cx2 is not None:
            z = np.asarray(zero_Cx2)[c]
            ax.scatter([z[0]], [z[1]], marker="x", s=40, color=colour)
        centre = np.asarray(centroids_Cx2)[c] if centroids_Cx2 is not None else sel.mean(axis=0)
        ax.annotate(name, centre, fontsize=8, ha="center", va="bottom", weight="bold")
    for text, (x, y) in (marks or {}).items():
        ax.scatter([x], [y], marker="*", s=160, color="black", zorder=5)
        ax.annotate(text, (x, y), fontsize=8, xytext=(4, -10), textcoords="offset points")
    if explained is not None:
        ax.set_xlabel(f"PC1 ({100 * float(explained[0]):.1f}% of variance)")
        ax.set_ylabel(f"PC2 ({100 * float(explained[1]):.1f}% of variance)" if len(explained) > 1 else "PC2")
    else:
        ax.set_xlabel("PC1")
        ax.set_ylabel("PC2")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7, loc="best", markerscale=1.2, ncol=2 if C > 12 else 1)
    ax.grid(alpha=0.3)
    return _save_style_figure(fig, path, dpi)


def plot_distance_heatmap(dist_CxC, style_names, path, *, title: str = "Distance between style centroids",
                          fmt: str = "{:.2g}", dpi: int = 120) -> Path:
    """C x C heatmap (imshow, Blues, annotated with each distance) of style-centroid distances."""
    plt = _pyplot()
    d = np.asarray(dist_CxC, np.float64)
    C = len(style_names)
    fig, ax = plt.subplots(figsize=(1.0 + 0.55 * C, 0.6 + 0.5 * C))
    im = ax.imshow(d, cmap="Blues")
    ax.set_xticks(range(C), labels=list(style_names), rotation=60, ha="right", fontsize=8)
    ax.set_yticks(range(C), labels=list(style_names), fontsize=8)
    hi = d.max() if d.size else 0.0
    if C <= 30:
        for i in range(C):
            for j in range(C):
                ax.text(j, i, fmt.format(d[i, j]), ha="center", va="center", fontsize=6,
                        color="white" if hi > 0 and d[i, j] > 0.6 * hi else "black")
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    ax.set_title(title, fontsize=10)
    return _save_style_figure(fig, path, dpi)


def plot_metrics(records: list[dict], path, *, keys=("d_total", "g_adv", "g_cls", "g_curve", "g_bone",
                                                      "d_cls_acc_real", "g_cls_acc_fake"), title: str = "") -> Path:
    """Loss curves from metrics.jsonl records, one panel per key (log scale where positive)."""
    plt = _pyplot()
    keys = [k for k in keys if any(k in r for r in records)]
    fig, axes = plt.subplots(1, len(keys), figsize=(2.6 * len(keys), 2.4), squeeze=False)
    steps = np.array([r["step"] for r in records])
    for ax, k in zip(axes[0], keys):
        v = np.array([r.get(k, np.nan) for r in records], dtype=float)
        ax.plot(steps, v, lw=0.6, color="0.6")
        if len(v) >= 10:  # a running mean over 10 logged points
            ax.plot(steps[9:], np.convolve(v, np.ones(10) / 10, mode="valid"), lw=1.2, color="tab:blue")
        if k.startswith(("g_curve", "g_bone")) and np.all(v[np.isfinite(v)] > 0):
            ax.set_yscale("log")
        ax.set_title(k, fontsize=8)
        ax.tick_params(labelsize=6)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path



def plot_gait(traces, path, *, sample_rate: float, contact_height_m: float, title: str = "") -> Path:
    """Toe heights over time, one row per style: a real held-out clip (left) and G walking its path
    in its style (right), left toe and right toe; the band below the contact height shaded. A walk
    shows flat planted stretches and alternating lifts; a glide shows neither."""
    plt = _pyplot()
    n = len(traces)
    fig, axes = plt.subplots(n, 2, figsize=(10, 1.25 * n + 0.8), sharex=True, sharey=True, squeeze=False)
    max_height = max(max(float(t.real_heights_Tx2.max()), float(t.gen_heights_Tx2.max())) for t in traces)
    for row, tr in zip(axes, traces):
        for ax, h, what in ((row[0], tr.real_heights_Tx2, "real"), (row[1], tr.gen_heights_Tx2, "generated")):
            t = np.arange(len(h)) / sample_rate
            ax.axhspan(0, contact_height_m, color="0.92", lw=0)
            ax.plot(t, h[:, 0], color=LEFT_COLOR, lw=1.3, label="left toe")
            ax.plot(t, h[:, 1], color=RIGHT_COLOR, lw=1.3, label="right toe")
            ax.set_ylim(-0.02, max(max_height * 1.05, 0.1))
            ax.text(0.01, 0.95, f"{tr.style} · {what}", transform=ax.transAxes, va="top", fontsize=8)
            ax.tick_params(labelsize=7)
    axes[0, 0].legend(loc="upper right", fontsize=7, frameon=False, ncol=2)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("height (m)", fontsize=7)
    fig.suptitle(title or "toe heights above the floor: real held-out clips and G on their paths", fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic.atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=110, format=path.suffix.lstrip(".") or "png")
    plt.close(fig)
    return path
