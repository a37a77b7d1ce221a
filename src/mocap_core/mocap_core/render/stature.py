"""Stature from a skeleton: the fit behind :meth:`mocap_core.skeleton.Skeleton.stature`.

A rendered clip knows its body's real stature (``meta['body_height_m']``: the rest mesh, soles
to the top of the head) and its rig's bone-group lengths (``data.npz`` ``bone_lengths``, the
project's skeleton convention, which the lifter learns to output). The least-squares line
``stature = slope * Skeleton.height() + offset`` over the training renders gives the constants
of :data:`mocap_core.skeleton.STATURE_SLOPE` / :data:`~mocap_core.skeleton.STATURE_OFFSET`;
``mocap data fit-stature`` refits and checks them on the validation renders.
"""
from __future__ import annotations

from pathlib import Path
from typing import Iterable, Tuple

import numpy as np

from ..skeleton import Skeleton


def stature_pairs(clip_dirs: Iterable[Path]) -> np.ndarray:
    """(N, 2) ``(true stature, Skeleton.height())`` in metres of rendered clip folders (one
    row per clip; folders without ``meta.json`` / ``data.npz`` are skipped)."""
    from .clip import load_clip
    rows = []
    for d in clip_dirs:
        d = Path(d)
        if not (d / 'meta.json').exists() or not (d / 'data.npz').exists():
            continue
        arrays, meta = load_clip(d)
        if 'body_height_m' not in meta or 'bone_lengths' not in arrays:
            continue
        sk = Skeleton.from_group_lengths(np.asarray(arrays['bone_lengths'], dtype=np.float64))
        rows.append((float(meta['body_height_m']), sk.height()))
    return np.asarray(rows, dtype=np.float64).reshape(-1, 2)


def fit_stature(pairs: np.ndarray) -> Tuple[float, float]:
    """Least-squares ``(slope, offset)`` of ``stature = slope * height + offset`` over (N, 2)
    :func:`stature_pairs` rows (N >= 2 with distinct heights)."""
    pairs = np.asarray(pairs, dtype=np.float64)
    if len(pairs) < 2 or np.ptp(pairs[:, 1]) <= 0:
        raise ValueError(f'need at least two bodies of different heights, got {len(pairs)}')
    a = np.c_[pairs[:, 1], np.ones(len(pairs))]
    slope, offset = np.linalg.lstsq(a, pairs[:, 0], rcond=None)[0]
    return float(slope), float(offset)


def stature_errors(pairs: np.ndarray, slope: float, offset: float) -> np.ndarray:
    """(N,) predicted minus true stature, metres."""
    pairs = np.asarray(pairs, dtype=np.float64)
    return slope * pairs[:, 1] + offset - pairs[:, 0]
