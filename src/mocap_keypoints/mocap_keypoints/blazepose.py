"""BlazePose's 33 landmarks in the project's 23-point keypoint layout (no ROS imports)."""

from __future__ import annotations

import numpy as np

from mocap_core.skeleton import BLAZEPOSE_TO_LAYOUT, NUM_KEYPOINTS

NUM_BLAZEPOSE_LANDMARKS = 33

_SRC = np.array(BLAZEPOSE_TO_LAYOUT)
_HAS = _SRC >= 0


def blazepose_to_layout(landmarks: np.ndarray, width: int, height: int) -> np.ndarray:
    """(33, 4) BlazePose landmarks ``(x, y, visibility, presence)`` with x, y normalised to the
    image (presence NaN where the model has none) -> (23, 3) layout keypoints in pixels.

    Confidence = visibility x presence (or visibility where presence is NaN), clipped to
    [0, 1]; layout points without a BlazePose landmark, and landmarks with non-finite values,
    get (0, 0, 0).
    """
    lm = np.asarray(landmarks, dtype=np.float64)
    if lm.shape != (NUM_BLAZEPOSE_LANDMARKS, 4):
        raise ValueError(f'expected ({NUM_BLAZEPOSE_LANDMARKS}, 4) landmarks, got {lm.shape}')
    conf = np.where(np.isnan(lm[:, 3]), lm[:, 2], lm[:, 2] * lm[:, 3])
    pts = np.stack([lm[:, 0] * width, lm[:, 1] * height, np.clip(conf, 0.0, 1.0)], axis=-1)
    out = np.zeros((NUM_KEYPOINTS, 3))
    picked = pts[_SRC[_HAS]]
    ok = np.isfinite(picked).all(axis=1)
    out[np.flatnonzero(_HAS)[ok]] = picked[ok]
    return out
