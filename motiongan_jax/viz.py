"""Headless matplotlib figures and animations of skeletons (Agg backend; artists updated in place)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from motiongan_jax import atomic


def _pyplot():
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def animate_skeletons(joints_list, parents, titles, path, *, fps: float = 15.0, curves=None,
                      size: float = 3.0) -> Path:
    """Side-by-side 3-D animations of several motions, written as a GIF (atomically).

    joints_list: list of (T, J, 3) arrays in metres, Y up; parents: kept-joint parents (-1 root);
    curves: optional list of (P, 3) input curves drawn on the floor in red.
    """
    from matplotlib.animation import PillowWriter

    plt = _pyplot()
    path = Path(path)
    n = len(joints_list)
    T = min(len(j) for j in joints_list)
    fig = plt.figure(figsize=(size * n, size))
    axes, bone_lines, trails = [], [], []
    bones = [(p, c) for c, p in enumerate(parents) if p >= 0]
    for i, joints in enumerate(joints_list):
        joints = np.asarray(joints)
        ax = fig.add_subplot(1, n, i + 1, projection="3d")
        ax.set_title(titles[i], fontsize=9)
        # plot axes: x -> data x, y -> data z, z -> data y (up)
        lo, hi = joints.reshape(-1, 3).min(0), joints.reshape(-1, 3).max(0)
        centre, half = (lo + hi) / 2, max(float(np.max(hi - lo)) / 2, 1.0)
        ax.set_xlim(centre[0] - half, centre[0] + half)
        ax.set_ylim(centre[2] - half, centre[2] + half)
        ax.set_zlim(0, 2 * half)
        ax.set_xticklabels([]); ax.set_yticklabels([]); ax.set_zticklabels([])
        if curves is not None and curves[i] is not None:
            c = np.asarray(curves[i])
            ax.plot(c[:, 0], c[:, 2], np.zeros(len(c)), color="red", lw=1)
        lines = [ax.plot([], [], [], color="0.3", lw=2)[0] for _ in bones]
        trail = ax.plot([], [], [], color="tab:blue", lw=1)[0]
        axes.append(joints)
        bone_lines.append(lines)
        trails.append(trail)

    def draw(t):
        for joints, lines, trail in zip(axes, bone_lines, trails):
            for line, (p, c) in zip(lines, bones):
                seg = joints[t, [p, c]]
                line.set_data(seg[:, 0], seg[:, 2])
                line.set_3d_properties(seg[:, 1])
            root = joints[: t + 1, 0]
            trail.set_data(root[:, 0], root[:, 2])
            trail.set_3d_properties(np.zeros(len(root)))

    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        with atomic.atomic_path(path) as tmp:
            writer = PillowWriter(fps=fps)
            with writer.saving(fig, str(tmp), dpi=60):
                for t in range(T):
                    draw(t)
                    writer.grab_frame()
    finally:
        plt.close(fig)
    return path
