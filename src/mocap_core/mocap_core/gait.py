"""Gait-cycle helpers (no ROS imports): strides from contact onsets, curves over the cycle.

A stride of one foot runs from its heel strike (the frame its contact turns on) to its next
one; curves are resampled to 0..100 % of the stride (:data:`CYCLE_POINTS` points) so that
strides of different durations can be averaged, as gait laboratories report them. Used by
``mocap eval gait`` (against ground-truth contacts) and ``mocap report`` (against the
physics stage's own forces).
"""

from __future__ import annotations

from typing import List, Sequence

import numpy as np

#: points of a resampled gait cycle (0, 1, ..., 100 %)
CYCLE_POINTS = 101


def heel_strikes(contact: np.ndarray, min_frames: int = 10) -> np.ndarray:
    """Frames where ``contact`` (F,) bool turns on, at least ``min_frames`` after the
    previous strike (a one-frame dropout inside a stance is not a new stride)."""
    c = np.asarray(contact, dtype=bool)
    on = np.flatnonzero(c[1:] & ~c[:-1]) + 1
    keep: List[int] = []
    for f in on:
        if not keep or f - keep[-1] >= min_frames:
            keep.append(int(f))
    return np.array(keep, dtype=int)


def stride_curves(values: np.ndarray, strikes: Sequence[int], min_len: int = 15,
                  max_len: int = 90) -> np.ndarray:
    """(S, CYCLE_POINTS) ``values`` (F,) over each stride between consecutive strikes,
    resampled to 0..100 %; strides shorter than ``min_len`` or longer than ``max_len`` frames
    (a missed strike, a pause) are skipped."""
    out = []
    x = np.linspace(0.0, 1.0, CYCLE_POINTS)
    for a, b in zip(strikes[:-1], strikes[1:]):
        if not min_len <= b - a <= max_len:
            continue
        seg = np.asarray(values)[a:b + 1]
        out.append(np.interp(x, np.linspace(0.0, 1.0, len(seg)), seg))
    return np.array(out).reshape(-1, CYCLE_POINTS)


__all__ = ['CYCLE_POINTS', 'heel_strikes', 'stride_curves']
