"""One frame's complete pose of the pipeline skeleton (no ROS imports).

A :class:`Pose` is what the ``/mocap/<stage>/motion`` topics carry (docs/design.md §2): the
skeleton (bone offsets), the local joint rotations relative to the rest pose and the root position.
Joint positions, contact-point positions and revolute angles are derived from it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Dict

import numpy as np

from .kinematics import forward_kinematics
from .rotations import euler_to_quat, quat_normalize, quat_to_euler
from .skeleton import Skeleton
from .urdf import BALL_EULER_ORDER


@dataclass(frozen=True, eq=False)
class Pose:
    """A skeleton pose in some frame.

    Attributes:
        skeleton: bone offsets (J, 3), metres.
        rotations: (J, 4) unit quaternions (x, y, z, w). Row j is joint j's rotation relative
            to its parent's frame (relative to the rest pose); row 0 is the root orientation
            in the pose's frame.
        root_position: (3,) root (pelvis) position in the pose's frame, metres.
    """

    skeleton: Skeleton
    rotations: np.ndarray
    root_position: np.ndarray

    def __post_init__(self) -> None:
        rot = np.array(self.rotations, dtype=np.float64)
        root = np.array(self.root_position, dtype=np.float64).reshape(-1)
        j = self.skeleton.num_joints
        if rot.shape != (j, 4):
            raise ValueError(f'rotations must have shape ({j}, 4), got {rot.shape}')
        if root.shape != (3,):
            raise ValueError(f'root_position must have 3 values, got shape {root.shape}')
        if not (np.all(np.isfinite(rot)) and np.all(np.isfinite(root))):
            raise ValueError('pose contains NaN or inf')
        norms = np.linalg.norm(rot, axis=-1)
        if np.any(norms < 1e-6):
            raise ValueError('pose has a zero quaternion')
        rot = quat_normalize(rot)
        rot.setflags(write=False)
        root.setflags(write=False)
        object.__setattr__(self, 'rotations', rot)
        object.__setattr__(self, 'root_position', root)

    @classmethod
    def rest(cls, skeleton: Skeleton, root_position: np.ndarray | None = None) -> 'Pose':
        """The rest (T-) pose: identity rotations; root at ``root_position`` (default: the
        rest root height above z = 0, so the feet touch the floor of a z-up frame)."""
        if root_position is None:
            root_position = np.array([0.0, 0.0, skeleton.rest_root_height()])
        rot = np.zeros((skeleton.num_joints, 4))
        rot[:, 3] = 1.0
        return cls(skeleton, rot, root_position)

    @property
    def joint_names(self) -> tuple:
        return self.skeleton.joint_names

    def joint_positions(self) -> np.ndarray:
        """(J, 3) joint positions in the pose's frame, metres (a new array)."""
        return self._fk().positions.copy()

    def global_rotations(self) -> np.ndarray:
        """(J, 3, 3) joint orientations in the pose's frame (a new array)."""
        return self._fk().global_rotations.copy()

    def contact_positions(self) -> Dict[str, np.ndarray]:
        """Foot contact points (heel, toe; left, right) -> (3,) position in the pose's frame
        (new arrays)."""
        cached = self.__dict__.get('_contacts_cache')
        if cached is None:
            fk = self._fk()
            cached = {name: fk.positions[j] + fk.global_rotations[j] @ p
                      for name, (j, p) in self.skeleton.contact_points().items()}
            object.__setattr__(self, '_contacts_cache', cached)
        return {name: p.copy() for name, p in cached.items()}

    def _fk(self):
        """Forward kinematics, computed once per pose (the pose is immutable)."""
        fk = self.__dict__.get('_fk_cache')
        if fk is None:
            fk = forward_kinematics(self.skeleton.parents, self.skeleton.offsets,
                                    self.rotations, self.root_position)
            object.__setattr__(self, '_fk_cache', fk)
        return fk

    def revolute_angles(self) -> np.ndarray:
        """(J-1, 3) angles (rad) of the z, y, x revolute joints standing for each non-root
        ball joint in the URDF (intrinsic Euler 'ZYX'), joints in skeleton order (a new
        array; computed once per pose)."""
        cached = self.__dict__.get('_angles_cache')
        if cached is None:
            cached = quat_to_euler(self.rotations[1:], BALL_EULER_ORDER)
            object.__setattr__(self, '_angles_cache', cached)
        return cached.copy()

    def with_revolute_angles(self, angles: np.ndarray) -> 'Pose':
        """Copy with the non-root rotations replaced from (J-1, 3) z, y, x angles (rad)."""
        angles = np.asarray(angles, dtype=np.float64)
        if angles.shape != (self.skeleton.num_joints - 1, 3):
            raise ValueError(
                f'expected ({self.skeleton.num_joints - 1}, 3) angles, got {angles.shape}')
        rot = np.array(self.rotations)
        rot[1:] = euler_to_quat(angles, BALL_EULER_ORDER)
        return Pose(self.skeleton, rot, self.root_position)
