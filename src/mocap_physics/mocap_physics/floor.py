"""The floor frame of the dynamics and its relation to the camera frame (no ROS imports).

The physics cycle runs in a **floor frame**: z up, the floor is the plane z = 0, gravity is
(0, 0, -9.81), x is the camera's viewing direction projected onto the floor, y points left.
Incoming motion in the camera's optical frame (REP-103: x right, y down, z forward) is mapped
into it by a rigid transform ``T_floor_camera`` before the cycle and the outputs can be mapped
back with its inverse.

This module holds that boundary: :class:`FloorFrame` (the transform) built from the camera
height and pitch (the ``floor_source = camera_params`` case) or the identity (input already in
a floor frame, e.g. ground-truth motion capture). A robust estimate from the feet during
predicted contacts plugs in here later, as another constructor of :class:`FloorFrame`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from mocap_core.pose import Pose
from mocap_core.rotations import matrix_to_quat, quat_multiply


@dataclass(frozen=True)
class FloorFrame:
    """Rigid transform from a source frame (camera or world) to the floor frame.

    Attributes:
        rotation: (3, 3) R with ``p_floor = R p_source + translation``.
        translation: (3,) metres.
        source_frame: name of the source frame (for messages and logs).
    """

    rotation: np.ndarray = field(default_factory=lambda: np.eye(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    source_frame: str = 'floor'

    def __post_init__(self) -> None:
        R = np.asarray(self.rotation, dtype=float)
        t = np.asarray(self.translation, dtype=float).reshape(3)
        if R.shape != (3, 3) or not np.allclose(R @ R.T, np.eye(3), atol=1e-6) \
                or np.linalg.det(R) < 0:
            raise ValueError('floor rotation must be a proper 3x3 rotation matrix')
        object.__setattr__(self, 'rotation', R)
        object.__setattr__(self, 'translation', t)

    @classmethod
    def identity(cls, source_frame: str = 'floor') -> 'FloorFrame':
        """The input already is in a floor frame (z up, floor at z = 0)."""
        return cls(source_frame=source_frame)

    @classmethod
    def from_camera_height_pitch(cls, height: float, pitch: float,
                                 source_frame: str = 'camera') -> 'FloorFrame':
        """Camera optical frame -> floor frame for a camera ``height`` metres above the floor,
        pitched down by ``pitch`` radians (0 = optical axis parallel to the floor), no roll.

        The floor origin is the point on the floor below the camera.
        """
        if not np.isfinite(height) or height < 0:
            raise ValueError(f'camera height must be >= 0, got {height}')
        c, s = np.cos(pitch), np.sin(pitch)
        forward = np.array([c, 0.0, -s])      # optical z
        right = np.array([0.0, -1.0, 0.0])    # optical x
        down = np.cross(forward, right)       # optical y
        R = np.stack([right, down, forward], axis=1)
        return cls(R, np.array([0.0, 0.0, float(height)]), source_frame)

    def inverse(self) -> 'FloorFrame':
        """The transform from the floor frame back to the source frame."""
        R_inv = self.rotation.T
        return FloorFrame(R_inv, -R_inv @ self.translation, 'floor')

    def transform_points(self, points: np.ndarray) -> np.ndarray:
        return np.asarray(points, dtype=float) @ self.rotation.T + self.translation

    def transform_pose(self, pose: Pose) -> Pose:
        """``pose`` (in the source frame) expressed in the floor frame."""
        rot = np.array(pose.rotations)
        q_frame = matrix_to_quat(self.rotation)
        rot[0] = quat_multiply(q_frame, rot[0])
        return Pose(pose.skeleton, rot, self.transform_points(pose.root_position))

    def quaternion(self) -> np.ndarray:
        """(4,) x, y, z, w rotation of the transform."""
        return matrix_to_quat(self.rotation)
