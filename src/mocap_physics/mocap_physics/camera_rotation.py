"""Physics in the frame of the first image: the camera's rotation taken out of the input.

With a camera that turns (a pan, a tilt, a hand-held or orbiting camera), a person standing
still moves in the camera frame, and so do their feet: a physics stage that works in a floor
frame fixed to the camera holds a stance foot where the world has moved it, or lets it slide
as the camera turns. The keypoint node estimates the camera's rotation since the first image
from the image background (``/mocap/camera/motion``, :mod:`mocap_core.camera_motion`). Turned
by that rotation, each incoming camera-frame pose is expressed in the optical frame of the
first image (``<optical frame>_start``), which does not turn; the floor is estimated there and
the simulation runs in the floor frame of the first image (``floor_start``).

Conventions: ``R`` (3, 3) maps the current camera frame into the first one,
``p_start = R p_camera`` (the translation of a camera that also moves is not taken out:
the camera-motion estimate measures it only now and then, over the floor); quaternions are
x, y, z, w. No ROS imports.
"""

from __future__ import annotations

import collections
from typing import Optional, Tuple

import numpy as np

from mocap_core import topics
from mocap_core.pose import Pose
from mocap_core.rotations import matrix_to_quat, quat_multiply

from .floor import FloorFrame

#: frame name of the outputs when the camera's rotation is taken out (the floor frame of the
#: first image; ``floor`` is the floor frame under the current camera)
START_FLOOR_FRAME = topics.FLOOR_START_FRAME


class CameraRotations:
    """The camera's rotation since the first image, by stamp, as the keypoint node estimates
    it (the newest ``max_frames`` stamps).

    :meth:`at` gives the rotation of a stamp; a stamp without an estimate of its own (lost,
    late, or ``unknown``: the estimator could not tell) holds the newest estimate before it,
    and before any estimate the camera is taken to be where it was at the first image
    (identity). A stamp more than ``restart_s`` before the newest one restarts the buffer (a
    bag played again: the estimate starts again from its own first image)."""

    def __init__(self, max_frames: int = 600, restart_s: float = 1.0) -> None:
        self.max_frames = int(max_frames)
        self.restart_ns = int(restart_s * 1e9)
        self._by_stamp: 'collections.OrderedDict[int, np.ndarray]' = collections.OrderedDict()

    def __len__(self) -> int:
        return len(self._by_stamp)

    def add(self, stamp_ns: int, state: str, rotation: np.ndarray) -> bool:
        """Store the estimate of ``stamp_ns`` (``state`` of
        :func:`mocap_core.ros_conversions.odometry_to_camera_motion`; ``rotation`` (3, 3)).
        Returns False when it is not kept (``unknown``, or not a finite rotation)."""
        R = np.asarray(rotation, dtype=float)
        if state == 'unknown' or R.shape != (3, 3) or not np.all(np.isfinite(R)) \
                or not np.allclose(R @ R.T, np.eye(3), atol=1e-4):
            return False
        stamp = int(stamp_ns)
        if self._by_stamp and next(reversed(self._by_stamp)) - stamp > self.restart_ns:
            self._by_stamp.clear()
        self._by_stamp[stamp] = R
        while len(self._by_stamp) > self.max_frames:
            self._by_stamp.popitem(last=False)
        return True

    def at(self, stamp_ns: int) -> Tuple[np.ndarray, bool]:
        """(R (3, 3), whether it is the stamp's own estimate) for ``stamp_ns``."""
        stamp = int(stamp_ns)
        R = self._by_stamp.get(stamp)
        if R is not None:
            return R, True
        before = next((s for s in reversed(self._by_stamp) if s < stamp), None)
        if before is not None:
            return self._by_stamp[before], False
        return np.eye(3), False


def rotate_pose(pose: Pose, rotation: np.ndarray) -> Pose:
    """``pose`` (camera frame) in the first image's camera frame: root position ``R p`` and
    root orientation ``R q`` (the other joints' rotations are local and unchanged)."""
    R = np.asarray(rotation, dtype=float)
    rot = np.array(pose.rotations, dtype=float)
    rot[0] = quat_multiply(matrix_to_quat(R), rot[0])
    return Pose(pose.skeleton, rot, R @ np.asarray(pose.root_position, dtype=float))


def floor_in_camera(floor: FloorFrame, rotation: Optional[np.ndarray],
                    source_frame: Optional[str] = None) -> FloorFrame:
    """The floor frame of the first image (``p_floor = A p_start + t``) seen from the
    current camera (``p_start = R p_camera``): ``p_floor = (A R) p_camera + t``. None
    ``rotation``: ``floor`` itself."""
    if rotation is None:
        return floor
    return FloorFrame(floor.rotation @ np.asarray(rotation, dtype=float), floor.translation,
                      source_frame or floor.source_frame)


__all__ = ['CameraRotations', 'rotate_pose', 'floor_in_camera', 'START_FLOOR_FRAME']
