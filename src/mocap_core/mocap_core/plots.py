"""Figures for reports and demos (matplotlib, Agg backend; no ROS imports)."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .skeleton import KEYPOINT_EDGES, KEYPOINT_NAMES


def plot_keypoint_frames(times_s: Sequence[float], keypoints: np.ndarray, path: str | Path,
                         panels: int = 6, min_confidence: float = 0.1,
                         title: str = '2D keypoints') -> Path:
    """Save a figure of 2D skeletons at evenly spaced frames plus the mean confidence over time.

    Args:
        times_s: (T,) frame times in seconds.
        keypoints: (T, 23, 3) u (px), v (px), confidence of the first person.
        path: output image (PNG).
        panels: number of frames drawn.
        min_confidence: keypoints below it are not drawn.
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    kp = np.asarray(keypoints, dtype=np.float64)
    t = np.asarray(times_s, dtype=np.float64)
    if kp.ndim != 3 or len(kp) == 0 or len(t) != len(kp):
        raise ValueError(f'expected (T, 23, 3) keypoints with T times, got {kp.shape}, {t.shape}')
    seen = kp[..., 2] >= min_confidence
    umax = kp[..., 0][seen].max() if seen.any() else 1.0
    vmax = kp[..., 1][seen].max() if seen.any() else 1.0
    n = min(panels, len(kp))
    idx = np.linspace(0, len(kp) - 1, n).round().astype(int)
    fig = plt.figure(figsize=(2.2 * n, 6.0))
    grid = fig.add_gridspec(2, n, height_ratios=[3, 1])
    for k, i in enumerate(idx):
        ax = fig.add_subplot(grid[0, k])
        for a, b in KEYPOINT_EDGES:
            if seen[i, a] and seen[i, b]:
                side = KEYPOINT_NAMES[b].split('_')[0]
                color = {'left': 'tab:blue', 'right': 'tab:orange'}.get(side, 'tab:gray')
                ax.plot(kp[i, [a, b], 0], kp[i, [a, b], 1], '-', color=color, lw=2)
        ax.scatter(kp[i, seen[i], 0], kp[i, seen[i], 1], s=8, c='k')
        ax.set_xlim(0, umax * 1.05)
        ax.set_ylim(vmax * 1.05, 0)
        ax.set_aspect('equal')
        ax.set_title(f't = {t[i] - t[0]:.2f} s', fontsize=9)
        ax.tick_params(labelsize=6)
    ax = fig.add_subplot(grid[1, :])
    ax.plot(t - t[0], kp[..., 2].mean(axis=-1), label='mean confidence')
    ax.plot(t - t[0], seen.mean(axis=-1), label=f'fraction >= {min_confidence:g}')
    ax.set_xlabel('time (s)')
    ax.set_ylim(0, 1.05)
    ax.legend(fontsize=8, loc='lower right')
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def plot_motion_frames(times_s: Sequence[float], positions: np.ndarray, parents: Sequence[int],
                       path: str | Path, panels: int = 6, frame: str = 'camera',
                       contacts: np.ndarray | None = None, title: str = '3D motion') -> Path:
    """Save front and side views of a 3D skeleton at evenly spaced frames.

    Args:
        times_s: (T,) frame times, seconds.
        positions: (T, J, 3) joint positions, metres.
        parents: the joint tree (parent index per joint, -1 for the root).
        path: output image (PNG).
        frame: 'camera' (optical frame: x right, y down, z forward; views from the camera and
            from its right) or 'world' (z up; views along -y and +x).
        contacts: optional (T, 4) contact probabilities of left/right heel/toe, drawn as the
            colour of the feet (red = contact).
    """
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    p = np.asarray(positions, dtype=np.float64)
    t = np.asarray(times_s, dtype=np.float64)
    if p.ndim != 3 or p.shape[-1] != 3 or len(p) == 0 or len(t) != len(p):
        raise ValueError(f'expected (T, J, 3) positions with T times, got {p.shape}, {t.shape}')
    if frame == 'camera':   # horizontal axis, vertical axis (up), per view
        views = (('front (camera view)', 0, 1, -1.0), ('side (from the right)', 2, 1, -1.0))
    elif frame == 'world':
        views = (('front (along +y)', 0, 2, 1.0), ('side (along -x)', 1, 2, 1.0))
    else:
        raise ValueError("frame must be 'camera' or 'world'")
    n = min(panels, len(p))
    idx = np.linspace(0, len(p) - 1, n).round().astype(int)
    fig, axes = plt.subplots(2, n, figsize=(2.2 * n, 5.6), squeeze=False)
    for row, (name, h, v, sign) in enumerate(views):
        for k, i in enumerate(idx):
            ax = axes[row, k]
            for j, par in enumerate(parents):
                if par < 0:
                    continue
                ax.plot(p[i, [par, j], h], sign * p[i, [par, j], v], '-', lw=2,
                        color='tab:blue')
            ax.scatter(p[i, :, h], sign * p[i, :, v], s=6, c='k')
            centre = p[i, 0]
            ax.set_xlim(centre[h] - 1.0, centre[h] + 1.0)
            ax.set_ylim(sign * centre[v] - 1.1, sign * centre[v] + 1.1)
            ax.set_aspect('equal')
            ax.tick_params(labelsize=6)
            if row == 0:
                ax.set_title(f't = {t[i] - t[0]:.2f} s', fontsize=9)
            if k == 0:
                ax.set_ylabel(name, fontsize=8)
    fig.suptitle(title)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
