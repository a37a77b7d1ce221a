"""A known camera pose by stamp (a robot's odometry or map pose of its camera), shared by the
physics stage (``carry_with_camera``) and the world stage (``camera_pose_topic``).

Conventions: the pose is the camera's optical frame (x right, y down, z forward) in a world
frame: ``p_world = R p_optical + t`` (R (3, 3), t (3,) m). A pose of the camera's body frame
(REP-103 camera link: x forward, y left, z up) becomes the optical frame's by
``R_world_optical = R_world_body @ BODY_TO_OPTICAL``. Quaternions are x, y, z, w. No ROS
imports.
"""

from __future__ import annotations

import collections
from typing import Any, Deque, Mapping, Optional, Tuple

import numpy as np

from .rotations import axis_angle_to_matrix, matrix_to_axis_angle, quat_to_matrix

#: A camera body frame (REP-103: x forward, y left, z up) -> its optical frame (x right,
#: y down, z forward): ``R_world_optical = R_world_body @ BODY_TO_OPTICAL``.
BODY_TO_OPTICAL = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
CONVENTIONS = ('optical', 'body')


class KnownCameraPoses:
    """The newest ``max_frames`` camera poses, by stamp (module docstring).

    :meth:`add` keeps a pose (stamps must increase; a stamp more than 1 s before the newest,
    or before the oldest kept, starts the poses again: a bag played again); :meth:`at`
    interpolates between the poses around a stamp (rotation by its geodesic, position
    linearly) when they are at most ``2 max_age_s`` apart, else takes the nearest pose
    within ``max_age_s``, else None."""

    def __init__(self, max_age_s: float = 0.1, convention: str = 'optical',
                 max_frames: int = 600) -> None:
        if convention not in CONVENTIONS:
            raise ValueError(f'camera pose convention must be optical or body, got '
                             f'{convention!r}')
        self.max_age_ns = float(max_age_s) * 1e9
        self.convention = convention
        self.poses: Deque[Tuple[int, np.ndarray, np.ndarray]] = collections.deque(
            maxlen=int(max_frames))

    def __len__(self) -> int:
        return len(self.poses)

    def add(self, stamp_ns: int, position: np.ndarray, quaternion: np.ndarray) -> str:
        """Keep the pose of ``stamp_ns`` (``position`` (3,) m, ``quaternion`` (4,) x, y, z,
        w of the frame named by ``convention``). Returns 'ok', 'restart' (kept, the poses
        before forgotten), 'old' (not after the newest: ignored) or 'invalid' (not finite:
        ignored)."""
        t = np.asarray(position, dtype=float).reshape(-1)
        q = np.asarray(quaternion, dtype=float).reshape(-1)
        n = float(np.linalg.norm(q)) if q.shape == (4,) else 0.0
        if t.shape != (3,) or not (np.all(np.isfinite(t)) and np.all(np.isfinite(q))
                                   and n > 0.5):
            return 'invalid'
        stamp = int(stamp_ns)
        status = 'ok'
        if self.poses and stamp <= self.poses[-1][0]:
            if self.poses[0][0] - stamp > 0 or stamp < self.poses[-1][0] - 10**9:
                self.poses.clear()
                status = 'restart'
            else:
                return 'old'
        R = quat_to_matrix(q / n)
        if self.convention == 'body':
            R = R @ BODY_TO_OPTICAL
        self.poses.append((stamp, R, t))
        return status

    def at(self, stamp_ns: int) -> Optional[Tuple[np.ndarray, np.ndarray]]:
        """The optical frame's (R (3, 3), t (3,)) in the world at ``stamp_ns``, or None."""
        poses = self.poses
        if not poses:
            return None
        stamp = int(stamp_ns)
        after = next((i for i, (s, _, _) in enumerate(poses) if s >= stamp), None)
        if after is not None and after > 0:
            (s0, R0, t0), (s1, R1, t1) = poses[after - 1], poses[after]
            if s1 - s0 <= 2 * self.max_age_ns:
                a = (stamp - s0) / max(s1 - s0, 1)
                return (R0 @ axis_angle_to_matrix(a * matrix_to_axis_angle(R0.T @ R1)),
                        t0 + a * (t1 - t0))
        near = min(poses, key=lambda e: abs(e[0] - stamp))
        if abs(near[0] - stamp) <= self.max_age_ns:
            return near[1], near[2]
        return None


__all__ = ['KnownCameraPoses', 'BODY_TO_OPTICAL', 'CONVENTIONS']


#: the message types a known camera pose comes as (``camera_pose_type``): nav_msgs/Odometry,
#: geometry_msgs/PoseStamped
CAMERA_POSE_TYPES = ('odometry', 'pose')


def known_camera_poses(params: Mapping[str, Any], max_frames: int = 600) -> KnownCameraPoses:
    """The store of a node's known camera poses, from its ``camera_pose_*`` parameters
    (:func:`mocap_core.parameters.camera_pose_params`: ``camera_pose_type``,
    ``camera_pose_convention``, ``camera_pose_max_age_s``). Raises ValueError for a type or
    convention the nodes do not know."""
    if params['camera_pose_type'] not in CAMERA_POSE_TYPES:
        raise ValueError(f"camera_pose_type must be odometry or pose, got "
                         f"{params['camera_pose_type']!r}")
    return KnownCameraPoses(params['camera_pose_max_age_s'], params['camera_pose_convention'],
                            max_frames)
