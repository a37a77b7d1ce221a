"""Physics with a moving camera: the camera's rotation taken out of the input
(``derotate_camera``), or the simulated state carried with the camera's motion
(``carry_with_camera``).

With a camera that turns (a pan, a tilt, a hand-held or orbiting camera), a person standing
still moves in the camera frame, and so do their feet: a physics stage that works in a floor
frame fixed to the camera holds a stance foot where the world has moved it, or lets it slide
as the camera turns. The keypoint node estimates the camera's rotation since the first image
from the image background (``/mocap/camera/motion``, :mod:`mocap_core.camera_motion`). Turned
by that rotation, each incoming camera-frame pose is expressed in the optical frame of the
first image (``<optical frame>_start``), which does not turn; the floor is estimated there and
the simulation runs in the floor frame of the first image (``floor_start``).

The camera's translation is not taken out here: a floor fixed to the first image over a long
path carries every drift of the estimate in height and tilt (measured: the floor under the
person 2x further off on the rendered walkers). ``carry_with_camera`` instead keeps the floor
frame riding with the camera and carries the simulated state by the camera's motion between
frames (:func:`camera_step_on_floor`); :class:`CameraRotations` keeps the camera's position for
it (``translation``): where the keypoint node measured the step over the floor, else coasted
on the last velocity for ``coast_s``, then held.

Conventions: ``R`` (3, 3) maps the current camera frame into the first one, ``C`` (3,) m is
the camera's position in the first camera frame; quaternions are x, y, z, w. No ROS imports.
"""

from __future__ import annotations

import collections
from typing import Optional, Tuple

import numpy as np

from mocap_core import topics
from mocap_core.pose import Pose
from mocap_core.rotations import closest_yaw, matrix_to_quat, quat_multiply

from .floor import FloorFrame

#: frame name of the outputs when the camera's rotation is taken out (the floor frame of the
#: first image; ``floor`` is the floor frame under the current camera)
START_FLOOR_FRAME = topics.FLOOR_START_FRAME


