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
