"""Helpers shared by the MotioNet and VTM training loops (no ROS imports)."""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Dict

import numpy as np
import torch


def to_torch(batch: Dict[str, np.ndarray], device: str) -> Dict[str, torch.Tensor]:
    """A sampler batch (arrays) as tensors on ``device``."""
    return {k: torch.as_tensor(v, device=device) for k, v in batch.items()}


def cosine_lr(step: int, steps: int, lr: float, lr_final: float) -> float:
    """Learning rate at ``step`` of ``steps``: cosine from ``lr`` down to ``lr_final``."""
    return lr_final + 0.5 * (lr - lr_final) * (1 + math.cos(math.pi * step / steps))


def plot_log(log_path: Path, out: Path) -> None:
    """Loss curves (train and validation joint error) from a training CSV log (columns
    ``step``, ``split``, ``loss``, ``joints_mm``, ``root_mm``) to a PNG."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    rows = list(csv.DictReader(Path(log_path).open()))
    if not rows:
        return
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.5))
    for split, style in (('train', '-'), ('val', 'o-')):
        r = [x for x in rows if x['split'] == split]
        if not r:
            continue
        s = [int(x['step']) for x in r]
        axes[0].plot(s, [float(x['loss']) for x in r], style, label=split)
        axes[1].plot(s, [float(x['joints_mm']) for x in r], style, label=f'{split} joints')
        axes[1].plot(s, [float(x['root_mm']) for x in r], style, alpha=0.5,
                     label=f'{split} root')
    axes[0].set_yscale('log')
    axes[0].set_xlabel('step')
    axes[0].set_ylabel('total loss')
    axes[1].set_xlabel('step')
    axes[1].set_ylabel('mm')
    axes[1].set_yscale('log')
    for a in axes:
        a.legend(fontsize=8)
        a.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(out, dpi=90)
    plt.close(fig)
