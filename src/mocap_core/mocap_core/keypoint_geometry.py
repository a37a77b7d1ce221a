"""Keypoint geometry shared by the runtime and the training data (no ROS imports).

Pixel coordinates: origin top-left, u right, v down (:mod:`mocap_core.camera`). Keypoints are
the 23-point layout of :mod:`mocap_core.skeleton`, one row per point: (u, v, confidence);
confidence 0 means unseen.
"""

from __future__ import annotations

from typing import Tuple

import numpy as np

from .camera import CameraIntrinsics

#: Layout keypoints that are joints of the pipeline skeleton (same name, same point).
JOINT_KEYPOINTS: Tuple[str, ...] = (
    'left_shoulder', 'right_shoulder', 'left_elbow', 'right_elbow', 'left_wrist',
    'right_wrist', 'left_hip', 'right_hip', 'left_knee', 'right_knee', 'left_ankle',
    'right_ankle')


def canonicalize(keypoints: np.ndarray, intrinsics: CameraIntrinsics) -> np.ndarray:
    """Canonical keypoints K^-1 [u, v, 1] (neural PhysCap §3.2).

    Args:
        keypoints: (..., 3) pixel u, v and confidence c.
        intrinsics: the camera the pixels come from.
    Returns:
        (..., 3) float64 ``((u - cx) / fx, (v - cy) / fy, c)``, independent of the camera
        intrinsics; points with c = 0 become (0, 0, 0).
    """
    kp = np.array(keypoints, dtype=np.float64)
    seen = kp[..., 2] > 0
    kp[..., 0] = np.where(seen, (kp[..., 0] - intrinsics.cx) / intrinsics.fx, 0.0)
    kp[..., 1] = np.where(seen, (kp[..., 1] - intrinsics.cy) / intrinsics.fy, 0.0)
    return kp