class CameraRotations:
    """The camera's rotation (and, with ``translation``, position) since the first image, by
    stamp, as the keypoint node estimates it (the newest ``max_frames`` stamps).

    :meth:`at` gives the rotation of a stamp, :meth:`pose_at` the rotation and position; a
    stamp without an estimate of its own (lost, late, or ``unknown``: the estimator could not
    tell) holds the newest estimate before it, and before any estimate the camera is taken to
    be where it was at the first image (identity). A stamp more than ``restart_s`` before the
    newest one restarts the buffer (a bag played again: the estimate starts again from its
    own first image).

    Translation (``translation=True``; module docstring): estimates must be added in stamp
    order. A measured position (``position`` not None: the estimator's position, which
    advances only by measured steps) moves the camera by the estimator's step since its last
    measured position; a frame without one moves it by the last measured velocity for
    ``coast_s`` after the last measurement, then not at all; a static frame stops it. An
    ``unknown`` frame is then stored too (the rotation held, the position coasted), as not
    the stamp's own estimate."""

    def __init__(self, max_frames: int = 600, restart_s: float = 1.0,
                 translation: bool = False, coast_s: float = 0.5) -> None:
        self.max_frames = int(max_frames)
        self.restart_ns = int(restart_s * 1e9)
        self.translation = bool(translation)
        self.coast_ns = int(max(coast_s, 0.0) * 1e9)
        #: stamp -> (R (3, 3), C (3,), the stamp's own estimate)
        self._by_stamp: 'collections.OrderedDict[int, Tuple[np.ndarray, np.ndarray, bool]]' = \
            collections.OrderedDict()
        #: frames whose camera position was measured / coasted / held (translation only)
        self.measured_frames = 0
        self.coasted_frames = 0
        self.held_frames = 0
        self._reset_translation()

    def _reset_translation(self) -> None:
        self._C = np.zeros(3)                 # the camera's position taken out, first frame
        self._v = np.zeros(3)                 # its last measured velocity, m/s, first frame
        self._estimator_C = np.zeros(3)       # the estimator's last measured position
        self._last_ns: Optional[int] = None
        self._measured_ns: Optional[int] = None

    def __len__(self) -> int:
        return len(self._by_stamp)

    def add(self, stamp_ns: int, state: str, rotation: np.ndarray,
            position: Optional[np.ndarray] = None) -> bool:
        """Store the estimate of ``stamp_ns`` (``state`` of
        :func:`mocap_core.ros_conversions.odometry_to_camera_motion`; ``rotation`` (3, 3);
        ``position`` (3,) m in the first camera frame where the step was measured, of
        :func:`mocap_core.ros_conversions.odometry_to_camera_position`). Returns False when
        it is not kept as the stamp's own estimate (``unknown``, or not a finite
        rotation)."""
        R = np.asarray(rotation, dtype=float)
        stamp = int(stamp_ns)
        if self._by_stamp and next(reversed(self._by_stamp)) - stamp > self.restart_ns:
            self._by_stamp.clear()
            self._reset_translation()
        ok = not (state == 'unknown' or R.shape != (3, 3) or not np.all(np.isfinite(R))
                  or not np.allclose(R @ R.T, np.eye(3), atol=1e-4))
        if not self.translation:
            if ok:
                self._store(stamp, R, np.zeros(3), True)
            return ok
        if self._last_ns is not None and stamp <= self._last_ns:
            return False                      # not in stamp order: nothing to add
        C = self._advance(stamp, state, position)
        if ok:
            self._store(stamp, R, C, True)
        else:
            held = self._newest_before(stamp)
            self._store(stamp, held[0] if held is not None else np.eye(3), C, False)
        return ok

    def _advance(self, stamp: int, state: str, position: Optional[np.ndarray]) -> np.ndarray:
        """The camera position of ``stamp`` (translation bookkeeping, class docstring)."""
        dt = 0.0 if self._last_ns is None else (stamp - self._last_ns) * 1e-9
        self._last_ns = stamp
        pos = None if position is None else np.asarray(position, dtype=float)
        if pos is not None and pos.shape == (3,) and np.all(np.isfinite(pos)):
            step = pos - self._estimator_C
            self._estimator_C = pos
            self._C = self._C + step
            self._v = np.zeros(3) if state == 'static' or dt <= 0 else step / dt
            self._measured_ns = stamp
            self.measured_frames += 1
        elif state != 'static' and self._measured_ns is not None \
                and stamp - self._measured_ns <= self.coast_ns and np.any(self._v):
            self._C = self._C + self._v * dt
            self.coasted_frames += 1
        else:
            self._v = np.zeros(3)
            self.held_frames += 1
        return self._C.copy()

    def _store(self, stamp: int, R: np.ndarray, C: np.ndarray, own: bool) -> None:
        self._by_stamp[stamp] = (R, C, own)
        while len(self._by_stamp) > self.max_frames:
            self._by_stamp.popitem(last=False)

    def _newest_before(self, stamp: int):
        before = next((s for s in reversed(self._by_stamp) if s < stamp), None)
        return None if before is None else self._by_stamp[before]

    def at(self, stamp_ns: int) -> Tuple[np.ndarray, bool]:
        """(R (3, 3), whether it is the stamp's own estimate) for ``stamp_ns``."""
        R, _, own = self.pose_at(stamp_ns)
        return R, own

    def pose_at(self, stamp_ns: int) -> Tuple[np.ndarray, np.ndarray, bool]:
        """(R (3, 3), C (3,) m (zero without ``translation``), whether it is the stamp's own
        estimate) for ``stamp_ns``."""
        stamp = int(stamp_ns)
        entry = self._by_stamp.get(stamp)
        if entry is not None:
            return entry
        before = self._newest_before(stamp)
        if before is not None:
            return before[0], before[1], False
        return np.eye(3), np.zeros(3), False


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


def camera_step_on_floor(previous: Tuple[np.ndarray, np.ndarray],
                         current: Tuple[np.ndarray, np.ndarray],
                         floor: FloorFrame) -> Tuple[np.ndarray, np.ndarray]:
    """How the world moved in the floor frame of the camera between two frames: a turn about
    the floor's z and a shift along it, ``p_floor_now = rotation p_floor_before +
    translation`` for a point fixed in the world.

    ``previous`` and ``current``: the camera's (R (3, 3), C (3,) m) of the two frames, the
    camera frame into the first image's camera frame (``p_first = R p_camera + C``);
    ``floor``: the floor in the camera frame (``p_floor = A p_camera + t``), taken to be
    the same in both frames (the floor frame rides with the camera, its height and tilt
    being re-estimated by the floor tracker). The camera's tilt change and vertical step
    are left out (the floor tracker follows those); the rest of the camera's rotation, its
    turn about the floor's normal, and its horizontal step are what move the world past
    the camera. Returns (rotation (3, 3) about z, translation (3,) with z = 0)."""
    R0, C0 = (np.asarray(x, dtype=float) for x in previous)
    R1, C1 = (np.asarray(x, dtype=float) for x in current)
    A, t = floor.rotation, floor.translation
    # p_cam_now = R1^T (R0 p_cam_before + C0 - C1), in the floor frame
    M = A @ R1.T @ R0 @ A.T
    yaw = closest_yaw(M)
    c, s = np.cos(yaw), np.sin(yaw)
    Rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    shift = A @ (R1.T @ (C0 - C1)) + t - Rz @ t
    shift[2] = 0.0
    return Rz, shift


__all__ = ['CameraRotations', 'camera_step_on_floor', 'rotate_pose', 'floor_in_camera',
           'START_FLOOR_FRAME']
