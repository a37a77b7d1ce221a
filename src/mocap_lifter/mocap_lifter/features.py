"""Input features of the lifter networks from 2D keypoints (no ROS imports).

Per frame (MotioNet §3.3 and §4 with neural PhysCap's canonicalisation, §3.2):

* keypoints are canonicalised with the camera intrinsics, ``((u - cx) / fx, (v - cy) / fy)``,
  so the networks never see the training cameras' focal lengths;
* the root keypoint is the midpoint of the two hips (the pelvis of the pipeline skeleton is
  the midpoint of the hip joints); every keypoint is expressed relative to it;
* unseen keypoints (confidence 0) are zeros; the confidences themselves are input channels;
* the global 2D velocity of the root keypoint (canonical units per frame) is appended.

Layout of the (T, C) feature matrix, C = 23*2 + 23 + 2 = 71: root-relative x, y of each
keypoint (interleaved), the 23 confidences, root velocity x, y. The root keypoint itself
(canonical, (T, 2)) is returned separately: the root position is
``Z * (root_x, root_y, 1)`` in the camera frame once the network predicts the depth ``Z``.

A frame where a hip is unseen takes the root of the nearest frame where both are seen (the
root keypoint is held, then back-filled), so the root stays defined through short gaps.
"""

from __future__ import annotations

from typing import Tuple

import numpy as np

from mocap_core.camera import CameraIntrinsics
from mocap_core.data.synth2d import canonicalize
from mocap_core.skeleton import KEYPOINT_INDEX, NUM_KEYPOINTS

NUM_FEATURES = NUM_KEYPOINTS * 3 + 2
_LHIP, _RHIP = KEYPOINT_INDEX['left_hip'], KEYPOINT_INDEX['right_hip']


def root_keypoint(canonical: np.ndarray) -> Tuple[np.ndarray, np.ndarray]:
    """Root (mid-hip) keypoint per frame from (T, 23, 3) canonical keypoints.

    Returns (T, 2) root and (T,) bool validity (both hips seen in that frame). Invalid frames
    hold the previous valid root (back-filled at the start); all-invalid gives zeros.
    """
    kc = np.asarray(canonical)
    valid = (kc[:, _LHIP, 2] > 0) & (kc[:, _RHIP, 2] > 0)
    root = 0.5 * (kc[:, _LHIP, :2] + kc[:, _RHIP, :2])
    if not valid.any():
        return np.zeros_like(root), valid
    idx = np.where(valid, np.arange(len(kc)), -1)
    idx = np.maximum.accumulate(idx)
    first = int(np.argmax(valid))
    idx[idx < 0] = first
    return root[idx], valid


def lifter_features(keypoints: np.ndarray, intr: CameraIntrinsics,
                    ) -> Tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Features of a keypoint window.

    Args:
        keypoints: (T, 23, 3) pixel u, v and confidence of one person.
        intr: the camera intrinsics of those pixels.
    Returns:
        features (T, 71) float32, root keypoint (T, 2) canonical, root validity (T,) bool.
    """
    kp = np.asarray(keypoints, dtype=np.float64)
    if kp.ndim != 3 or kp.shape[1:] != (NUM_KEYPOINTS, 3):
        raise ValueError(f'keypoints must have shape (T, {NUM_KEYPOINTS}, 3), got {kp.shape}')
    kc = canonicalize(kp, intr)
    root, valid = root_keypoint(kc)
    seen = kc[..., 2:3] > 0
    rel = np.where(seen, kc[..., :2] - root[:, None, :], 0.0)
    vel = np.zeros_like(root)
    vel[1:] = root[1:] - root[:-1]
    feats = np.concatenate([rel.reshape(len(kp), -1), kc[..., 2], vel], axis=1)
    return feats.astype(np.float32), root, valid
